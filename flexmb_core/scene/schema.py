"""Frozen dataclasses of a scene (SI units throughout: m, kg, s, N, Pa, rad)."""

from __future__ import annotations

import math

from dataclasses import dataclass, field

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Signal:
    """A scalar function of time.

    kinds: ``spin_up`` (Simo–Vu-Quoc angle law: rate ramps smoothly to ``amplitude`` rad/s over
    ``duration``, then constant), ``constant`` (value), ``ramp`` (start → end over [t0, t0+duration], shape linear /
    smooth (C² quintic) / cycloidal (C², SPEC §4.2)), ``sine`` (offset + amplitude·sin(2π f t + phase)),
    ``table`` (piecewise linear in (t, value), held outside).
    """

    kind: str = "constant"
    value: float = 1.0
    start: float = 0.0
    end: float = 1.0
    t0: float = 0.0
    duration: float = 1.0
    shape: str = "linear"
    offset: float = 0.0
    amplitude: float = 0.0
    frequency: float = 0.0
    phase: float = 0.0
    table_t: tuple[float, ...] = ()
    table_v: tuple[float, ...] = ()


@dataclass(frozen=True)
class Material:
    """Elastic constants, density and the Kelvin–Voigt viscosity ``eta`` (Pa·s, 0: undamped).

    Material damping: ``S = C : (E + τ Ė)`` with the retardation time ``τ = eta / E``; it damps
    deformation only (never rigid motion), each linear mode with the ratio ``ζ = ω τ / 2``.
    """

    name: str
    E: float
    nu: float
    rho: float
    G: float
    eta: float = 0.0

    @property
    def retardation_time(self) -> float:
        """τ = η / E (s)."""
        return self.eta / self.E


@dataclass(frozen=True)
class SectionSpec:
    name: str
    shape: str                      # rectangle | circle | tube
    dims: tuple[float, ...]          # rectangle (width, height); circle (radius,); tube (ro, ri)
    torsion_constant: float | None = None
    shear_factor: float | None = None


@dataclass(frozen=True)
class ServoSpec:
    """An actuator's position servo (see :mod:`flexmb_core.servo`): the actuator's length x
    follows the commanded length u by x'' = ωn²(u − x) − 2ζωn x' with ωn = 2π ``bandwidth_hz``,
    ζ = ``damping_ratio``, |x'| ≤ ``max_rate`` (m/s) and |x''| ≤ ``max_accel`` (m/s²)."""

    bandwidth_hz: float
    damping_ratio: float
    max_rate: float
    max_accel: float


@dataclass(frozen=True)
class ActuatorSpec:
    variant: str                     # frame | bar
    command: Signal | None           # commanded length L(t) (m); None → hold the reference length
    stroke: tuple[float, float] | None
    servo: ServoSpec | None = None   # None: the length is the commanded length (an ideal actuator)


@dataclass(frozen=True)
class MassOverride:
    per_length: float | None = None            # ρA (kg/m)
    rotary_inertia: tuple[float, float] | None = None  # (ρI1, ρI2) (kg·m)


@dataclass(frozen=True)
class Member:
    name: str
    kind: str                        # frame | truss | actuator
    start: str
    end: str
    elements: int
    order: int
    material: str
    section: str
    up: Vec3 | None
    arc_center: Vec3 | None
    actuator: ActuatorSpec | None
    mass: MassOverride | None
    integration: str = "reduced"     # reduced (p Gauss points along the axis) | full (p + 2)
    via: tuple[str, ...] = ()        # named nodes the member passes through (continuous vectors)


EdgeRef = tuple[str, str]            # (shell name, edge name)


