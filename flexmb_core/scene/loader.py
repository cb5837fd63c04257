"""Strict YAML loader: unknown keys, wrong shapes or units and dangling names are errors that
name ``file:key`` and what was expected (``flexmb check SCENE``).

The keys, types, defaults, units and ranges of every block are the schema's
(:mod:`flexmb_core.scene.schema`, read by :mod:`flexmb_core.scene.typed`). This module reads the
top-level blocks in the order their references need — materials, sections and nodes before the
members that name them, shells and their mesh points before the supports, loads and outputs that
may name those points — and checks what spans blocks: a member's nodes must not coincide, a
moment's node must be an end of its member, a joint's members must pass through its node, …
"""

from __future__ import annotations

import functools
import math
import stat
from pathlib import Path
from typing import Any

from ..errors import SceneError, name_list
from . import strict_yaml
from .include import compose
from .limits import DEFAULT_LIMITS, Limits, over_limit
from .reader import Node
from .schema import Joint, Member, Scene, SceneFile, ShellJoint, SolverSpec
from .shells import check_shell, check_shell_joint, edge_ref, named_points, point_reader
from .typed import check_keys, read, read_key


def parse_yaml(text: str, source: str = "<string>", limits: Limits | None = None) -> Any:
    """Parse scene YAML text the way :func:`load_scene` does: ``1e9`` is a float, duplicate keys,
    deep nesting and alias bombs are :class:`SceneError` at ``source:line:column``."""
    return strict_yaml.parse(text, source, limits)


def read_scene_text(path: str | Path, limits: Limits | None = None) -> str:
    """The UTF-8 text of a scene file (size-limited); errors name the file (and line:column)."""
    path = Path(path)
    limits = limits or DEFAULT_LIMITS
    try:
        mode = path.stat().st_mode
        if not stat.S_ISREG(mode):
            # a FIFO would block the read until a writer came, /dev/zero would fill the memory
            raise SceneError(str(path), f"not a regular file ({_file_kind(mode)}); expected a scene file (YAML)")
        with path.open("rb") as f:
            # read one byte past the limit: a file that grew after stat() is refused all the same
            data = f.read(limits.max_file_bytes + 1)
        if len(data) > limits.max_file_bytes:
            raise over_limit(str(path), "scene file size in bytes", path.stat().st_size, "max_file_bytes", limits)
    except OSError as exc:
        raise SceneError(str(path), f"cannot read scene file ({exc.strerror})") from None
    return strict_yaml.decode(data, str(path))


def _file_kind(mode: int) -> str:
    kinds = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
             (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))
    return next((name for test, name in kinds if test(mode)), "not a regular file")


def load_scene(path: str | Path, overrides: dict[str, Any] | None = None, *,
               limits: Limits | None = None) -> Scene:
    """Read and validate a scene file. ``overrides`` are merged into ``solver`` (CLI flags);
    ``limits`` bound the file, its alias expansion and (in :func:`compile_scene`) its size."""
    text = read_scene_text(path, limits)
    data = parse_yaml(text, str(path), limits)
    return scene_from_dict(data, source=str(path), overrides=overrides, limits=limits)


