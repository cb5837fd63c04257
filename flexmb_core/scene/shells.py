"""Strict parsing of the shell parts of a scene: ``shells``, edge references, edge loads and the
shell joints (``hinge_line``, ``shell_rigid``). Errors name ``file:key``, the value and what was
expected."""

from __future__ import annotations

import math

from ..errors import excerpt, name_list
from .reader import Node
from .schema import EdgeLoad, EdgeRef, Shell, ShellJoint, ShellMeshSpec, Signal

MESH_KEYS = {
    "rectangle": ({"corners", "divisions", "pattern"}, {"corners", "divisions"}),
    "triangle": ({"corners", "divisions"}, {"corners", "divisions"}),
    "annulus": ({"center", "axis", "reference", "inner_radius", "outer_radius", "angles", "divisions", "pattern"},
                {"center", "axis", "reference", "inner_radius", "outer_radius", "angles", "divisions"}),
    "cylinder": ({"center", "axis", "reference", "radius", "length", "angles", "divisions", "pattern"},
                 {"center", "axis", "reference", "radius", "length", "angles", "divisions"}),
}
EDGE_NAMES = {
    "rectangle": ("bottom", "right", "top", "left"),
    "triangle": ("ab", "bc", "ca"),
    "annulus": ("inner", "outer", "start", "end"),
    "cylinder": ("bottom", "top", "start", "end"),
}


def parse_shell(name: str, n: Node, materials, nodes) -> Shell:
    n.mapping({"mesh", "thickness", "material", "quadrature"}, {"mesh", "thickness", "material"})
    material = n.get("material").name_in(materials, "material")
    if materials[material].eta > 0.0:
        raise n.fail(f"material '{material}' has Kelvin–Voigt damping (eta = {materials[material].eta}), which "
                     "the shell element does not model; give the shell a material without 'eta' (and use "
                     "damping.mass_proportional or the integrator's ρ∞ for its damping)", "material")
    thickness = n.get("thickness").number(positive=True, unit="m")
    quad = (4, 3)
    if n.has("quadrature"):
        q = n.get("quadrature").mapping({"in_plane", "thickness"})
        quad = (q.get("in_plane", 4).integer(lo=3, hi=8), q.get("thickness", 3).integer(lo=2, hi=6))
    mesh = _mesh(n.get("mesh"), nodes)
    if mesh.kind in ("annulus", "cylinder"):
        r = mesh.inner_radius if mesh.kind == "annulus" else mesh.radius
        if mesh.kind == "cylinder" and thickness / 2 >= r:
            raise n.fail(f"half thickness {thickness / 2} m is not below the radius {r} m", "thickness")
    return Shell(name, mesh, thickness, material, quad)


def _mesh(n: Node, nodes) -> ShellMeshSpec:
    kind = n.mapping(set().union(*(k for k, _ in MESH_KEYS.values())) | {"kind"}, {"kind"}
                     ).get("kind").string(tuple(MESH_KEYS))
    allowed, required = MESH_KEYS[kind]
    extra = sorted(k for k in n.value if k not in allowed | {"kind"})
    if extra:
        raise n.fail(f"key(s) {name_list(extra)} do not apply to a '{kind}' mesh; expected {sorted(allowed)}")
    missing = sorted(k for k in required if k not in n.value)
    if missing:
        raise n.fail(f"a '{kind}' mesh needs {missing}")
    pattern = n.get("pattern", "alternate").string(("alternate", "right", "left"))
    dn = n.get("divisions")
    if kind == "triangle":
        divisions = (dn.integer(lo=1, hi=200),)
    else:
        lst = dn.list()
        if len(lst) != 2:
            raise dn.fail(f"expected [n_u, n_v] element divisions, got {excerpt(dn.value)}")
        divisions = tuple(x.integer(lo=1, hi=1000) for x in lst)
    if kind in ("rectangle", "triangle"):
        need = 4 if kind == "rectangle" else 3
        cn = n.get("corners")
        corners = tuple(c.name_in(nodes, "node") for c in cn.list())
        if len(corners) != need or len(set(corners)) != need:
            raise cn.fail(f"a {kind} needs {need} distinct corner nodes, got {name_list(corners)}")
        pts = [nodes[c] for c in corners]
        cross = _cross(_sub(pts[1], pts[0]), _sub(pts[-1], pts[0]))
        if math.sqrt(sum(c * c for c in cross)) <= 1e-12 * max(1e-300, _norm(_sub(pts[1], pts[0])) ** 2):
            raise cn.fail(f"corners {list(corners)} are collinear: the {kind} has no area")
        return ShellMeshSpec(kind, divisions, corners, pattern)
    center = n.get("center").vector(3, unit="m")
    axis = n.get("axis").vector(3, nonzero=True)
    reference = n.get("reference").vector(3, nonzero=True)
    if _norm(_cross(axis, reference)) <= 1e-9 * _norm(axis) * _norm(reference):
        raise n.fail(f"'reference' {list(reference)} is parallel to 'axis' {list(axis)}", "reference")
    angles = n.get("angles").vector(2, unit="rad")
    if not 0.0 < angles[1] - angles[0] <= 2.0 * math.pi + 1e-12:
        raise n.fail(f"expected angles [θ0, θ1] (rad) with 0 < θ1 − θ0 ≤ 2π, got {list(angles)}", "angles")
    if kind == "annulus":
        ri = n.get("inner_radius").number(positive=True, unit="m")
        ro = n.get("outer_radius").number(positive=True, unit="m")
        if not ri < ro:
            raise n.fail(f"inner_radius {ri} must be below outer_radius {ro}")
        return ShellMeshSpec(kind, divisions, (), pattern, center, axis, reference, ri, ro, angles=angles)
    return ShellMeshSpec(kind, divisions, (), pattern, center, axis, reference,
                         radius=n.get("radius").number(positive=True, unit="m"),
                         length=n.get("length").number(positive=True, unit="m"), angles=angles)


