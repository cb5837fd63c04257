"""Edits of a parsed scene mapping by dotted key: ``materials.steel.E=2.2e11``, ``members.leg1.elements=4``,
``supports.0.type=clamped`` (list items by index).

One implementation for every verb that edits a scene from the command line: ``flexmb replay
--override`` and ``flexmb sweep --param``. Values are parsed as scene YAML (``1e9`` is a float,
``[0.6, 1.6]`` a list). Keys under ``solver.`` are handed back separately by
:func:`apply_overrides` (``replay`` lets them win over the recorded solver settings).

YAML anchors make several entries share one mapping (``leg2: {<<: *leg}`` shares ``leg1``'s
``actuator`` block): an edit copies every mapping and list on its path first, so it changes the
entry it names and nothing else.
"""

from __future__ import annotations

from typing import Any

from ..errors import FlexmbError, SceneError, excerpt


class OverrideError(FlexmbError):
    """A ``KEY=VALUE`` edit that does not fit the scene (bad syntax, missing key, bad index)."""


def parse_override(item: str, flag: str = "--override") -> tuple[list[str], Any]:
    """``"materials.steel.E=2.2e11"`` → ``(["materials", "steel", "E"], 2.2e11)``."""
    from .loader import parse_yaml

    if "=" not in item:
        raise OverrideError(f"{flag} {item!r}: expected KEY.PATH=VALUE, e.g. materials.steel.E=2.2e11")
    key, raw = item.split("=", 1)
    path = split_key(key)
    if not path:
        raise OverrideError(f"{flag} {item!r}: empty key")
    try:
        value = parse_yaml(raw, "VALUE")
    except SceneError as exc:       # its place in a one-line value says nothing: the flag and item do
        raise OverrideError(f"{flag} {excerpt(item, 80)}: the value is not valid YAML "
                            f"({str(exc)[len(exc.where) + 2:]})") from None
    return path, value


def split_key(key: str) -> list[str]:
    """``"materials.steel.E"`` → ``["materials", "steel", "E"]`` (empty parts dropped)."""
    return [p for p in key.strip().split(".") if p]


def apply_overrides(data: dict, items: list[str] | None, flag: str = "--override") -> dict:
    """Set dotted keys of a scene mapping in place (``materials.steel.E=2.2e11``; list items by index).
    Keys ``solver.X`` are not set but returned as ``{X: value}``.

    Raises
    ------
    OverrideError
        When a key's parent does not exist or an index is out of range.
    """
    solver: dict = {}
    for item in items or ():
        path, value = parse_override(item, flag)
        if path[0] == "solver" and len(path) == 2:
            solver[path[1]] = value
            continue
        set_path(data, path, value, item=item, flag=flag)
    return solver


def set_path(data: dict, path: list[str], value: Any, *, item: str, flag: str = "--override") -> None:
    """Set ``data[path[0]][path[1]]… = value``; every parent must exist (a new leaf key is allowed,
    the scene's strict schema judges it). Mappings and lists on the path are copied first (no edit
    through a YAML anchor reaches another entry)."""
    node: Any = data
    for depth, key in enumerate(path[:-1]):
        where = ".".join(path[:depth + 1])
        child = _child(node, key, where, item, flag)
        if isinstance(child, (dict, list)):
            child = child.copy()                    # copy on write: unshare anchored blocks
            _put(node, key, child, item, flag)
        node = child
    last = path[-1]
    if isinstance(node, (dict, list)):
        _put(node, last, value, item, flag)
    else:
        raise OverrideError(f"{flag} {item!r}: {'.'.join(path[:-1])} is a value, not a mapping")


def _put(node: Any, key: str, value: Any, item: str, flag: str) -> None:
    if isinstance(node, list):
        node[_index(node, key, item, flag)] = value
    else:
        node[key] = value


def _index(node: list, key: str, item: str, flag: str) -> int:
    try:
        i = int(key)
    except ValueError:
        raise OverrideError(f"{flag} {item!r}: {key!r} must be a list index") from None
    if not -len(node) <= i < len(node):
        raise OverrideError(f"{flag} {item!r}: index {i} out of range (list of {len(node)})")
    return i


def _child(node: Any, key: str, where: str, item: str, flag: str) -> Any:
    if isinstance(node, dict):
        if key not in node:
            raise OverrideError(f"{flag} {item!r}: the scene has no key {where!r} "
                                f"(has {sorted(map(str, node))})")
        return node[key]
    if isinstance(node, list):
        return node[_index(node, key, item, flag)]
    raise OverrideError(f"{flag} {item!r}: {where!r} is a value, not a mapping")
