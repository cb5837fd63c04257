"""Strict YAML loader: unknown keys, wrong shapes or units and dangling names are errors that
name ``file:key`` and what was expected (``flexmb check SCENE``)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

from ..errors import SceneError, excerpt, name_list
from . import strict_yaml
from .limits import DEFAULT_LIMITS, Limits, over_limit
from .reader import Node
from .schema import (ActuatorSpec, CommandProgramSpec, Force, Joint, Gravity, MassOverride, Material, Member, Moment,
                     Output, PointMass, Scene, SectionSpec, ServoSpec, Signal, SolverSpec, Support)
from .schema import ArcLengthSpec, DisplacementControlSpec, DofComponent, PathStepSpec, PhysicalLimits
from .include import compose
from .shells import axis_normal, edge_ref, parse_edge_loads, parse_edge_support, parse_shell_joint, parse_shells, place_points

OUTPUT_KINDS = {
    "node_position": ("node",),
    "node_displacement": ("node",),
    "section_vectors": ("node", "member"),
    "actuator_length": ("actuator",),
    "actuator_command": ("actuator",),
    "actuator_force": ("actuator",),
    "energy": (),
    "member_shape": ("member",),
    "platform_pose": ("nodes",),
    "actuator_velocity": ("actuator",),
    "joint_angle": ("node", "members"),
    "shell_point": ("shell", "at"),
    "shell_shape": ("shell",),
}


def parse_yaml(text: str, source: str = "<string>", limits: Limits | None = None) -> Any:
    """Parse scene YAML text the way :func:`load_scene` does: ``1e9`` is a float, duplicate keys,
    deep nesting and alias bombs are :class:`SceneError` at ``source:line:column``."""
    return strict_yaml.parse(text, source, limits)


def read_scene_text(path: str | Path, limits: Limits | None = None) -> str:
    """The UTF-8 text of a scene file (size-limited); errors name the file (and line:column)."""
    path = Path(path)
    limits = limits or DEFAULT_LIMITS
    try:
        size = path.stat().st_size
        if size > limits.max_file_bytes:
            raise over_limit(str(path), "scene file size in bytes", size, "max_file_bytes", limits)
        data = path.read_bytes()
    except OSError as exc:
        raise SceneError(str(path), f"cannot read scene file ({exc.strerror})") from None
    return strict_yaml.decode(data, str(path))


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
    root = Node(data, "", source).mapping(
        {"name", "description", "materials", "sections", "nodes", "members", "supports", "loads",
         "point_masses", "damping", "solver", "outputs", "commands", "joints", "shells", "limits"},
        {"name", "materials"})
    name = root.get("name").string()
    description = root.get("description", "").value
    if not isinstance(description, str):
        raise root.fail("expected a string", "description")

    materials = {k: _material(k, n) for k, n in root.get("materials").items()}
    sections = {k: _section(k, n) for k, n in root.get("sections", {}).items()}
    nodes = {k: n.vector(3, unit="m") for k, n in root.get("nodes", {}).items()}
    if not materials:
        raise root.fail("at least one material is required", "materials")
    members = {k: _member(k, n, materials, sections, nodes) for k, n in root.get("members", {}).items()}
    shells, points = parse_shells(root.get("shells", {}), materials, nodes)
    root = place_points(root, shells, points)         # node: {shell, at} → a generated point name
    refs = {**nodes, **{k: p.at for k, p in points.items()}}   # what supports, loads, outputs may name
    if not members and not shells:
        raise root.fail("a scene needs at least one member or one shell", "members")
    clash = sorted(set(members) & set(shells))
    if clash:
        raise root.fail(f"name(s) {name_list(clash)} are used by both a member and a shell; names must be unique", "shells")

    supports = tuple(_support(n, refs, members, shells) for n in root.get("supports", []).list())
    forces, moments, gravity = _loads(root.get("loads", {}), refs, members)
    edge_loads = parse_edge_loads(root.get("loads", {}), shells)
    pmasses = tuple(PointMass(k, n.mapping({"node", "mass"}, {"node", "mass"}).get("node").name_in(refs, "node"),
                              n.get("mass").number(positive=True, unit="kg"))
                    for k, n in root.get("point_masses", {}).items())
    damp = root.get("damping", {})
    if isinstance(damp.value, dict) and any(k in damp.value for k in ("eta", "strain_rate", "kelvin_voigt")):
        raise damp.fail("material (Kelvin–Voigt) damping is a material property: give it as "
                        "materials: {name: {eta: <Pa·s>}}; the damping block holds mass_proportional only")
    damp = damp.mapping({"mass_proportional"})
    c_m = damp.get("mass_proportional", 0.0).number(nonneg=True, unit="1/s")
    solver = _solver(root.get("solver", {}), overrides or {}, nodes)
    outputs = tuple(_output(k, n, refs, members, shells) for k, n in root.get("outputs", {}).items())
    commands = _commands(root.get("commands"), members) if root.has("commands") else None
    joint_nodes = root.get("joints", []).list()
    shell_types = ("hinge_line", "shell_rigid")
    joints = tuple(_joint(n, nodes, members) for n in joint_nodes
                   if not (isinstance(n.value, dict) and n.value.get("type") in shell_types))
    shell_joints = tuple(parse_shell_joint(n, nodes, members, shells) for n in joint_nodes
                         if isinstance(n.value, dict) and n.value.get("type") in shell_types)
    limits = _physical_limits(root.get("limits")) if root.has("limits") else None
    return Scene(name, description, source, materials, sections, nodes, members, supports, forces,
                 moments, pmasses, gravity, c_m, solver, outputs, commands, joints, shells, shell_joints,
                 edge_loads, tuple(points.values()), limits)


def _physical_limits(n: Node) -> PhysicalLimits:
    n.mapping({"max_actuator_force", "singular_configurations", "on_violation"}, set())
    force = n.get("max_actuator_force").number(positive=True, unit="N") if n.has("max_actuator_force") else math.inf
    return PhysicalLimits(force, n.get("singular_configurations", "detect").string(("detect", "ignore")),
                          n.get("on_violation", "report").string(("report", "stop")))


def _joint(n: Node, nodes, members) -> Joint:
    n.mapping({"type", "node", "members", "axis"}, {"type", "node", "members"})
    typ = n.get("type").string(("spherical", "revolute", "rigid", "hinge_line", "shell_rigid"))
    node = n.get("node").name_in(nodes, "node")
    mems = tuple(m.name_in(members, "member") for m in n.get("members").list())
    if len(mems) < 2 or len(set(mems)) != len(mems):
        raise n.fail(f"a joint connects at least two distinct members, got {name_list(mems)}", "members")
    for m in mems:
        mem = members[m]
        if node not in (mem.start, mem.end) and node not in mem.via:
            raise n.fail(f"member '{m}' does not pass through node '{node}'", "members")
        if typ != "spherical" and (mem.kind == "truss" or (mem.actuator and mem.actuator.variant == "bar")):
            raise n.fail(f"member '{m}' is a bar: it has no section vectors for a {typ} joint", "members")
    axis = None
    if typ == "revolute":
        axis = _unit3(n.get("axis").vector(3, nonzero=True))
    elif n.has("axis"):
        raise n.fail(f"'axis' applies to revolute joints only (type is '{typ}')", "axis")
    return Joint(typ, node, mems, axis)


def _commands(n: Node, members) -> CommandProgramSpec:
    n.mapping({"program", "actuators", "start", "blend_time", "switch_blend", "blend_continuity"},
              {"program", "actuators"})
    program = n.get("program").string(("stewart_appendix",))
    acts = []
    for a in n.get("actuators").list():
        name = a.name_in(members, "member")
        if members[name].kind != "actuator":
            raise a.fail(f"member '{name}' is not an actuator (kind '{members[name].kind}')")
        acts.append(name)
    if len(set(acts)) != len(acts):
        raise n.fail(f"actuators listed twice: {name_list(acts)}", "actuators")
    start = n.get("start", "blended").string(("exact", "blended"))
    blend_time = n.get("blend_time", 1.0).number(positive=True, unit="s")
    switch_blend = n.get("switch_blend", 0.0).number(nonneg=True, unit="s")
    if switch_blend > 10.0:
        raise n.fail(f"the branch switch at t = 10 s is blended over [10 − T/2, 10 + T/2]; T must lie in "
                     f"[0, 10] s (0: the exact law), got {excerpt(switch_blend)}", "switch_blend")
    continuity = n.get("blend_continuity", 2).integer(lo=2, hi=4)
    return CommandProgramSpec(program, tuple(acts), start, blend_time, switch_blend, continuity)


# -- pieces -------------------------------------------------------------------------------
def _material(name: str, n: Node) -> Material:
    n.mapping({"E", "nu", "rho", "G", "eta"}, {"E", "rho"})
    E = n.get("E").number(positive=True, unit="Pa")
    nu = n.get("nu", 0.0).number(lo=-0.99, hi=0.4999)
    rho = n.get("rho").number(positive=True, unit="kg/m³")
    G = n.get("G").number(positive=True, unit="Pa") if n.has("G") else E / (2.0 * (1.0 + nu))
    eta = 0.0
    if n.has("eta"):
        v = n.get("eta").value
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise n.fail(f"expected the Kelvin–Voigt viscosity as a finite number ≥ 0 in Pa·s, got {excerpt(v)} "
                         f"(η = 2ζE/ω gives the damping ratio ζ at the circular frequency ω; 0: undamped)", "eta")
        eta = float(v)
    return Material(name, E, nu, rho, G, eta)


def _section(name: str, n: Node) -> SectionSpec:
    shape = n.mapping({"shape", "width", "height", "radius", "outer_radius", "inner_radius",
                       "thickness", "torsion_constant", "shear_factor"}, {"shape"}
                      ).get("shape").string(("rectangle", "circle", "tube"))
    allowed = {"rectangle": {"width", "height"}, "circle": {"radius"},
               "tube": {"outer_radius", "inner_radius", "thickness"}}[shape]
    extra = sorted(k for k in n.value if k not in allowed | {"shape", "torsion_constant", "shear_factor"})
    if extra:
        raise n.fail(f"key(s) {name_list(extra)} do not apply to a {shape}; expected {sorted(allowed)}")
    if shape == "rectangle":
        dims = (n.get("width").number(positive=True, unit="m"), n.get("height").number(positive=True, unit="m"))
    elif shape == "circle":
        dims = (n.get("radius").number(positive=True, unit="m"),)
    else:
        ro = n.get("outer_radius").number(positive=True, unit="m")
        if n.has("inner_radius") == n.has("thickness"):
            raise n.fail("a tube needs exactly one of 'inner_radius' or 'thickness'")
        ri = (n.get("inner_radius").number(nonneg=True, unit="m") if n.has("inner_radius")
              else ro - n.get("thickness").number(positive=True, unit="m"))
        if not 0.0 <= ri < ro:
            raise n.fail(f"inner radius {ri} must lie in [0, outer_radius={ro})")
        dims = (ro, ri)
    tc = n.get("torsion_constant").number(positive=True, unit="m⁴") if n.has("torsion_constant") else None
    ks = n.get("shear_factor").number(positive=True, hi=2.0) if n.has("shear_factor") else None
    return SectionSpec(name, shape, dims, tc, ks)


def signal(n: Node, *, default_value: float = 1.0) -> Signal:
    """Parse a time signal (see :class:`Signal`)."""
    if isinstance(n.value, (int, float)) and not isinstance(n.value, bool):
        return Signal("constant", value=n.number())
    kind = n.mapping({"kind", "value", "start", "end", "t0", "duration", "shape", "offset",
                      "amplitude", "frequency", "phase", "t", "values", "rate"}, {"kind"}
                     ).get("kind").string(("constant", "ramp", "sine", "table", "spin_up"))
    keys = {"constant": {"value"}, "ramp": {"start", "end", "t0", "duration", "shape"},
            "spin_up": {"rate", "duration"},
            "sine": {"offset", "amplitude", "frequency", "phase"}, "table": {"t", "values"}}[kind]
    extra = sorted(k for k in n.value if k not in keys | {"kind"})
    if extra:
        raise n.fail(f"key(s) {name_list(extra)} do not apply to a '{kind}' signal; expected {sorted(keys)}")
    if kind == "constant":
        return Signal("constant", value=n.get("value", default_value).number())
    if kind == "ramp":
        return Signal("ramp", start=n.get("start", 0.0).number(), end=n.get("end", default_value).number(),
                      t0=n.get("t0", 0.0).number(nonneg=True),
                      duration=n.get("duration").number(positive=True, unit="s"),
                      shape=n.get("shape", "linear").string(("linear", "smooth", "cycloidal")))
    if kind == "spin_up":
        return Signal("spin_up", amplitude=n.get("rate").number(unit="rad/s"),
                      duration=n.get("duration").number(positive=True, unit="s"))
    if kind == "sine":
        return Signal("sine", offset=n.get("offset", 0.0).number(), amplitude=n.get("amplitude").number(),
                      frequency=n.get("frequency").number(nonneg=True, unit="Hz"),
                      phase=n.get("phase", 0.0).number(unit="rad"))
    t = n.get("t").numbers(min_len=2)
    v = n.get("values").numbers(min_len=2)
    if len(t) != len(v):
        raise n.fail(f"'t' has {len(t)} entries but 'values' has {len(v)}")
    if any(b <= a for a, b in zip(t, t[1:])):
        raise n.fail(f"'t' must be strictly increasing, got {excerpt(list(t))}", "t")
    return Signal("table", table_t=t, table_v=v)


def _member(name: str, n: Node, materials, sections, nodes) -> Member:
    n.mapping({"kind", "from", "to", "elements", "order", "material", "section", "up", "arc",
               "actuator", "mass", "integration", "via"}, {"kind", "from", "to", "material", "section"})
    kind = n.get("kind").string(("frame", "truss", "actuator"))
    start = n.get("from").name_in(nodes, "node")
    end = n.get("to").name_in(nodes, "node")
    if start == end:
        raise n.fail(f"'from' and 'to' are the same node '{start}'")
    if math.dist(nodes[start], nodes[end]) <= 0.0:
        raise n.fail(f"nodes '{start}' and '{end}' coincide: a member needs a positive length")
    actuator = None
    if kind == "actuator":
        a = n.get("actuator", {}).mapping({"variant", "command", "stroke", "servo"})
        stroke = None
        if a.has("stroke"):
            stroke = a.get("stroke").vector(2, unit="m")
            if not 0.0 < stroke[0] < stroke[1]:
                raise a.fail(f"expected 0 < min < max (m), got {list(stroke)}", "stroke")
        actuator = ActuatorSpec(a.get("variant", "frame").string(("frame", "bar")),
                                signal(a.get("command")) if a.has("command") else None, stroke,
                                _servo(a.get("servo")) if a.has("servo") else None)
    elif n.has("actuator"):
        raise n.fail(f"only members of kind 'actuator' take an 'actuator' block (kind is '{kind}')", "actuator")
    is_bar = kind == "truss" or (actuator is not None and actuator.variant == "bar")
    order = n.get("order", 1 if is_bar else 3).integer(lo=1, hi=4)
    if is_bar and order != 1:
        raise n.fail(f"bars are 2-node elements (order 1), got order {order}", "order")
    elements = n.get("elements", 1 if is_bar else 4).integer(lo=1, hi=10000)
    up = n.get("up").vector(3, nonzero=True) if n.has("up") else None
    arc = None
    if n.has("arc"):
        a = n.get("arc").mapping({"center"}, {"center"})
        arc = a.get("center").vector(3, unit="m")
        r0, r1 = math.dist(arc, nodes[start]), math.dist(arc, nodes[end])
        if abs(r0 - r1) > 1e-9 * max(r0, r1):
            raise a.fail(f"'{start}' and '{end}' are not equidistant from the centre ({r0} vs {r1} m)", "center")
        if is_bar:
            raise n.fail("arcs are for frame members", "arc")
    mass = None
    if n.has("mass"):
        m = n.get("mass").mapping({"per_length", "rotary_inertia"})
        mass = MassOverride(m.get("per_length").number(positive=True, unit="kg/m") if m.has("per_length") else None,
                            m.get("rotary_inertia").vector(2, unit="kg·m") if m.has("rotary_inertia") else None)
    via = ()
    if n.has("via"):
        via = tuple(v.name_in(nodes, "node") for v in n.get("via").list())
        if start in via or end in via or len(set(via)) != len(via):
            raise n.fail(f"'via' must list distinct interior nodes, got {name_list(via)}", "via")
    return Member(name, kind, start, end, elements, order, n.get("material").name_in(materials, "material"),
                  n.get("section").name_in(sections, "section"), up, arc, actuator, mass,
                  n.get("integration", "reduced").string(("reduced", "full")), via)


def _servo(n: Node) -> ServoSpec:
    """``actuator.servo``: every key required, positive and finite (SI)."""
    keys = {"bandwidth_hz", "damping_ratio", "max_rate", "max_accel"}
    n.mapping(keys, keys)
    return ServoSpec(n.get("bandwidth_hz").number(positive=True, unit="Hz"),
                     n.get("damping_ratio").number(positive=True),
                     n.get("max_rate").number(positive=True, unit="m/s"),
                     n.get("max_accel").number(positive=True, unit="m/s²"))


def _support(n: Node, nodes, members, shells) -> Support:
    n.mapping({"node", "edge", "type", "member", "vector", "rotation", "translation", "axis", "normal"}, {"type"})
    if n.has("edge"):
        return parse_edge_support(n, shells)
    typ = n.get("type").string(("clamp", "ball", "roller", "fixed_vector", "revolute", "driven"))
    node = n.get("node").name_in(nodes, "node")
    if typ == "roller":                                 # fixes the position along 'normal' only
        extra = sorted(k for k in n.value if k not in ("node", "type", "normal"))
        if extra:
            raise n.fail(f"key(s) {name_list(extra)} do not apply to a roller; expected 'node', 'type', 'normal'")
        return Support(node, typ, normal=axis_normal(n, typ))
    if n.has("normal"):
        raise n.fail(f"'normal' applies to roller supports and shell-edge symmetry supports (type is '{typ}')",
                     "normal")
    member = n.get("member").name_in(members, "member") if n.has("member") else None
    vector = None
    if typ == "fixed_vector":
        if member is None:
            raise n.fail("a fixed_vector support needs 'member' (whose section vector is fixed)")
        vector = n.get("vector").string(("v1", "v2"))
    elif n.has("vector"):
        raise n.fail(f"'vector' applies to type fixed_vector only (type is '{typ}')", "vector")
    if member is not None and node not in (members[member].start, members[member].end):
        raise n.fail(f"node '{node}' is not an end of member '{member}'")
    axis = angle = direction = distance = None
    if typ == "revolute":
        if member is None:
            raise n.fail("a revolute support needs 'member' (whose section vector lies on the axis)")
        axis = _unit3(n.get("axis").vector(3, nonzero=True))
    elif n.has("axis") and typ != "driven":
        raise n.fail(f"'axis' applies to revolute supports only (type is '{typ}')", "axis")
    if typ == "driven":
        if not (n.has("rotation") or n.has("translation")):
            raise n.fail("a driven support needs 'rotation' and/or 'translation'")
        if n.has("rotation"):
            r = n.get("rotation").mapping({"axis", "angle"}, {"axis", "angle"})
            axis = _unit3(r.get("axis").vector(3, nonzero=True))
            angle = signal(r.get("angle"))
        if n.has("translation"):
            tr = n.get("translation").mapping({"direction", "distance"}, {"direction", "distance"})
            direction = _unit3(tr.get("direction").vector(3, nonzero=True))
            distance = signal(tr.get("distance"))
    else:
        for k in ("rotation", "translation"):
            if n.has(k):
                raise n.fail(f"'{k}' applies to type driven only (type is '{typ}')", k)
    return Support(node, typ, member, vector, axis, angle, direction, distance)


def _unit3(v: tuple[float, ...]) -> tuple[float, float, float]:
    norm = math.sqrt(sum(x * x for x in v))
    return (v[0] / norm, v[1] / norm, v[2] / norm)


def _loads(n: Node, nodes, members):
    n.mapping({"gravity", "forces", "moments", "edge_forces", "edge_moments"})
    gravity = None
    if n.has("gravity"):
        g = n.get("gravity")
        if isinstance(g.value, list):
            gravity = Gravity(g.vector(3, unit="m/s²"), Signal())
        else:
            g.mapping({"acceleration", "signal"}, {"acceleration"})
            gravity = Gravity(g.get("acceleration").vector(3, unit="m/s²"),
                              signal(g.get("signal")) if g.has("signal") else Signal())
    forces = []
    for k, f in n.get("forces", {}).items():
        f.mapping({"node", "force", "signal"}, {"node", "force"})
        forces.append(Force(k, f.get("node").name_in(nodes, "node"), f.get("force").vector(3, unit="N"),
                            signal(f.get("signal")) if f.has("signal") else Signal()))
    moments = []
    for k, m in n.get("moments", {}).items():
        m.mapping({"node", "member", "moment", "follower", "signal"}, {"node", "member", "moment"})
        node = m.get("node").name_in(nodes, "node")
        member = m.get("member").name_in(members, "member")
        mem = members[member]
        if node not in (mem.start, mem.end):
            raise m.fail(f"node '{node}' is not an end of member '{member}'", "node")
        if mem.kind == "truss" or (mem.actuator is not None and mem.actuator.variant == "bar"):
            raise m.fail(f"member '{member}' has no section vectors (bars carry no moments)", "member")
        moments.append(Moment(k, node, member, m.get("moment").vector(3, unit="N·m"),
                              m.get("follower", False).boolean(),
                              signal(m.get("signal")) if m.has("signal") else Signal()))
    return tuple(forces), tuple(moments), gravity


def _solver(n: Node, overrides: dict[str, Any], nodes: dict | None = None) -> SolverSpec:
    fields = {f.name for f in dataclasses.fields(SolverSpec)}
    n.mapping(fields)
    merged = dict(n.value)
    merged.update({k: v for k, v in overrides.items() if v is not None})
    n = Node(merged, n.path or "solver", n.source)
    d = SolverSpec()
    s = SolverSpec(
        analysis=n.get("analysis", d.analysis).string(("dynamic", "static")),
        integrator=n.get("integrator", d.integrator).string(("newmark", "generalized_alpha", "chung_hulbert")),
        dt=n.get("dt", d.dt).number(positive=True, unit="s"),
        until=n.get("until", d.until).number(positive=True, unit="s"),
        beta=n.get("beta", d.beta).number(positive=True, hi=0.5),
        gamma=n.get("gamma", d.gamma).number(lo=0.5, hi=1.0),
        rho_inf=n.get("rho_inf", d.rho_inf).number(lo=0.0, hi=1.0),
        tolerance=n.get("tolerance", d.tolerance).number(positive=True, hi=1e-2),
        max_iterations=n.get("max_iterations", d.max_iterations).integer(lo=1, hi=1000),
        initial_acceleration=n.get("initial_acceleration", d.initial_acceleration).string(("consistent", "zero")),
        initial_state=n.get("initial_state", d.initial_state).string(("rest", "static")),
        on_unconverged=n.get("on_unconverged", d.on_unconverged).string(("substep", "stop", "accept_flagged")),
        max_substep_levels=n.get("max_substep_levels", d.max_substep_levels).integer(lo=0, hi=12),
        newton=n.get("newton", d.newton).string(("full", "modified")),
        modified_contraction=n.get("modified_contraction", d.modified_contraction).number(positive=True, hi=0.9),
        tangent_max_age=n.get("tangent_max_age", d.tangent_max_age).integer(lo=1, hi=10**9),
    )
    return _static_control(n, s, nodes or {})


_COMPONENTS = ("x", "y", "z")
_PATH_KEYS = ("arc_length", "displacement", "until_load_factor", "until_displacement", "max_steps")


def _static_control(n: Node, s: SolverSpec, nodes: dict) -> SolverSpec:
    """The statics keys of ``solver`` (control, its block, monitor, goals), checked together:
    a key that does not apply to the chosen analysis or control is an error, not ignored."""
    control = n.get("control", "load").string(("load", "arc_length", "displacement"))
    static_keys = ("control", "monitor", "allow_snap_through") + _PATH_KEYS
    if s.analysis != "static":
        given = [k for k in static_keys if n.has(k)]
        if given:
            raise n.fail(f"key(s) {name_list(given)} apply to analysis: static only (analysis is '{s.analysis}')",
                         given[0])
        return s
    if control == "load":
        given = [k for k in _PATH_KEYS if n.has(k)]
        if given:
            raise n.fail(f"key(s) {name_list(given)} apply to control: arc_length or displacement; "
                         f"load control steps by 'dt' to 'until'", given[0])
    other = "displacement" if control == "arc_length" else "arc_length"
    if n.has(other):
        raise n.fail(f"'{other}' applies to control: {other} (control is '{control}')", other)
    arc = disp = None
    if control == "arc_length":
        if not n.has("arc_length"):
            raise n.fail("control: arc_length needs an 'arc_length' block, e.g. {initial: 0.05} (m)")
        arc = _arc_length(n.get("arc_length"))
    elif control == "displacement":
        if not n.has("displacement"):
            raise n.fail("control: displacement needs a 'displacement' block {node, component, to}")
        disp = _displacement_control(n.get("displacement"), nodes)
    monitor = _dof_component(n.get("monitor"), nodes) if n.has("monitor") else (disp.dof if disp else None)
    until_lf = n.get("until_load_factor").number() if n.has("until_load_factor") else None
    until_u = n.get("until_displacement").number(unit="m") if n.has("until_displacement") else None
    if until_u is not None and until_u == 0.0:
        raise n.fail("expected a non-zero displacement (m) to stop at, got 0", "until_displacement")
    if until_u is not None and monitor is None:
        raise n.fail("'until_displacement' needs a 'monitor' {node, component} (the displacement it bounds)",
                     "until_displacement")
    if control == "arc_length":
        if until_lf is None and until_u is None:
            raise n.fail("control: arc_length needs a goal: 'until_load_factor' and/or 'until_displacement'")
        if monitor is None:
            raise n.fail("control: arc_length needs a 'monitor' {node, component}: the displacement "
                         "reported with the load factor")
    return dataclasses.replace(
        s, control=control, arc_length=arc, displacement=disp, monitor=monitor,
        until_load_factor=until_lf, until_displacement=until_u,
        max_steps=n.get("max_steps", s.max_steps).integer(lo=1, hi=10**6),
        allow_snap_through=n.get("allow_snap_through", s.allow_snap_through).boolean())


def _dof_component(n: Node, nodes: dict) -> DofComponent:
    """``{node, component: x|y|z}``."""
    keys = {f.name for f in dataclasses.fields(DofComponent)}
    n.mapping(keys, keys)
    return DofComponent(n.get("node").name_in(nodes, "node"), n.get("component").string(_COMPONENTS))


def _path_step(n: Node, what: str) -> PathStepSpec:
    """The increment keys shared by ``arc_length`` and ``displacement`` (m; ``what`` names them)."""
    initial = n.get("initial").number(positive=True, unit="m")
    lo = n.get("min", initial * 1e-3).number(positive=True, unit="m")
    hi = n.get("max", initial * 10.0).number(positive=True, unit="m")
    if not lo <= initial <= hi:
        raise n.fail(f"expected min ≤ initial ≤ max for the {what}, got min {excerpt(lo)}, initial "
                     f"{excerpt(initial)}, max {excerpt(hi)} (m)")
    return PathStepSpec(initial, lo, hi, n.get("target_iterations", 5).integer(lo=1, hi=100))


def _arc_length(n: Node) -> ArcLengthSpec:
    step_keys = {f.name for f in dataclasses.fields(PathStepSpec)}
    n.mapping(step_keys | {f.name for f in dataclasses.fields(ArcLengthSpec)} - {"step"}, {"initial"})
    kind = n.get("kind", "cylindrical").string(("cylindrical", "spherical"))
    if kind == "cylindrical" and n.has("psi"):
        raise n.fail("'psi' (the load term's weight) applies to kind: spherical only", "psi")
    return ArcLengthSpec(_path_step(n, "arc length"), kind, n.get("psi", 1.0).number(positive=True))


def _displacement_control(n: Node, nodes: dict) -> DisplacementControlSpec:
    step_keys = {f.name for f in dataclasses.fields(PathStepSpec)}
    dof_keys = {f.name for f in dataclasses.fields(DofComponent)}
    n.mapping(step_keys | dof_keys | {"to"}, {"node", "component", "to", "initial"})
    dof = DofComponent(n.get("node").name_in(nodes, "node"), n.get("component").string(_COMPONENTS))
    to = n.get("to").number(unit="m")
    if to == 0.0:
        raise n.fail("expected a non-zero target displacement (m), got 0", "to")
    return DisplacementControlSpec(dof, to, _path_step(n, "displacement increment"))


def _output(name: str, n: Node, nodes, members, shells) -> Output:
    kind = n.mapping({"kind", "node", "member", "actuator", "nodes", "members", "shell", "at", "edge"},
                     {"kind"}).get("kind").string(tuple(OUTPUT_KINDS))
    need = OUTPUT_KINDS[kind]
    extra = sorted(k for k in n.value if k != "kind" and k not in need and not (kind == "shell_point" and k == "edge"))
    if extra:
        raise n.fail(f"key(s) {name_list(extra)} do not apply to output kind '{kind}'; expected {list(need)}")
    node = n.get("node").name_in(nodes, "node") if "node" in need else None
    member = n.get("member").name_in(members, "member") if "member" in need else None
    if "shell" in need:
        shell = n.get("shell").name_in(shells, "shell")
        at = n.get("at").vector(3, unit="m") if "at" in need else None
        edge = edge_ref(n.get("edge"), shells) if n.has("edge") else None
        if edge is not None and edge[0] != shell:
            raise n.fail(f"edge '{edge[0]}.{edge[1]}' is not an edge of shell '{shell}'", "edge")
        return Output(name, kind, shell=shell, at=at, edge=edge)
    pose_nodes: tuple[str, ...] = ()
    if "members" in need:
        lst = [m.name_in(members, "member") for m in n.get("members").list()]
        if not 1 <= len(lst) <= 2:
            raise n.fail(f"a joint angle relates 1 member (to its reference) or 2 members, got {name_list(lst)}", "members")
        for m in lst:
            mem = members[m]
            if mem.kind == "truss" or (mem.actuator and mem.actuator.variant == "bar"):
                raise n.fail(f"member '{m}' has no section vectors", "members")
            if node not in (mem.start, mem.end) and node not in mem.via:
                raise n.fail(f"member '{m}' does not pass through node '{node}'", "members")
        pose_nodes = tuple(lst)
    if "nodes" in need:
        lst = n.get("nodes").list()
        if len(lst) != 3:
            raise n.fail(f"a platform pose is defined by 3 nodes, got {len(lst)}", "nodes")
        pose_nodes = tuple(x.name_in(nodes, "node") for x in lst)
    actuator = None
    if "actuator" in need:
        actuator = n.get("actuator").name_in(members, "member")
        if members[actuator].kind != "actuator":
            raise n.fail(f"member '{actuator}' is not an actuator (kind '{members[actuator].kind}')", "actuator")
    if kind == "section_vectors":
        mem = members[member]
        if mem.kind == "truss" or (mem.actuator and mem.actuator.variant == "bar"):
            raise n.fail(f"member '{member}' has no section vectors", "member")
        if node not in (mem.start, mem.end):
            raise n.fail(f"node '{node}' is not an end of member '{member}'", "node")
    return Output(name, kind, node, member, actuator, pose_nodes)