@dataclass(frozen=True)
class ShellMeshSpec:
    """A mesh generator of cubic shell triangles (:mod:`flexmb_core.model.shell_mesh`).

    ``rectangle``: bilinear patch through 4 ``corners`` (scene nodes), ``divisions`` (n_u, n_v);
    ``triangle``: 3 ``corners``, ``divisions`` (n,); ``annulus``: flat sector about ``center`` with
    normal ``axis``, radii, ``angles`` (rad) from ``reference``; ``cylinder``: patch of ``radius`` and
    ``length`` along ``axis`` from ``center``, ``angles`` (rad) from ``reference``;
    ``spherical_cap``: sphere of ``radius`` about ``center``, ``polar_angles`` [α0, α1] (rad) from the
    pole ``axis`` (α0 > 0: a polar hole; α0 = 0: closed at the pole), ``angles`` (rad) from
    ``reference``. ``closed`` (annulus, cylinder, cap; a full turn of ``angles``): the seam is joined
    (shared mesh nodes), not slit.
    """

    kind: str                        # rectangle | triangle | annulus | cylinder | spherical_cap
    divisions: tuple[int, ...]
    corners: tuple[str, ...] = ()
    pattern: str = "alternate"       # cell diagonals: alternate | right | left
    center: Vec3 | None = None
    axis: Vec3 | None = None
    reference: Vec3 | None = None
    inner_radius: float = 0.0
    outer_radius: float = 0.0
    radius: float = 0.0
    length: float = 0.0
    angles: tuple[float, float] = (0.0, 0.0)
    polar_angles: tuple[float, float] = (0.0, 0.0)
    closed: bool = False


@dataclass(frozen=True)
class Shell:
    """A solid-like positional shell part (SPEC §2): a generated mesh, a thickness and a material.

    ``quadrature`` = (n, n_ζ): an n × n conical-product triangle rule (exact to degree 2n − 1) and
    n_ζ Gauss points through the thickness."""

    name: str
    mesh: ShellMeshSpec
    thickness: float
    material: str
    quadrature: tuple[int, int] = (4, 3)


@dataclass(frozen=True)
class ShellPoint:
    """A mesh node of ``shell`` chosen by its reference position: the node nearest to ``at`` (m),
    which must lie within ``tolerance`` (m; None: 10⁻⁶ of the shell's size) — on ``edge`` only when
    given (the coincident nodes of a slit). ``name`` is how supports, loads, point masses and
    outputs refer to it as a node: ``shell.point`` for the named points of ``shells.<shell>.points``,
    a generated ``shell@key`` for a coordinate given in place (``node: {shell, at}``). ``where`` is
    the scene key errors name."""

    name: str
    shell: str
    at: Vec3
    edge: str | None = None
    tolerance: float | None = None
    where: str = ""


@dataclass(frozen=True)
class ShellJoint:
    """``hinge_line``: the coincident nodes of the listed shell edges (and of ``member``, a frame
    or truss member laid along them) share their positions only; each shell keeps its own
    director G, so the common line is a hinge (SPEC §5.3 (i)). Two edges of one shell (the
    ``start`` and ``end`` of a full turn) close it onto itself along a hinge.
    ``rigid``: at ``node`` (a corner of ``shell``), the shell's director G is tied to the frame
    ``member``'s section vectors by Lagrange multipliers, G = Σ α_j W_j (W = V1, V2, V1 × V2);
    with the shared position it transmits force and the two bending moments (the shell has no
    drilling stiffness at a node)."""

    type: str
    edges: tuple[EdgeRef, ...] = ()
    member: str | None = None
    node: str | None = None
    shell: str | None = None


@dataclass(frozen=True)
class EdgeLoad:
    """Dead force or conservative moment per unit length along a shell edge (N/m or N·m/m)."""

    name: str
    edge: EdgeRef
    kind: str                        # force | moment
    value: Vec3
    signal: Signal


@dataclass(frozen=True)
class Support:
    node: str                        # "" for an edge support
    type: str                        # clamp | ball | roller | symmetry (edges) | fixed_vector | revolute | driven
    member: str | None = None
    vector: str | None = None        # v1 | v2 (fixed_vector)
    axis: tuple[float, float, float] | None = None        # driven: rotation axis (unit)
    angle: Signal | None = None                           # driven: rotation angle θ(t) (rad)
    direction: tuple[float, float, float] | None = None   # driven: translation direction (unit)
    distance: Signal | None = None                        # driven: translation s(t) (m)
    edge: EdgeRef | None = None      # a shell edge instead of a node: clamp (Y, G) or ball (Y) on every node
    normal: Vec3 | None = None       # roller (node, edge) / symmetry (edge): the plane's unit normal, along x, y or z