def edge_ref(n: Node, shells) -> EdgeRef:
    """``"shell.edge"`` → (shell, edge), checked against the shell's mesh kind."""
    text = n.string()
    shell, _, edge = text.partition(".")
    if shell not in shells:
        raise n.fail(f"unknown shell '{shell}' in edge '{text}'; shells: {sorted(shells)} (write 'shell.edge')")
    names = EDGE_NAMES[shells[shell].mesh.kind]
    if edge not in names:
        raise n.fail(f"a {shells[shell].mesh.kind} has no edge '{edge}'; its edges: {list(names)}")
    return shell, edge


def parse_edge_loads(n: Node, shells) -> tuple[EdgeLoad, ...]:
    from .loader import signal
    out = []
    for block, kind, key, unit in (("edge_forces", "force", "force_per_length", "N/m"),
                                   ("edge_moments", "moment", "moment_per_length", "N·m/m")):
        if not n.has(block):
            continue
        for name, m in n.get(block).items():
            m.mapping({"edge", key, "signal"}, {"edge", key})
            out.append(EdgeLoad(name, edge_ref(m.get("edge"), shells), kind, m.get(key).vector(3, unit=unit),
                                signal(m.get("signal")) if m.has("signal") else Signal()))
    return tuple(out)


def parse_shell_joint(n: Node, nodes, members, shells) -> ShellJoint:
    typ = n.get("type").string(("hinge_line", "shell_rigid"))
    if typ == "hinge_line":
        n.mapping({"type", "edges", "member"}, {"type", "edges"})
        edges = tuple(edge_ref(e, shells) for e in n.get("edges").list())
        member = n.get("member").name_in(members, "member") if n.has("member") else None
        if len(edges) + (member is not None) < 2:
            raise n.fail("a hinge line joins at least two shell edges, or one shell edge and a member", "edges")
        if len({e[0] for e in edges}) != len(edges):
            raise n.fail(f"each shell may appear once in a hinge line, got {[f'{a}.{b}' for a, b in edges]}", "edges")
        return ShellJoint(typ, edges, member)
    n.mapping({"type", "node", "shell", "member"}, {"type", "node", "shell", "member"})
    node = n.get("node").name_in(nodes, "node")
    shell = n.get("shell").name_in(shells, "shell")
    member = n.get("member").name_in(members, "member")
    mem = members[member]
    if mem.kind == "truss" or (mem.actuator is not None and mem.actuator.variant == "bar"):
        raise n.fail(f"member '{member}' is a bar: it has no section vectors to tie a shell to", "member")
    if node not in (mem.start, mem.end) and node not in mem.via:
        raise n.fail(f"member '{member}' does not pass through node '{node}'", "member")
    if node not in shells[shell].mesh.corners:
        raise n.fail(f"node '{node}' is not a corner of shell '{shell}' (corners: {list(shells[shell].mesh.corners)})",
                     "node")
    return ShellJoint(typ, member=member, node=node, shell=shell)


def _sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _norm(a) -> float:
    return math.sqrt(sum(x * x for x in a))
