"""The shell parts of a scene that reach beyond one mapping (their keys, types and defaults are
the schema's, :mod:`flexmb_core.scene.schema`): edge references ``shell.edge`` checked against the
mesh kind, the named mesh ``points`` and mesh nodes chosen by coordinates wherever a support,
force, point mass or output names a ``node``, a shell's material and corner geometry, and the
``shell_rigid`` tie's member and corner. Errors name ``file:key``, the value and what was expected.

Mesh points: ``shells.cap.points: {pole: [0, 0, 10]}`` names the mesh node nearest to that
reference position ``cap.pole``; ``{at: [...], edge: rim, tolerance: 1e-3}`` restricts the search to
an edge and sets the distance it may be off (default 10⁻⁶ of the shell's size). In place of a node
name, ``node: {shell: cap, at: [x, y, z]}`` (same optional ``edge``, ``tolerance``) does the same
without a name. Compiling fails (naming the key) when no mesh node lies that close."""

from __future__ import annotations

import dataclasses
import math

from ..errors import excerpt
from .reader import Node
from .schema import EdgeRef, Shell, ShellJoint, ShellMeshSpec, ShellPoint
from .typed import read

EDGE_NAMES = {
    "rectangle": ("bottom", "right", "top", "left"),
    "triangle": ("ab", "bc", "ca"),
    "annulus": ("inner", "outer", "start", "end"),
    "cylinder": ("bottom", "top", "start", "end"),
    "spherical_cap": ("hole", "rim", "start", "end"),
}
SEAM_EDGES = ("start", "end")        # the edges a closed mesh joins


def edge_names(mesh: ShellMeshSpec) -> tuple[str, ...]:
    """The edges a mesh has: a closed one has no seam edges, a cap closed at the pole no ``hole``."""
    names = EDGE_NAMES[mesh.kind]
    if mesh.closed:
        names = tuple(e for e in names if e not in SEAM_EDGES)
    if mesh.kind == "spherical_cap" and mesh.polar_angles[0] == 0.0:
        names = tuple(e for e in names if e != "hole")
    return names


def mesh_title(mesh: ShellMeshSpec) -> str:
    """``'closed cylinder'``, ``'spherical_cap'`` … for messages."""
    return f"closed {mesh.kind}" if mesh.closed else mesh.kind


def check_shell(n: Node, shell: Shell, materials, nodes) -> None:
    """What a shell's keys cannot say alone: its material has no Kelvin–Voigt damping, the corner
    nodes of a rectangle or triangle span an area."""
    mat = materials[shell.material]
    if mat.eta > 0.0:
        raise n.fail(f"material '{shell.material}' has Kelvin–Voigt damping (eta = {mat.eta}), which "
                     "the shell element does not model; give the shell a material without 'eta' (and use "
                     "damping.mass_proportional or the integrator's ρ∞ for its damping)", "material")
    mesh = shell.mesh
    if mesh.kind in ("rectangle", "triangle"):
        pts = [nodes[c] for c in mesh.corners]
        cross = _cross(_sub(pts[1], pts[0]), _sub(pts[-1], pts[0]))
        if math.sqrt(sum(c * c for c in cross)) <= 1e-12 * max(1e-300, _norm(_sub(pts[1], pts[0])) ** 2):
            raise n.get("mesh").fail(f"corners {list(mesh.corners)} are collinear: the {mesh.kind} has no area",
                                     "corners")


def named_points(n: Node, shells: dict[str, Shell], nodes) -> tuple[dict[str, Shell], dict[str, ShellPoint]]:
    """The named mesh points of ``shells.<shell>.points`` as ``{"shell.point": ShellPoint}``, and
    the shells with their ``points`` (names) filled in."""
    points: dict[str, ShellPoint] = {}
    shells = dict(shells)
    for k, m in n.items():
        if not m.has("points"):
            continue
        names = []
        for pname, p in m.get("points").items():
            if "." in pname or "@" in pname:
                raise p.fail(f"a point name may not contain '.' or '@', got {excerpt(pname)}")
            full = f"{k}.{pname}"
            if full in nodes:
                raise p.fail(f"'{full}' names both a scene node and this shell point; rename one")
            where = f"{p.path}.at" if isinstance(p.value, dict) else p.path
            points[full] = _point(p, shells, name=full, shell=k, where=where)
            names.append(full)
        shells[k] = dataclasses.replace(shells[k], points=tuple(names))
    return shells, points


def _point(p: Node, shells: dict[str, Shell], **given) -> ShellPoint:
    """A :class:`ShellPoint` read from ``p`` (its keys: the fields not ``given``); an ``edge`` must
    be one of its shell's."""
    point = read(p, ShellPoint, {"shell": shells}, **given)
    if point.edge is not None:
        names = edge_names(shells[point.shell].mesh)
        if point.edge not in names:
            raise p.get("edge").fail(f"expected one of {list(names)}, got {excerpt(point.edge)}")
    return point


def point_reader(shells: dict[str, Shell], points: dict[str, ShellPoint], names: dict):
    """The reader of a mesh point given in place of a node name, ``node: {shell, at, edge?,
    tolerance?}`` (the schema's ``in_place="point"``): a :class:`ShellPoint` named ``shell@key``
    (``key`` the entry that holds ``node``, e.g. ``hemi@loads.forces.pull``), registered in
    ``points`` and in the node ``names`` later keys may refer to."""
    def read_point(n: Node) -> str:
        point = _point(n, shells, name="", where=f"{n.path}.at")
        name = f"{point.shell}@{n.path.removesuffix('.node')}"
        points[name] = dataclasses.replace(point, name=name)
        names[name] = point.at
        return name
    return read_point


def edge_ref(n: Node, shells) -> EdgeRef:
    """``"shell.edge"`` → (shell, edge), checked against the shell's mesh kind."""
    text = n.string()
    shell, _, edge = text.partition(".")
    if shell not in shells:
        raise n.fail(f"unknown shell '{shell}' in edge '{text}'; shells: {sorted(shells)} (write 'shell.edge')")
    names = edge_names(shells[shell].mesh)
    if edge not in names:
        raise n.fail(f"a {mesh_title(shells[shell].mesh)} has no edge '{edge}'; its edges: {list(names)}")
    return shell, edge


def check_shell_joint(n: Node, j: ShellJoint, members, shells) -> None:
    """A ``shell_rigid`` tie needs a frame member through ``node``, a corner of its shell."""
    if j.type != "shell_rigid":
        return
    mem = members[j.member]
    if mem.kind == "truss" or (mem.actuator is not None and mem.actuator.variant == "bar"):
        raise n.fail(f"member '{j.member}' is a bar: it has no section vectors to tie a shell to", "member")
    if j.node not in (mem.start, mem.end) and j.node not in mem.via:
        raise n.fail(f"member '{j.member}' does not pass through node '{j.node}'", "member")
    if j.node not in shells[j.shell].mesh.corners:
        raise n.fail(f"node '{j.node}' is not a corner of shell '{j.shell}' (corners: {list(shells[j.shell].mesh.corners)})",
                     "node")


def _sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _norm(a) -> float:
    return math.sqrt(sum(x * x for x in a))
