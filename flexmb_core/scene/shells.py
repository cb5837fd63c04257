"""Strict parsing of the shell parts of a scene: ``shells`` (mesh generators, named mesh
``points``), edge references, edge supports (``clamp``, ``ball``, ``symmetry``), edge loads, the
shell joints (``hinge_line``, ``shell_rigid``) and mesh nodes chosen by coordinates wherever a
support, force, point mass or output names a ``node``. Errors name ``file:key``, the value and what
was expected.

Mesh points: ``shells.cap.points: {pole: [0, 0, 10]}`` names the mesh node nearest to that
reference position ``cap.pole``; ``{at: [...], edge: rim, tolerance: 1e-3}`` restricts the search to
an edge and sets the distance it may be off (default 10⁻⁶ of the shell's size). In place of a node
name, ``node: {shell: cap, at: [x, y, z]}`` (same optional ``edge``, ``tolerance``) does the same
without a name. Compiling fails (naming the key) when no mesh node lies that close."""

from __future__ import annotations

import math

from ..errors import excerpt, name_list
from .reader import Node
from .overrides import set_path
from .schema import EdgeLoad, EdgeRef, Shell, ShellJoint, ShellMeshSpec, ShellPoint, Signal, Support

_ARC = {"center", "axis", "reference", "angles", "divisions", "pattern", "closed"}
MESH_KEYS = {                        # kind: (allowed keys, required keys; 'angles' unless closed)
    "rectangle": ({"corners", "divisions", "pattern"}, {"corners", "divisions"}),
    "triangle": ({"corners", "divisions"}, {"corners", "divisions"}),
    "annulus": (_ARC | {"inner_radius", "outer_radius"},
                {"center", "axis", "reference", "inner_radius", "outer_radius", "divisions"}),
    "cylinder": (_ARC | {"radius", "length"}, {"center", "axis", "reference", "radius", "length", "divisions"}),
    "spherical_cap": (_ARC | {"radius", "polar_angles"},
                      {"center", "axis", "reference", "radius", "polar_angles", "divisions"}),
}
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


def parse_shells(n: Node, materials, nodes) -> tuple[dict[str, Shell], dict[str, ShellPoint]]:
    """The ``shells`` block: the shells, and their named mesh points as ``{"shell.point": ShellPoint}``."""
    shells = {k: parse_shell(k, m, materials, nodes) for k, m in n.items()}
    points: dict[str, ShellPoint] = {}
    for k, m in n.items():
        if not m.has("points"):
            continue
        for pname, p in m.get("points").items():
            if "." in pname or "@" in pname:
                raise p.fail(f"a point name may not contain '.' or '@', got {excerpt(pname)}")
            full = f"{k}.{pname}"
            if full in nodes:
                raise p.fail(f"'{full}' names both a scene node and this shell point; rename one")
            if isinstance(p.value, list):
                points[full] = ShellPoint(full, k, p.vector(3, unit="m"), where=p.path)
            else:
                points[full] = _point(full, k, p.mapping({"at", "edge", "tolerance"}, {"at"}), shells)
    return shells, points


def _point(name: str, shell: str, p: Node, shells) -> ShellPoint:
    edge = None
    if p.has("edge"):
        names = edge_names(shells[shell].mesh)
        edge = p.get("edge").string(names)
    tol = p.get("tolerance").number(positive=True, unit="m") if p.has("tolerance") else None
    return ShellPoint(name, shell, p.get("at").vector(3, unit="m"), edge, tol, f"{p.path}.at")


NODE_REF_PLACES = (("supports", "list"), ("loads.forces", "map"), ("point_masses", "map"), ("outputs", "map"))


def place_points(root: Node, shells, points: dict[str, ShellPoint]) -> Node:
    """Replace every ``node: {shell, at, …}`` of supports, forces, point masses and outputs by a
    generated name ``shell@key`` registered in ``points`` (in a copy of the scene mapping; the
    caller's data stay untouched)."""
    data = dict(root.value)
    for place, how in NODE_REF_PLACES:
        block: object = data
        for key in place.split("."):
            block = block.get(key) if isinstance(block, dict) else None
        if not isinstance(block, (list, dict)):
            continue
        entries = enumerate(block) if how == "list" else block.items()
        for key, entry in list(entries):
            if not (isinstance(entry, dict) and isinstance(entry.get("node"), dict)):
                continue
            path = f"{place}[{key}]" if how == "list" else f"{place}.{key}"
            ref = Node(entry["node"], f"{path}.node", root.source)
            ref.mapping({"shell", "at", "edge", "tolerance"}, {"shell", "at"})
            shell = ref.get("shell").name_in(shells, "shell")
            name = f"{shell}@{path}"
            points[name] = _point(name, shell, ref, shells)
            set_path(data, place.split(".") + [str(key), "node"], name, item=path)
    return Node(data, root.path, root.source)