@dataclass(frozen=True)
class Joint:
    """A connection of members at a shared node, expressed by sharing DOFs (SPEC §5).

    ``spherical``: positions only (what any shared node already is); ``revolute``: position and
    the section vector along ``axis`` (each member must have one: set its ``up``); ``rigid``:
    position and both vectors (collinear, equally oriented members).
    """

    type: str
    node: str
    members: tuple[str, ...]
    axis: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class Force:
    name: str
    node: str
    force: Vec3
    signal: Signal


@dataclass(frozen=True)
class Moment:
    name: str
    node: str
    member: str
    moment: Vec3
    follower: bool
    signal: Signal


@dataclass(frozen=True)
class PointMass:
    name: str
    node: str
    mass: float


@dataclass(frozen=True)
class Gravity:
    acceleration: Vec3
    signal: Signal


@dataclass(frozen=True)
class DofComponent:
    """One displacement component of a named node: ``component`` x | y | z (global axes)."""

    node: str
    component: str


@dataclass(frozen=True)
class PathStepSpec:
    """Increment control of a path-following static run (:mod:`flexmb_core.integrators.path_following`).

    The first increment is ``initial``; each next one is scaled by √(target_iterations / iterations
    of the last), bounded to [½, 2]× and to [``min``, ``max``]; a failed increment is halved, down
    to ``min``. Arc lengths and displacement increments are in m.
    """

    initial: float
    min: float
    max: float
    target_iterations: int = 5


@dataclass(frozen=True)
class ArcLengthSpec:
    """``solver.arc_length`` (Crisfield): ``kind`` cylindrical (‖Δu‖ = Δl over the free nodal
    positions) or spherical (‖Δu‖² + ψ² Δλ² ‖u₁‖² = Δl², u₁ the first linear displacement per unit
    load factor, so ψ is dimensionless)."""

    step: PathStepSpec
    kind: str = "cylindrical"        # cylindrical | spherical
    psi: float = 1.0


@dataclass(frozen=True)
class DisplacementControlSpec:
    """``solver.displacement``: the load factor follows from prescribing one displacement
    component ``dof`` (m, from the reference position), stepped from 0 to ``to``."""

    dof: DofComponent
    to: float
    step: PathStepSpec


@dataclass(frozen=True)
class SolverSpec:
    """``solver:``. Statics (``analysis: static``) follows the equilibrium path under ``control``:

    - ``load``: the loads follow their signals in pseudo-time ``t`` = 0 … ``until`` by ``dt``
      (load stepping); a step that passes a critical point or jumps to another branch is a
      snap-through, an error unless ``allow_snap_through``;
    - ``arc_length`` / ``displacement``: every load (forces, gravity, edge loads, moments) is its
      constant value times the load factor λ, an unknown traced by Crisfield's arc length
      (``arc_length``) or by prescribing one displacement component (``displacement``), for at
      most ``max_steps`` increments until λ reaches ``until_load_factor`` or the ``monitor``
      displacement reaches ``until_displacement``.

    ``monitor`` names the displacement component reported with limit points, bifurcations and
    snap-throughs (by default the controlled one under displacement control).
    """

    analysis: str = "dynamic"        # dynamic | static
    integrator: str = "generalized_alpha"   # Arnold–Brüls (default) | newmark | chung_hulbert
    dt: float = 1e-3                 # time step (s); in statics the load (pseudo-time) increment
    until: float = 1.0
    beta: float = 0.25
    gamma: float = 0.5
    rho_inf: float = 0.8     # 0.9 let the spin-up drift unstable at Δt = 0.02 (tests/verification)
    tolerance: float = 1e-9
    max_iterations: int = 25
    initial_acceleration: str = "consistent"   # consistent | zero
    initial_state: str = "rest"                # rest (reference geometry) | static (equilibrium at t0)
    on_unconverged: str = "substep"            # substep | stop | accept_flagged
    max_substep_levels: int = 4
    newton: str = "full"                       # full | modified (tangent reuse)
    modified_contraction: float = 0.25         # refresh when |Δq_k| > this · |Δq_k−1|
    tangent_max_age: int = 100                 # steps a held tangent may serve
    control: str = "load"                      # statics: load | arc_length | displacement
    arc_length: ArcLengthSpec | None = None    # control: arc_length
    displacement: DisplacementControlSpec | None = None   # control: displacement
    monitor: DofComponent | None = None        # reported displacement component
    until_load_factor: float | None = None     # path following: stop once λ reaches this
    until_displacement: float | None = None    # path following: stop once the monitor reaches this (m)
    max_steps: int = 200                       # path following: increments at most
    allow_snap_through: bool = False           # load control: a snap-through is reported, not an error


