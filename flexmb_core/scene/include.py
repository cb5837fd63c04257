"""Scene composition: ``include:`` other scene files, with overrides.

::

    include: base.yaml                                   # a path, relative to this file
    include:                                             # or a list, merged in order
      - materials.yaml
      - file: ../scenes/shell_pinched_hemisphere.yaml
        overrides: {shells.hemi.mesh.divisions: [4, 4], loads.forces.pull.force: [0.01, 0, 0]}

Each included file is read, composed itself (its own ``include:`` resolved relative to *its*
directory), then edited by its ``overrides`` — the dotted keys of ``flexmb replay --override``
(``materials.steel.E``, ``supports.0.type``; :mod:`flexmb_core.scene.overrides`): every parent must
exist, except that ``solver.KEY`` creates the ``solver`` block. The includes are merged in order,
then this file's own keys on top: mappings merge key by key, ``null`` removes a key (``angles:
null``), anything else (lists such as ``supports``, numbers, strings) replaces what came before,
so a list is changed by an override of its item (``supports.1.type``) or given whole (JSON Merge
Patch, RFC 7386).

A file that includes itself, directly or through others, is refused (``include cycle: a.yaml →
b.yaml → a.yaml``), as are chains deeper than :data:`MAX_DEPTH`. Errors name
``file:include[i]…``; errors in the composed scene name the including file's path and the key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import SceneError, excerpt
from .limits import Limits
from .overrides import OverrideError, set_path, split_key
from .reader import Node
from .schema import IncludeItem
from .typed import read

MAX_DEPTH = 16


def compose(data: Any, source: str, limits: Limits | None = None) -> Any:
    """``data`` with its ``include:`` resolved (unchanged when it has none). ``source`` is the
    path of the file ``data`` was read from: relative includes resolve against its directory."""
    if not (isinstance(data, dict) and "include" in data):
        return data
    here = Path(source)
    stack = (here.resolve(),) if here.is_file() else ()
    return _compose(data, source, limits, stack)


def _compose(data: dict, source: str, limits: Limits | None, stack: tuple[Path, ...]) -> dict:
    root = Node(data, "", source)
    inc = root.get("include")
    items = inc.list() if isinstance(inc.value, list) else [inc]
    merged: dict = {}
    for item in items:
        sub = _read_one(item, source, limits, stack)
        merged = merge(merged, sub)
    return merge(merged, {k: v for k, v in data.items() if k != "include"})


def _read_one(item: Node, source: str, limits: Limits | None, stack: tuple[Path, ...]) -> dict:
    from .loader import parse_yaml, read_scene_text

    if isinstance(item.value, dict):
        read(item, IncludeItem)
        file = item.get("file")
    else:
        file = item
    name = file.string()
    path = Path(name)
    if not path.is_absolute():
        here = Path(source)
        if not here.is_file():
            raise file.fail(f"the relative path {excerpt(name)} needs the including file's location, but the "
                            f"scene came from {excerpt(source)}; give an absolute path")
        path = here.parent / path
    path = path.resolve()
    if path in stack:
        chain = " → ".join(p.name for p in (*stack, path))
        raise file.fail(f"include cycle: {chain}; a scene may not include itself")
    if len(stack) >= MAX_DEPTH:
        raise file.fail(f"includes nested deeper than {MAX_DEPTH} files")
    if not path.is_file():
        raise file.fail(f"no scene file {excerpt(str(path))} (relative paths start at the including file's folder)")
    sub = parse_yaml(read_scene_text(path, limits), str(path), limits)
    if not isinstance(sub, dict):
        raise SceneError(str(path), f"expected a scene mapping at the top level, got {excerpt(sub)}")
    sub = _compose(sub, str(path), limits, (*stack, path)) if "include" in sub else sub
    if isinstance(item.value, dict) and item.has("overrides"):
        _override(sub, item.get("overrides"))
    return sub


def _override(data: dict, overrides: Node) -> None:
    """Apply ``{dotted.key: value}`` edits to an included scene mapping (copy on write)."""
    for key, value in overrides.items():
        path = split_key(key)
        if path[0] == "solver" and len(path) == 2 and "solver" not in data:
            data["solver"] = {}
        try:
            set_path(data, path, value.value, item=f"{key}={excerpt(value.value)}", flag="include overrides")
        except OverrideError as exc:
            raise overrides.fail(str(exc).split(": ", 1)[-1], key) from None


def merge(base: Any, top: Any) -> Any:
    """``top`` over ``base``: mappings merge key by key (recursively), a ``null`` in ``top`` removes
    the key, anything else replaces (the rules of JSON Merge Patch, RFC 7386)."""
    if not (isinstance(base, dict) and isinstance(top, dict)):
        return top
    out = dict(base)
    for k, v in top.items():
        if v is None:
            out.pop(k, None)
        else:
            out[k] = merge(out[k], v) if k in out else v
    return out