def parse_edge_support(n: Node, shells) -> Support:
    """A support on every node of a shell edge: ``clamp`` fixes Y and G, ``ball`` fixes Y,
    ``roller`` (with ``normal`` n along x, y or z) fixes n·Y only (the edge slides in the plane;
    two rollers make a diaphragm), ``symmetry`` (the symmetry plane's ``normal`` n along x, y or z)
    fixes n·Y and n·G.

    Why n·Y and n·G: a mirror-symmetric deformation maps every material fibre through the plane
    onto itself. The fibre of a node is y(ζ) = Y + (h/2)(ζ + aζ²) G, so S y = y for all ζ with the
    reflection S = I − 2nnᵀ needs n·Y = n·Y⁰ (the node stays in the plane) and n·G = 0 (the director
    stays in it: the shell meets the plane at a right angle, turning only about n — the rotations
    about the plane's in-plane axes, which the symmetry forbids, are exactly the changes of n·G).
    The director's length (thickness stretch) and the strain rate a are symmetric and stay free.
    Only the component along a coordinate axis is a DOF, hence the axis-aligned normal (a general
    plane would need a constraint equation)."""
    if n.has("node"):
        raise n.fail("a support is on a 'node' or on a shell 'edge', not both")
    typ = n.get("type").value
    allowed = ("edge", "type", "normal") if typ in ("symmetry", "roller") else ("edge", "type")
    extra = sorted(k for k in n.value if k not in allowed)
    if extra:
        raise n.fail(f"key(s) {name_list(extra)} do not apply to an edge support of type {excerpt(typ)}; "
                     f"expected {list(allowed)}")
    typ = n.get("type").string(("clamp", "ball", "roller", "symmetry"))
    edge = edge_ref(n.get("edge"), shells)
    if typ in ("clamp", "ball"):
        return Support("", typ, edge=edge)
    return Support("", typ, edge=edge, normal=axis_normal(n, typ))


def axis_normal(n: Node, typ: str) -> tuple[float, float, float]:
    """The unit ``normal`` of a roller or symmetry support, which must lie along x, y or z."""
    if not n.has("normal"):
        raise n.fail(f"a {typ} support needs 'normal': the plane's normal along x, y or z, e.g. [1, 0, 0]")
    v = n.get("normal").vector(3, nonzero=True)
    norm = math.sqrt(sum(x * x for x in v))
    if max(abs(x) for x in v) < norm * (1.0 - 1e-12):
        raise n.fail(f"a {typ} normal must lie along x, y or z (it fixes one DOF component per node; "
                     f"a skew plane would need a constraint equation), got {excerpt(list(v))}", "normal")
    return (v[0] / norm, v[1] / norm, v[2] / norm)


def parse_shell(name: str, n: Node, materials, nodes) -> Shell:
    n.mapping({"mesh", "thickness", "material", "quadrature", "points"}, {"mesh", "thickness", "material"})
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
    if mesh.kind in ("cylinder", "spherical_cap") and thickness / 2 >= mesh.radius:
        raise n.fail(f"half thickness {thickness / 2} m is not below the radius {mesh.radius} m", "thickness")
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
    closed = n.get("closed", False).boolean()
    angles = _angles(n, closed)
    if kind == "annulus":
        ri = n.get("inner_radius").number(positive=True, unit="m")
        ro = n.get("outer_radius").number(positive=True, unit="m")
        if not ri < ro:
            raise n.fail(f"inner_radius {ri} must be below outer_radius {ro}")
        return ShellMeshSpec(kind, divisions, (), pattern, center, axis, reference, ri, ro, angles=angles,
                             closed=closed)
    radius = n.get("radius").number(positive=True, unit="m")
    if kind == "cylinder":
        return ShellMeshSpec(kind, divisions, (), pattern, center, axis, reference, radius=radius,
                             length=n.get("length").number(positive=True, unit="m"), angles=angles, closed=closed)
    polar = n.get("polar_angles").vector(2, unit="rad")
    if not 0.0 <= polar[0] < polar[1] < math.pi:
        raise n.fail(f"expected polar angles [α0, α1] (rad, from the pole 'axis') with 0 ≤ α0 < α1 < π "
                     f"(α0 = 0: closed at the pole, α0 > 0: a polar hole), got {excerpt(list(polar))}", "polar_angles")
    return ShellMeshSpec(kind, divisions, (), pattern, center, axis, reference, radius=radius, angles=angles,
                         polar_angles=polar, closed=closed)


def _angles(n: Node, closed: bool) -> tuple[float, float]:
    """``angles`` [θ0, θ1] (rad): required for an open mesh; a closed one takes a full turn
    (the default [0, 2π])."""
    if closed and not n.has("angles"):
        return (0.0, 2.0 * math.pi)
    if not n.has("angles"):
        raise n.fail("missing required key 'angles' ([θ0, θ1] in rad; or closed: true for a full turn)")
    angles = n.get("angles").vector(2, unit="rad")
    if not 0.0 < angles[1] - angles[0] <= 2.0 * math.pi + 1e-12:
        raise n.fail(f"expected angles [θ0, θ1] (rad) with 0 < θ1 − θ0 ≤ 2π, got {list(angles)}", "angles")
    if closed and abs(angles[1] - angles[0] - 2.0 * math.pi) > 1e-9:
        raise n.fail(f"a closed mesh turns once: θ1 − θ0 must be 2π, got {excerpt(angles[1] - angles[0])} rad "
                     f"(leave out 'angles' or drop 'closed')", "angles")
    return angles


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
        if len(set(edges)) != len(edges):
            raise n.fail(f"each edge may appear once in a hinge line, got {[f'{a}.{b}' for a, b in edges]}", "edges")
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