def scene_from_dict(data: Any, source: str = "<dict>",
                    overrides: dict[str, Any] | None = None, *, limits: Limits | None = None) -> Scene:
    """Validate a scene given as nested dicts (as parsed from YAML); its ``include:`` files are
    read relative to ``source``'s folder (:mod:`flexmb_core.scene.include`)."""
    data = compose(data, source, limits)
    root = check_keys(Node(data, "", source), SceneFile)
    block = functools.partial(read_key, root, SceneFile)
    name, description = block("name"), block("description")
    materials, sections, nodes, members = _frame_parts(root, block)
    shells, points = _shell_parts(root, block, materials, nodes, members)
    edge = functools.partial(edge_ref, shells=shells)
    names = {**nodes, **{k: p.at for k, p in points.items()}}      # what supports, loads, outputs may name
    refs = {"node": names, "member": members, "shell": shells, "edge": edge,
            "point": point_reader(shells, points, names)}          # node: {shell, at} → 'shell@key'
    supports = block("supports", refs)
    for n, s in zip(_items(root, "supports"), supports):
        if s.member is not None and s.node not in (members[s.member].start, members[s.member].end):
            raise n.fail(f"node '{s.node}' is not an end of member '{s.member}'")
    loads = block("loads", refs)
    for k, m in loads.moments.items():
        _check_moment(root.get("loads").get("moments").get(k), m, members)
    point_masses = block("point_masses", refs)
    mass_damping = _mass_damping(root)
    solver = _solver(root, overrides or {}, names)      # a monitor may name a mesh point
    outputs = block("outputs", refs)
    for k, out in outputs.items():
        _check_output(root.get("outputs").get(k), out, members)
    commands = _commands(root, block, members)
    joints = block("joints", {"node": nodes, "member": members, "shell": shells, "edge": edge})
    for n, j in zip(_items(root, "joints"), joints):
        if isinstance(j, Joint):
            _check_joint(n, j, members)
        else:
            check_shell_joint(n, j, members, shells)
    return Scene(name, description, source, materials, sections, nodes, members, supports,
                 tuple(loads.forces.values()), tuple(loads.moments.values()), tuple(point_masses.values()),
                 loads.gravity, mass_damping, solver, tuple(outputs.values()), commands,
                 tuple(j for j in joints if isinstance(j, Joint)), shells,
                 tuple(j for j in joints if isinstance(j, ShellJoint)),
                 tuple(loads.edge_forces.values()) + tuple(loads.edge_moments.values()), tuple(points.values()),
                 block("limits"))


def _frame_parts(root: Node, block) -> tuple[dict, dict, dict, dict[str, Member]]:
    """Materials, sections, nodes and the members that name them."""
    materials = block("materials")
    if not materials:
        raise root.fail("at least one material is required", "materials")
    sections = block("sections")
    nodes = block("nodes")
    members = block("members", {"node": nodes, "material": materials, "section": sections})
    for k, m in members.items():
        _check_member(root.get("members").get(k), m, nodes)
    return materials, sections, nodes, members


def _shell_parts(root: Node, block, materials: dict, nodes: dict, members: dict) -> tuple[dict, dict]:
    """The shells (with their named mesh points) and those points, ``{"shell.point": ShellPoint}``."""
    shells = block("shells", {"node": nodes, "material": materials})
    for k, sh in shells.items():
        check_shell(root.get("shells").get(k), sh, materials, nodes)
    shells, points = named_points(root.get("shells", {}), shells, nodes)
    if not members and not shells:
        raise root.fail("a scene needs at least one member or one shell", "members")
    clash = sorted(set(members) & set(shells))
    if clash:
        raise root.fail(f"name(s) {name_list(clash)} are used by both a member and a shell; names must be unique", "shells")
    return shells, points


def _commands(root: Node, block, members: dict[str, Member]):
    """The command program; what it drives must be actuators."""
    commands = block("commands", {"member": members})
    if commands is not None:
        for n, a in zip(root.get("commands").get("actuators").list(), commands.actuators):
            if members[a].kind != "actuator":
                raise n.fail(f"member '{a}' is not an actuator (kind '{members[a].kind}')")
    return commands


def _items(root: Node, key: str) -> list[Node]:
    """The items of the top-level list ``key`` (none when absent)."""
    return root.get(key).list() if root.has(key) else []


def _is_bar(mem: Member) -> bool:
    """A truss or bar-actuator member: 2-node bars without section vectors."""
    return mem.kind == "truss" or (mem.actuator is not None and mem.actuator.variant == "bar")


def _passes_through(mem: Member, node: str) -> bool:
    return node in (mem.start, mem.end) or node in mem.via


_MIN_RELATIVE_LENGTH = 1e-9     # a member's length at least this fraction of its nodes' coordinates
_MIN_LENGTH = 1e-12             # m: and at least this