@dataclass(frozen=True)
class Output:
    name: str
    kind: str
    node: str | None = None
    member: str | None = None
    actuator: str | None = None
    nodes: tuple[str, ...] = ()
    shell: str | None = None         # shell_point, shell_shape
    at: Vec3 | None = None           # shell_point: reference position of a mesh node (m)
    edge: EdgeRef | None = None      # shell_point: look for ``at`` on this edge only (coincident slit edges)


@dataclass(frozen=True)
class CommandProgramSpec:
    """A generator that commands several actuators together (see :mod:`flexmb_core.commands`)."""

    program: str                     # stewart_appendix
    actuators: tuple[str, ...]
    start: str = "blended"           # exact | blended (C² start from rest)
    blend_time: float = 1.0          # s
    switch_blend: float = 0.0        # s; blend of the t = 10 s branch switch over [10 − T/2, 10 + T/2]; 0: exact
    blend_continuity: int = 2        # C^k of both blends: 2 quintic, 3 septic, 4 nonic


@dataclass(frozen=True)
class PhysicalLimits:
    """The scene's ``limits:`` (issue 15; :mod:`flexmb_core.faults`): what a twin's state must not do.

    ``max_actuator_force`` (N, |axial force| of any actuator; inf: no bound),
    ``singular_configurations``: ``detect`` (a platform_pose with six legs that passes through a
    singular configuration into another assembly mode is a fault) or ``ignore``;
    ``on_violation``: ``report`` (status, /diagnostics, the recording; stepping goes on) or ``stop``
    (the violating step is rolled back and the twin stops stepping, holding its last good state).
    """

    max_actuator_force: float = math.inf
    singular_configurations: str = "detect"
    on_violation: str = "report"


@dataclass(frozen=True)
class Scene:
    """A whole mechanism: what the compiler turns into a :class:`~flexmb_core.model.Model`."""

    name: str
    description: str
    source: str
    materials: dict[str, Material]
    sections: dict[str, SectionSpec]
    nodes: dict[str, Vec3]
    members: dict[str, Member]
    supports: tuple[Support, ...]
    forces: tuple[Force, ...]
    moments: tuple[Moment, ...]
    point_masses: tuple[PointMass, ...]
    gravity: Gravity | None
    mass_damping: float
    solver: SolverSpec
    outputs: tuple[Output, ...] = field(default_factory=tuple)
    commands: CommandProgramSpec | None = None
    joints: tuple[Joint, ...] = ()
    shells: dict[str, Shell] = field(default_factory=dict)
    shell_joints: tuple[ShellJoint, ...] = ()
    edge_loads: tuple[EdgeLoad, ...] = ()
    shell_points: tuple[ShellPoint, ...] = ()    # mesh nodes named by coordinates (named or in place)
    limits: PhysicalLimits | None = None         # the scene's ``limits:`` (None: defaults)