def _check_member(n: Node, m: Member, nodes: dict) -> None:
    """A member's geometry: distinct end positions, an arc centre equidistant from both ends."""
    length = math.dist(nodes[m.start], nodes[m.end])
    if length <= 0.0:
        raise n.fail(f"nodes '{m.start}' and '{m.end}' coincide: a member needs a positive length")
    # shorter than this, the element's geometry is lost to rounding of the positions (or is below any
    # physical length in SI): its tangent is singular, which a run would report without naming the key
    floor = max(_MIN_RELATIVE_LENGTH * max(math.hypot(*nodes[m.start]), math.hypot(*nodes[m.end])), _MIN_LENGTH)
    if length < floor:
        raise n.fail(f"nodes '{m.start}' and '{m.end}' are {length:.3g} m apart; a member needs at least "
                     f"{floor:.3g} m (1e-9 of its nodes' distance from the origin, 1e-12 m at least)")
    if m.arc_center is not None:
        r0, r1 = math.dist(m.arc_center, nodes[m.start]), math.dist(m.arc_center, nodes[m.end])
        if abs(r0 - r1) > 1e-9 * max(r0, r1):
            raise n.get("arc").fail(f"'{m.start}' and '{m.end}' are not equidistant from the centre ({r0} vs {r1} m)",
                                    "center")


def _check_moment(n: Node, mo, members: dict[str, Member]) -> None:
    mem = members[mo.member]
    if mo.node not in (mem.start, mem.end):
        raise n.fail(f"node '{mo.node}' is not an end of member '{mo.member}'", "node")
    if _is_bar(mem):
        raise n.fail(f"member '{mo.member}' has no section vectors (bars carry no moments)", "member")


def _check_joint(n: Node, j: Joint, members: dict[str, Member]) -> None:
    for m in j.members:
        if not _passes_through(members[m], j.node):
            raise n.fail(f"member '{m}' does not pass through node '{j.node}'", "members")
        if j.type != "spherical" and _is_bar(members[m]):
            raise n.fail(f"member '{m}' is a bar: it has no section vectors for a {j.type} joint", "members")


def _check_output(n: Node, out, members: dict[str, Member]) -> None:
    """What an output names must have what it reports: an actuator, section vectors at an end."""
    if out.actuator is not None and members[out.actuator].kind != "actuator":
        raise n.fail(f"member '{out.actuator}' is not an actuator (kind '{members[out.actuator].kind}')", "actuator")
    if out.kind == "section_vectors":
        if _is_bar(members[out.member]):
            raise n.fail(f"member '{out.member}' has no section vectors", "member")
        if out.node not in (members[out.member].start, members[out.member].end):
            raise n.fail(f"node '{out.node}' is not an end of member '{out.member}'", "node")
    if out.kind == "joint_angle":
        for m in out.nodes:
            if _is_bar(members[m]):
                raise n.fail(f"member '{m}' has no section vectors", "members")
            if not _passes_through(members[m], out.node):
                raise n.fail(f"member '{m}' does not pass through node '{out.node}'", "members")


def _mass_damping(root: Node) -> float:
    """``damping.mass_proportional`` (1/s); material damping given here points to the material."""
    damp = root.get("damping", {})
    if isinstance(damp.value, dict) and any(k in damp.value for k in ("eta", "strain_rate", "kelvin_voigt")):
        raise damp.fail("material (Kelvin–Voigt) damping is a material property: give it as "
                        "materials: {name: {eta: <Pa·s>}}; the damping block holds mass_proportional only")
    return read_key(root, SceneFile, "damping").mass_proportional


def _solver(root: Node, overrides: dict[str, Any], names: dict) -> SolverSpec:
    """``solver``, with the command line's ``overrides`` (flags, ``--override solver.KEY``) on top."""
    n = check_keys(root.get("solver", {}), SolverSpec)
    merged = {**n.value, **{k: v for k, v in overrides.items() if v is not None}}
    return read(Node(merged, n.path, n.source), SolverSpec, {"node": names})
