"""Frozen dataclasses of a scene (SI units throughout: m, kg, s, N, Pa, rad) — and its YAML schema.

The schema is written once, here: the keys a scene mapping may hold are the fields of the
dataclass it is read as, with their types (annotations), defaults (field defaults) and units,
ranges and references (``spec(...)``, :mod:`flexmb_core.scene.typed`). Where the YAML form
differs from what the compiler reads — a section's keys depend on its ``shape``, a signal's on its
``kind``, a support's on its ``type`` — the compiled class declares its form (``yaml_form``): one
small dataclass per case, whose ``build()`` returns the compiled value. Invariants within one
mapping are a dataclass's ``check()``; references across the scene stay in the loader
(:mod:`flexmb_core.scene.loader`). :class:`SceneFile` lists the top-level keys.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

from ..errors import excerpt, name_list
from .typed import Invalid, OneOf, spec

Vec3 = tuple[float, float, float]
# A ``node`` key with ``in_place="point"`` also takes a mesh point by coordinates instead of a name,
# ``node: {shell, at, edge?, tolerance?}`` (a :class:`ShellPoint` named ``shell@key``).


def unit3(v: tuple[float, ...]) -> tuple[float, float, float]:
    """``v`` scaled to unit length (a non-zero 3-vector)."""
    norm = math.sqrt(sum(x * x for x in v))
    return (v[0] / norm, v[1] / norm, v[2] / norm)


# -- signals ------------------------------------------------------------------------------------

@dataclass(frozen=True, kw_only=True)
class ConstantSignal:
    """``{kind: constant, value}``, or a bare number."""

    value: float = 1.0

    def build(self) -> Signal:
        return Signal("constant", value=self.value)


@dataclass(frozen=True, kw_only=True)
class RampSignal:
    """``{kind: ramp, start, end, t0, duration, shape}``: start → end over [t0, t0 + duration]."""

    start: float = 0.0
    end: float = 1.0
    t0: float = spec(0.0, nonneg=True, unit="s")
    duration: float = spec(positive=True, unit="s")
    shape: Literal["linear", "smooth", "cycloidal"] = "linear"

    def build(self) -> Signal:
        return Signal("ramp", start=self.start, end=self.end, t0=self.t0, duration=self.duration, shape=self.shape)


@dataclass(frozen=True, kw_only=True)
class SpinUpSignal:
    """``{kind: spin_up, rate, duration}``: the Simo–Vu-Quoc angle law."""

    rate: float = spec(unit="rad/s")
    duration: float = spec(positive=True, unit="s")

    def build(self) -> Signal:
        return Signal("spin_up", amplitude=self.rate, duration=self.duration)


@dataclass(frozen=True, kw_only=True)
class SineSignal:
    """``{kind: sine, offset, amplitude, frequency, phase}``."""

    offset: float = 0.0
    amplitude: float
    frequency: float = spec(nonneg=True, unit="Hz")
    phase: float = spec(0.0, unit="rad")

    def build(self) -> Signal:
        return Signal("sine", offset=self.offset, amplitude=self.amplitude, frequency=self.frequency,
                      phase=self.phase)


@dataclass(frozen=True, kw_only=True)
class TableSignal:
    """``{kind: table, t: [...], values: [...]}``: piecewise linear, held outside."""

    t: tuple[float, ...] = spec(min_len=2)
    values: tuple[float, ...] = spec(min_len=2)

    def check(self) -> None:
        if len(self.t) != len(self.values):
            raise Invalid(f"'t' has {len(self.t)} entries but 'values' has {len(self.values)}")
        if any(b <= a for a, b in zip(self.t, self.t[1:])):
            raise Invalid(f"'t' must be strictly increasing, got {excerpt(list(self.t))}", "t")

    def build(self) -> Signal:
        return Signal("table", table_t=self.t, table_v=self.values)


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

    yaml_form: ClassVar[OneOf] = OneOf("kind", {"constant": ConstantSignal, "ramp": RampSignal, "sine": SineSignal,
                                                "table": TableSignal, "spin_up": SpinUpSignal},
                                       "a '{}' signal", shorthand=("constant", "value"))


# -- materials and sections ---------------------------------------------------------------------

@dataclass(frozen=True, kw_only=True)
class Material:
    """Elastic constants, density and the Kelvin–Voigt viscosity ``eta`` (Pa·s, 0: undamped).

    Material damping: ``S = C : (E + τ Ė)`` with the retardation time ``τ = eta / E``; it damps
    deformation only (never rigid motion), each linear mode with the ratio ``ζ = ω τ / 2``.
    ``G`` defaults to E / (2 (1 + ν)).
    """

    name: str = spec(yaml=False)
    E: float = spec(positive=True, unit="Pa")
    nu: float = spec(0.0, lo=-0.99, hi=0.4999)
    rho: float = spec(positive=True, unit="kg/m³")
    G: float = spec(positive=True, unit="Pa", default_from=lambda m: m["E"] / (2.0 * (1.0 + m["nu"])))
    eta: float = spec(0.0, nonneg=True, expected="the Kelvin–Voigt viscosity as a finite number ≥ 0 in Pa·s",
                      hint="(η = 2ζE/ω gives the damping ratio ζ at the circular frequency ω; 0: undamped)")

    @property
    def retardation_time(self) -> float:
        """τ = η / E (s)."""
        return self.eta / self.E


@dataclass(frozen=True, kw_only=True)
class _SectionShape:
    """Keys every section shape takes: benchmark overrides of the computed properties."""

    name: str = spec(yaml=False)
    shape: str = spec(yaml=False)
    torsion_constant: float | None = spec(None, positive=True, unit="m⁴")
    shear_factor: float | None = spec(None, positive=True, hi=2.0)

    def build(self) -> SectionSpec:
        return SectionSpec(self.name, self.shape, self.dims(), self.torsion_constant, self.shear_factor)


@dataclass(frozen=True, kw_only=True)
class RectangleShape(_SectionShape):
    """``shape: rectangle``: ``width`` along V1, ``height`` along V2 (m)."""

    width: float = spec(positive=True, unit="m")
    height: float = spec(positive=True, unit="m")

    def dims(self) -> tuple[float, ...]:
        return (self.width, self.height)


@dataclass(frozen=True, kw_only=True)
class CircleShape(_SectionShape):
    """``shape: circle``: a solid circle of ``radius`` (m)."""

    radius: float = spec(positive=True, unit="m")

    def dims(self) -> tuple[float, ...]:
        return (self.radius,)


@dataclass(frozen=True, kw_only=True)
class TubeShape(_SectionShape):
    """``shape: tube``: ``outer_radius`` and one of ``inner_radius`` or wall ``thickness`` (m)."""

    outer_radius: float = spec(positive=True, unit="m")
    inner_radius: float | None = spec(None, nonneg=True, unit="m")
    thickness: float | None = spec(None, positive=True, unit="m")

    def check(self) -> None:
        if (self.inner_radius is None) == (self.thickness is None):
            raise Invalid("a tube needs exactly one of 'inner_radius' or 'thickness'")
        ri = self.dims()[1]
        if not 0.0 <= ri < self.outer_radius:
            raise Invalid(f"inner radius {ri} must lie in [0, outer_radius={self.outer_radius})")

    def dims(self) -> tuple[float, ...]:
        ro = self.outer_radius
        return (ro, self.inner_radius if self.inner_radius is not None else ro - self.thickness)


@dataclass(frozen=True)
class SectionSpec:
    name: str
    shape: str                      # rectangle | circle | tube
    dims: tuple[float, ...]          # rectangle (width, height); circle (radius,); tube (ro, ri)
    torsion_constant: float | None = None
    shear_factor: float | None = None

    yaml_form: ClassVar[OneOf] = OneOf("shape", {"rectangle": RectangleShape, "circle": CircleShape,
                                                 "tube": TubeShape}, "a {}")


# -- members --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ServoSpec:
    """An actuator's position servo (see :mod:`flexmb_core.servo`): the actuator's length x
    follows the commanded length u by x'' = ωn²(u − x) − 2ζωn x' with ωn = 2π ``bandwidth_hz``,
    ζ = ``damping_ratio``, |x'| ≤ ``max_rate`` (m/s) and |x''| ≤ ``max_accel`` (m/s²)."""

    bandwidth_hz: float = spec(positive=True, unit="Hz")
    damping_ratio: float = spec(positive=True)
    max_rate: float = spec(positive=True, unit="m/s")
    max_accel: float = spec(positive=True, unit="m/s²")


@dataclass(frozen=True)
class ActuatorSpec:
    """``members.NAME.actuator`` (kind actuator): a frame or bar ``variant``, the commanded length
    ``command`` L(t) (m; None: hold the reference length), the ``stroke`` [min, max] (m) and an
    optional ``servo`` (None: the length is the commanded length, an ideal actuator)."""

    variant: Literal["frame", "bar"] = "frame"
    command: Signal | None = None
    stroke: tuple[float, float] | None = spec(None, unit="m")
    servo: ServoSpec | None = None

    def check(self) -> None:
        if self.stroke is not None and not 0.0 < self.stroke[0] < self.stroke[1]:
            raise Invalid(f"expected 0 < min < max (m), got {list(self.stroke)}", "stroke")


@dataclass(frozen=True)
class MassOverride:
    """``mass: {per_length, rotary_inertia}``: the member's own inertia data in place of the section's."""

    per_length: float | None = spec(None, positive=True, unit="kg/m")            # ρA
    rotary_inertia: tuple[float, float] | None = spec(None, unit="kg·m")          # (ρI1, ρI2)

    def check(self) -> None:
        if self.rotary_inertia is not None and not min(self.rotary_inertia) > 0.0:   # scales the mass by √ratio
            raise Invalid(f"expected positive rotary inertias [ρI1, ρI2] (kg·m), got {list(self.rotary_inertia)}",
                          "rotary_inertia")


@dataclass(frozen=True)
class Arc:
    """``arc: {center}``: a frame member bent on a circle about ``center`` (m)."""

    center: Vec3 = spec(unit="m")

    def build(self) -> Vec3:
        return self.center


def _is_bar(m: dict) -> bool:
    """A member read so far (field → value) is a 2-node bar: a truss or a bar actuator."""
    act = m.get("actuator")
    return m["kind"] == "truss" or (act is not None and act.variant == "bar")


@dataclass(frozen=True)
class Member:
    """A frame, truss or actuator member from node ``start`` (key ``from``) to ``end`` (``to``):
    ``elements`` of ``order`` (default 4 cubic frame elements, 1 bar), ``up`` the V2 direction
    hint, ``arc_center`` (key ``arc: {center}``) for a curved frame, ``via`` the named nodes it
    passes through (continuous vectors)."""

    name: str = spec(yaml=False)
    kind: Literal["frame", "truss", "actuator"]
    start: str = spec(key="from", ref="node")
    end: str = spec(key="to", ref="node")
    elements: int = spec(lo=1, hi=10000, default_from=lambda m: 1 if _is_bar(m) else 4)
    order: int = spec(lo=1, hi=4, default_from=lambda m: 1 if _is_bar(m) else 3)
    material: str = spec(ref="material")
    section: str = spec(ref="section")
    up: Vec3 | None = spec(nonzero=True)
    arc_center: Vec3 | None = spec(key="arc", form=Arc)
    actuator: ActuatorSpec | None = spec(when=(("kind", ("actuator",)),),
                                         default_from=lambda m: ActuatorSpec() if m["kind"] == "actuator" else None)
    mass: MassOverride | None
    integration: Literal["reduced", "full"] = "reduced"   # reduced (p Gauss points along the axis) | full (p + 2)
    via: tuple[str, ...] = spec((), ref="node")

    def check(self) -> None:
        bar = _is_bar({"kind": self.kind, "actuator": self.actuator})
        if self.start == self.end:
            raise Invalid(f"'from' and 'to' are the same node '{self.start}'")
        if bar and self.order != 1:
            raise Invalid(f"bars are 2-node elements (order 1), got order {self.order}", "order")
        if bar and self.arc_center is not None:
            raise Invalid("arcs are for frame members", "arc")
        if self.kind == "actuator" and self.arc_center is not None:
            raise Invalid("actuators must be straight (no 'arc')", "arc")
        if self.start in self.via or self.end in self.via or len(set(self.via)) != len(self.via):
            raise Invalid(f"'via' must list distinct interior nodes, got {name_list(self.via)}", "via")


# -- shells ---------------------------------------------------------------------------------------

_GRID = dict(lo=1, hi=1000, expected="[n_u, n_v] element divisions")


@dataclass(frozen=True, kw_only=True)
class RectangleMesh:
    """``kind: rectangle``: bilinear patch through 4 ``corners`` (scene nodes), ``divisions``
    [n_u, n_v] cells, each cut in two triangles along ``pattern``."""

    kind: str = spec(yaml=False)
    corners: tuple[str, ...] = spec(ref="node")
    divisions: tuple[int, int] = spec(**_GRID)
    pattern: Literal["alternate", "right", "left"] = "alternate"

    def check(self) -> None:
        _corner_count(self.kind, self.corners, 4)

    def build(self) -> ShellMeshSpec:
        return ShellMeshSpec(self.kind, self.divisions, self.corners, self.pattern)


@dataclass(frozen=True, kw_only=True)
class TriangleMesh:
    """``kind: triangle``: 3 ``corners`` (scene nodes), ``divisions`` n (n² elements)."""

    kind: str = spec(yaml=False)
    corners: tuple[str, ...] = spec(ref="node")
    divisions: int = spec(lo=1, hi=200)

    def check(self) -> None:
        _corner_count(self.kind, self.corners, 3)

    def build(self) -> ShellMeshSpec:
        return ShellMeshSpec(self.kind, (self.divisions,), self.corners, "alternate")


def _corner_count(kind: str, corners: tuple[str, ...], need: int) -> None:
    if len(corners) != need or len(set(corners)) != need:
        raise Invalid(f"a {kind} needs {need} distinct corner nodes, got {name_list(corners)}", "corners")


@dataclass(frozen=True, kw_only=True)
class _ArcMesh:
    """A mesh about ``center`` with the axis ``axis``, ``angles`` [θ0, θ1] (rad) measured from
    ``reference``; ``closed``: a full turn whose seam is joined (``angles`` then default to
    [0, 2π])."""

    kind: str = spec(yaml=False)
    center: Vec3 = spec(unit="m")
    axis: Vec3 = spec(nonzero=True)
    reference: Vec3 = spec(nonzero=True)
    angles: tuple[float, float] | None = spec(None, unit="rad")
    divisions: tuple[int, int] = spec(**_GRID)
    pattern: Literal["alternate", "right", "left"] = "alternate"
    closed: bool = False

    def check(self) -> None:
        a, r = self.axis, self.reference
        cross = (a[1] * r[2] - a[2] * r[1], a[2] * r[0] - a[0] * r[2], a[0] * r[1] - a[1] * r[0])
        if _norm(cross) <= 1e-9 * _norm(a) * _norm(r):
            raise Invalid(f"'reference' {list(r)} is parallel to 'axis' {list(a)}", "reference")
        if self.angles is None:
            if not self.closed:
                raise Invalid("missing required key 'angles' ([θ0, θ1] in rad; or closed: true for a full turn)")
            return
        t0, t1 = self.angles
        if not 0.0 < t1 - t0 <= 2.0 * math.pi + 1e-12:
            raise Invalid(f"expected angles [θ0, θ1] (rad) with 0 < θ1 − θ0 ≤ 2π, got {list(self.angles)}", "angles")
        if self.closed and abs(t1 - t0 - 2.0 * math.pi) > 1e-9:
            raise Invalid(f"a closed mesh turns once: θ1 − θ0 must be 2π, got {excerpt(t1 - t0)} rad "
                          f"(leave out 'angles' or drop 'closed')", "angles")

    def turn(self) -> tuple[float, float]:
        return self.angles if self.angles is not None else (0.0, 2.0 * math.pi)


@dataclass(frozen=True, kw_only=True)
class AnnulusMesh(_ArcMesh):
    """``kind: annulus``: a flat sector between two radii (m) about ``center``, normal ``axis``."""

    inner_radius: float = spec(positive=True, unit="m")
    outer_radius: float = spec(positive=True, unit="m")

    def check(self) -> None:
        super().check()
        if not self.inner_radius < self.outer_radius:
            raise Invalid(f"inner_radius {self.inner_radius} must be below outer_radius {self.outer_radius}")

    def build(self) -> ShellMeshSpec:
        return ShellMeshSpec(self.kind, self.divisions, (), self.pattern, self.center, self.axis, self.reference,
                             self.inner_radius, self.outer_radius, angles=self.turn(), closed=self.closed)


@dataclass(frozen=True, kw_only=True)
class CylinderMesh(_ArcMesh):
    """``kind: cylinder``: a patch of ``radius`` and ``length`` (m) along ``axis`` from ``center``."""

    radius: float = spec(positive=True, unit="m")
    length: float = spec(positive=True, unit="m")

    def build(self) -> ShellMeshSpec:
        return ShellMeshSpec(self.kind, self.divisions, (), self.pattern, self.center, self.axis, self.reference,
                             radius=self.radius, length=self.length, angles=self.turn(), closed=self.closed)


@dataclass(frozen=True, kw_only=True)
class SphericalCapMesh(_ArcMesh):
    """``kind: spherical_cap``: a sphere of ``radius`` (m) between ``polar_angles`` [α0, α1] (rad)
    from the pole ``axis`` (α0 > 0: a polar hole; α0 = 0: closed at the pole)."""

    radius: float = spec(positive=True, unit="m")
    polar_angles: tuple[float, float] = spec(unit="rad")

    def check(self) -> None:
        super().check()
        a0, a1 = self.polar_angles
        if not 0.0 <= a0 < a1 < math.pi:
            raise Invalid(f"expected polar angles [α0, α1] (rad, from the pole 'axis') with 0 ≤ α0 < α1 < π "
                          f"(α0 = 0: closed at the pole, α0 > 0: a polar hole), got {excerpt(list(self.polar_angles))}",
                          "polar_angles")

    def build(self) -> ShellMeshSpec:
        return ShellMeshSpec(self.kind, self.divisions, (), self.pattern, self.center, self.axis, self.reference,
                             radius=self.radius, angles=self.turn(), polar_angles=self.polar_angles, closed=self.closed)


def _norm(a) -> float:
    return math.sqrt(sum(x * x for x in a))


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

    yaml_form: ClassVar[OneOf] = OneOf("kind", {"rectangle": RectangleMesh, "triangle": TriangleMesh,
                                                "annulus": AnnulusMesh, "cylinder": CylinderMesh,
                                                "spherical_cap": SphericalCapMesh}, "a '{}' mesh")


@dataclass(frozen=True)
class Quadrature:
    """``quadrature: {in_plane, thickness}``: an n × n conical-product triangle rule (exact to
    degree 2n − 1) and n_ζ Gauss points through the thickness."""

    in_plane: int = spec(4, lo=3, hi=8)
    thickness: int = spec(3, lo=2, hi=6)

    def build(self) -> tuple[int, int]:
        return (self.in_plane, self.thickness)


@dataclass(frozen=True)
class Shell:
    """A solid-like positional shell part (SPEC §2): a generated mesh, a thickness and a material.

    ``quadrature`` = (n, n_ζ) (:class:`Quadrature`). ``points``: the names (``shell.point``) of
    the mesh points named under ``shells.<shell>.points`` (:class:`ShellPoint`)."""

    name: str = spec(yaml=False)
    mesh: ShellMeshSpec
    thickness: float = spec(positive=True, unit="m")
    material: str = spec(ref="material")
    quadrature: tuple[int, int] = spec(Quadrature().build(), form=Quadrature)
    points: tuple[str, ...] = spec((), deferred=True)

    def check(self) -> None:
        if self.mesh.kind in ("cylinder", "spherical_cap") and self.thickness / 2 >= self.mesh.radius:
            raise Invalid(f"half thickness {self.thickness / 2} m is not below the radius {self.mesh.radius} m",
                          "thickness")


@dataclass(frozen=True)
class ShellPoint:
    """A mesh node of ``shell`` chosen by its reference position: the node nearest to ``at`` (m),
    which must lie within ``tolerance`` (m; None: 10⁻⁶ of the shell's size) — on ``edge`` only when
    given (the coincident nodes of a slit). ``name`` is how supports, loads, point masses and
    outputs refer to it as a node: ``shell.point`` for the named points of ``shells.<shell>.points``,
    a generated ``shell@key`` for a coordinate given in place (``node: {shell, at}``). ``where`` is
    the scene key errors name. A bare list is ``at``."""

    name: str = spec(yaml=False)
    shell: str = spec(ref="shell")
    at: Vec3 = spec(unit="m")
    edge: str | None = None
    tolerance: float | None = spec(None, positive=True, unit="m")
    where: str = spec("", yaml=False)

    yaml_shorthand: ClassVar[str] = "at"


@dataclass(frozen=True, kw_only=True)
class HingeLine:
    """``{type: hinge_line, edges, member?}``."""

    edges: tuple[EdgeRef, ...] = spec(ref="edge")
    member: str | None = spec(None, ref="member")

    def check(self) -> None:
        if len(self.edges) + (self.member is not None) < 2:
            raise Invalid("a hinge line joins at least two shell edges, or one shell edge and a member", "edges")
        if len(set(self.edges)) != len(self.edges):
            raise Invalid(f"each edge may appear once in a hinge line, got {[f'{a}.{b}' for a, b in self.edges]}",
                          "edges")

    def build(self) -> ShellJoint:
        return ShellJoint("hinge_line", self.edges, self.member)


@dataclass(frozen=True, kw_only=True)
class ShellRigidJoint:
    """``{type: shell_rigid, node, shell, member}``."""

    node: str = spec(ref="node")
    shell: str = spec(ref="shell")
    member: str = spec(ref="member")

    def build(self) -> ShellJoint:
        return ShellJoint("shell_rigid", member=self.member, node=self.node, shell=self.shell)


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


@dataclass(frozen=True, kw_only=True)
class EdgeForce:
    """``loads.edge_forces.NAME``: a dead force per unit length along a shell edge (N/m)."""

    name: str = spec(yaml=False)
    edge: EdgeRef = spec(ref="edge")
    force_per_length: Vec3 = spec(unit="N/m")
    signal: Signal = spec(default_factory=Signal)

    def build(self) -> EdgeLoad:
        return EdgeLoad(self.name, self.edge, "force", self.force_per_length, self.signal)


@dataclass(frozen=True, kw_only=True)
class EdgeMoment:
    """``loads.edge_moments.NAME``: a conservative moment per unit length along a shell edge (N·m/m)."""

    name: str = spec(yaml=False)
    edge: EdgeRef = spec(ref="edge")
    moment_per_length: Vec3 = spec(unit="N·m/m")
    signal: Signal = spec(default_factory=Signal)

    def build(self) -> EdgeLoad:
        return EdgeLoad(self.name, self.edge, "moment", self.moment_per_length, self.signal)


@dataclass(frozen=True)
class EdgeLoad:
    """Dead force or conservative moment per unit length along a shell edge (N/m or N·m/m)."""

    name: str
    edge: EdgeRef
    kind: str                        # force | moment
    value: Vec3
    signal: Signal


# -- supports -------------------------------------------------------------------------------------

_NORMAL = dict(nonzero=True, doc="the plane's normal along x, y or z, e.g. [1, 0, 0]")


def _axis_normal(typ: str, v: Vec3) -> None:
    """A roller's or symmetry support's ``normal`` must lie along x, y or z: it fixes one DOF
    component per node (a general plane would need a constraint equation)."""
    if max(abs(x) for x in v) < _norm(v) * (1.0 - 1e-12):
        raise Invalid(f"a {typ} normal must lie along x, y or z (it fixes one DOF component per node; "
                      f"a skew plane would need a constraint equation), got {excerpt(list(v))}", "normal")


@dataclass(frozen=True, kw_only=True)
class NodeSupport:
    """``{node, type: clamp | ball, member?}``: Y (and a clamp's vectors; of ``member`` only, when given) fixed."""

    type: str = spec(yaml=False)
    node: str = spec(ref="node", in_place="point")
    member: str | None = spec(None, ref="member")

    def build(self) -> Support:
        return Support(self.node, self.type, self.member)


@dataclass(frozen=True, kw_only=True)
class RollerSupport:
    """``{node, type: roller, normal}``: the position along the axis ``normal`` only."""

    type: str = spec(yaml=False)
    node: str = spec(ref="node", in_place="point")
    normal: Vec3 = spec(**_NORMAL)

    def check(self) -> None:
        _axis_normal(self.type, self.normal)

    def build(self) -> Support:
        return Support(self.node, self.type, normal=unit3(self.normal))


@dataclass(frozen=True, kw_only=True)
class FixedVectorSupport(NodeSupport):
    """``{node, type: fixed_vector, member, vector: v1 | v2}``: one section vector of ``member`` fixed."""

    member: str = spec(ref="member", doc="whose section vector is fixed")
    vector: Literal["v1", "v2"]

    def build(self) -> Support:
        return Support(self.node, self.type, self.member, self.vector)


@dataclass(frozen=True, kw_only=True)
class RevoluteSupport(NodeSupport):
    """``{node, type: revolute, member, axis}``: Y and ``member``'s section vector on ``axis`` fixed."""

    member: str = spec(ref="member", doc="whose section vector lies on the axis")
    axis: Vec3 = spec(nonzero=True)

    def build(self) -> Support:
        return Support(self.node, self.type, self.member, axis=unit3(self.axis))


@dataclass(frozen=True)
class DriveRotation:
    """``rotation: {axis, angle}``: turn about ``axis`` by the signal θ(t) (rad)."""

    axis: Vec3 = spec(nonzero=True)
    angle: Signal


@dataclass(frozen=True)
class DriveTranslation:
    """``translation: {direction, distance}``: move along ``direction`` by the signal s(t) (m)."""

    direction: Vec3 = spec(nonzero=True)
    distance: Signal


@dataclass(frozen=True, kw_only=True)
class DrivenSupport(NodeSupport):
    """``{node, type: driven, member?, rotation?, translation?}``: prescribed Y(t) and V(t) = R(t) V⁰."""

    rotation: DriveRotation | None = None
    translation: DriveTranslation | None = None

    def check(self) -> None:
        if self.rotation is None and self.translation is None:
            raise Invalid("a driven support needs 'rotation' and/or 'translation'")

    def build(self) -> Support:
        r, t = self.rotation, self.translation
        return Support(self.node, self.type, self.member, None, r and unit3(r.axis), r and r.angle,
                       t and unit3(t.direction), t and t.distance)


@dataclass(frozen=True, kw_only=True)
class EdgeSupport:
    """``{edge, type: clamp | ball}`` on every node of a shell edge: clamp fixes Y and G, ball Y."""

    type: str = spec(yaml=False)
    edge: EdgeRef = spec(ref="edge")

    def build(self) -> Support:
        return Support("", self.type, edge=self.edge)


@dataclass(frozen=True, kw_only=True)
class EdgePlaneSupport(EdgeSupport):
    """``{edge, type: roller | symmetry, normal}``: n·Y (roller), n·Y and n·G (symmetry) fixed."""

    normal: Vec3 = spec(**_NORMAL)

    def check(self) -> None:
        _axis_normal(self.type, self.normal)

    def build(self) -> Support:
        return Support("", self.type, edge=self.edge, normal=unit3(self.normal))


EDGE_SUPPORTS = OneOf("type", {"clamp": EdgeSupport, "ball": EdgeSupport, "roller": EdgePlaneSupport,
                               "symmetry": EdgePlaneSupport}, "an edge support of type '{}'")


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

    yaml_form: ClassVar[OneOf] = OneOf("type", {"clamp": NodeSupport, "ball": NodeSupport, "roller": RollerSupport,
                                                "fixed_vector": FixedVectorSupport, "revolute": RevoluteSupport,
                                                "driven": DrivenSupport}, "a '{}' support",
                                       split=("edge", EDGE_SUPPORTS))


# -- joints ---------------------------------------------------------------------------------------

@dataclass(frozen=True, kw_only=True)
class MemberJoint:
    """``{type: spherical | rigid, node, members}``."""

    type: str = spec(yaml=False)
    node: str = spec(ref="node")
    members: tuple[str, ...] = spec(ref="member")

    def check(self) -> None:
        if len(self.members) < 2 or len(set(self.members)) != len(self.members):
            raise Invalid(f"a joint connects at least two distinct members, got {name_list(self.members)}", "members")

    def build(self) -> Joint:
        return Joint(self.type, self.node, self.members)


@dataclass(frozen=True, kw_only=True)
class RevoluteJoint(MemberJoint):
    """``{type: revolute, node, members, axis}``."""

    axis: Vec3 = spec(nonzero=True)

    def build(self) -> Joint:
        return Joint(self.type, self.node, self.members, unit3(self.axis))


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


JOINTS = OneOf("type", {"spherical": MemberJoint, "revolute": RevoluteJoint, "rigid": MemberJoint,
                        "hinge_line": HingeLine, "shell_rigid": ShellRigidJoint}, "a '{}' joint")


# -- loads ----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Force:
    name: str = spec(yaml=False)
    node: str = spec(ref="node", in_place="point")
    force: Vec3 = spec(unit="N")
    signal: Signal = spec(default_factory=Signal)


@dataclass(frozen=True)
class Moment:
    """An end moment of ``member`` at ``node``: conservative about a fixed axis, or ``follower``
    (body-fixed components)."""

    name: str = spec(yaml=False)
    node: str = spec(ref="node")
    member: str = spec(ref="member")
    moment: Vec3 = spec(unit="N·m")
    follower: bool = False
    signal: Signal = spec(default_factory=Signal)


@dataclass(frozen=True)
class PointMass:
    name: str = spec(yaml=False)
    node: str = spec(ref="node", in_place="point")
    mass: float = spec(positive=True, unit="kg")


@dataclass(frozen=True)
class Gravity:
    """``gravity``: an ``acceleration`` (m/s²) times a signal; a bare list is the acceleration."""

    acceleration: Vec3 = spec(unit="m/s²")
    signal: Signal = spec(default_factory=Signal)

    yaml_shorthand: ClassVar[str] = "acceleration"


@dataclass(frozen=True, kw_only=True)
class Loads:
    """The ``loads:`` block (its parts go to :class:`Scene`'s ``gravity``, ``forces``,
    ``moments`` and ``edge_loads``)."""

    gravity: Gravity | None = None
    forces: dict[str, Force] = spec(default_factory=dict)
    moments: dict[str, Moment] = spec(default_factory=dict)
    edge_forces: dict[str, EdgeLoad] = spec(default_factory=dict, form=EdgeForce)
    edge_moments: dict[str, EdgeLoad] = spec(default_factory=dict, form=EdgeMoment)


@dataclass(frozen=True)
class Damping:
    """``damping: {mass_proportional}``: C = c_m M (1/s). Material (Kelvin–Voigt) damping is a
    material's ``eta``."""

    mass_proportional: float = spec(0.0, nonneg=True, unit="1/s")


# -- solver ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class DofComponent:
    """One displacement component of a named node: ``component`` x | y | z (global axes)."""

    node: str = spec(ref="node")
    component: Literal["x", "y", "z"]


@dataclass(frozen=True)
class PathStepSpec:
    """Increment control of a path-following static run (:mod:`flexmb_core.integrators.path_following`).

    The first increment is ``initial``; each next one is scaled by √(target_iterations / iterations
    of the last), bounded to [½, 2]× and to [``min``, ``max``] (by default 10⁻³ and 10× ``initial``);
    a failed increment is halved, down to ``min``. Arc lengths and displacement increments are in m.
    """

    initial: float = spec(positive=True, unit="m")
    min: float = spec(positive=True, unit="m", default_from=lambda s: s["initial"] * 1e-3)
    max: float = spec(positive=True, unit="m", default_from=lambda s: s["initial"] * 10.0)
    target_iterations: int = spec(5, lo=1, hi=100)

    def check_order(self, what: str) -> None:
        """min ≤ initial ≤ max, else :class:`Invalid` naming ``what`` the increments are."""
        if not self.min <= self.initial <= self.max:
            raise Invalid(f"expected min ≤ initial ≤ max for the {what}, got min {excerpt(self.min)}, initial "
                          f"{excerpt(self.initial)}, max {excerpt(self.max)} (m)")


@dataclass(frozen=True)
class ArcLengthSpec:
    """``solver.arc_length`` (Crisfield): ``kind`` cylindrical (‖Δu‖ = Δl over the free nodal
    positions) or spherical (‖Δu‖² + ψ² Δλ² ‖u₁‖² = Δl², u₁ the first linear displacement per unit
    load factor, so ψ is dimensionless). The keys of :class:`PathStepSpec` sit in this mapping."""

    step: PathStepSpec = spec(inline=True)
    kind: Literal["cylindrical", "spherical"] = "cylindrical"
    psi: float = spec(1.0, positive=True, when=(("kind", ("spherical",)),))   # the load term's weight

    def check(self) -> None:
        self.step.check_order("arc length")


@dataclass(frozen=True)
class DisplacementControlSpec:
    """``solver.displacement``: the load factor follows from prescribing one displacement
    component ``dof`` (m, from the reference position), stepped from 0 to ``to``. The keys of
    :class:`DofComponent` and :class:`PathStepSpec` sit in this mapping."""

    dof: DofComponent = spec(inline=True)
    to: float = spec(unit="m")
    step: PathStepSpec = spec(inline=True)

    def check(self) -> None:
        if self.to == 0.0:
            raise Invalid("expected a non-zero target displacement (m), got 0", "to")
        self.step.check_order("displacement increment")


_STATIC = (("analysis", ("static",)),)
_PATH = _STATIC + (("control", ("arc_length", "displacement")),)


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
    snap-throughs (by default the controlled one under displacement control). A statics key in a
    dynamic run, or a path-following key under load control, is an error (``when``), not ignored.
    """

    analysis: Literal["dynamic", "static"] = "dynamic"
    integrator: Literal["newmark", "generalized_alpha", "chung_hulbert"] = "generalized_alpha"   # Arnold–Brüls
    dt: float = spec(1e-3, positive=True, lo=1e-9, unit="s")   # time step (s, ≥ 1 ns); in statics the load (pseudo-time) increment
    until: float = spec(1.0, positive=True, unit="s")
    beta: float = spec(0.25, positive=True, hi=0.5)
    gamma: float = spec(0.5, lo=0.5, hi=1.0)
    rho_inf: float = spec(0.8, lo=0.0, hi=1.0)     # 0.9 let the spin-up drift unstable at Δt = 0.02 (tests/verification)
    tolerance: float = spec(1e-9, positive=True, hi=1e-2)
    max_iterations: int = spec(25, lo=1, hi=1000)
    initial_acceleration: Literal["consistent", "zero"] = "consistent"
    initial_state: Literal["rest", "static"] = "rest"     # rest (reference geometry) | static (equilibrium at t0)
    on_unconverged: Literal["substep", "stop", "accept_flagged"] = "substep"
    max_substep_levels: int = spec(4, lo=0, hi=12)
    newton: Literal["full", "modified"] = "full"           # modified: tangent reuse
    modified_contraction: float = spec(0.25, positive=True, hi=0.9)   # refresh when |Δq_k| > this · |Δq_k−1|
    tangent_max_age: int = spec(100, lo=1, hi=10**9)                  # steps a held tangent may serve
    # dynamics, modified Newton: the held tangent follows each shell's rotation since it was
    # formed (kernels/corotation.py) | is used as formed
    held_tangent: Literal["corotated", "fixed"] = "corotated"
    control: Literal["load", "arc_length", "displacement"] = spec("load", when=_STATIC)
    arc_length: ArcLengthSpec | None = spec(None, when=_STATIC + (("control", ("arc_length",)),))
    displacement: DisplacementControlSpec | None = spec(None, when=_STATIC + (("control", ("displacement",)),))
    monitor: DofComponent | None = spec(None, when=_STATIC,         # default: the controlled component
                                        default_from=lambda s: s["displacement"].dof if s.get("displacement") else None)
    until_load_factor: float | None = spec(None, when=_PATH)       # path following: stop once λ reaches this
    until_displacement: float | None = spec(None, unit="m", when=_PATH)   # … once the monitor reaches this (m)
    max_steps: int = spec(200, lo=1, hi=10**6, when=_PATH)         # path following: increments at most
    allow_snap_through: bool = spec(False, when=_STATIC)           # load control: reported, not an error

    def check(self) -> None:
        if self.analysis != "static":
            return
        if self.control == "arc_length" and self.arc_length is None:
            raise Invalid("control: arc_length needs an 'arc_length' block, e.g. {initial: 0.05} (m)")
        if self.control == "displacement" and self.displacement is None:
            raise Invalid("control: displacement needs a 'displacement' block {node, component, to}")
        if self.until_displacement == 0.0:
            raise Invalid("expected a non-zero displacement (m) to stop at, got 0", "until_displacement")
        if self.until_displacement is not None and self.monitor is None:
            raise Invalid("'until_displacement' needs a 'monitor' {node, component} (the displacement it bounds)",
                          "until_displacement")
        if self.control == "arc_length" and self.until_load_factor is None and self.until_displacement is None:
            raise Invalid("control: arc_length needs a goal: 'until_load_factor' and/or 'until_displacement'")
        if self.control == "arc_length" and self.monitor is None:
            raise Invalid("control: arc_length needs a 'monitor' {node, component}: the displacement "
                          "reported with the load factor")


# -- outputs --------------------------------------------------------------------------------------

@dataclass(frozen=True, kw_only=True)
class _Output:
    name: str = spec(yaml=False)
    kind: str = spec(yaml=False)


@dataclass(frozen=True, kw_only=True)
class NodeOutput(_Output):
    """``node_position``, ``node_displacement``: a node (or mesh point)."""

    node: str = spec(ref="node", in_place="point")

    def build(self) -> Output:
        return Output(self.name, self.kind, self.node)


@dataclass(frozen=True, kw_only=True)
class SectionVectorsOutput(_Output):
    """``section_vectors``: V1, V2 of ``member`` at its end ``node``."""

    node: str = spec(ref="node", in_place="point")
    member: str = spec(ref="member")

    def build(self) -> Output:
        return Output(self.name, self.kind, self.node, self.member)


@dataclass(frozen=True, kw_only=True)
class ActuatorOutput(_Output):
    """``actuator_length``, ``actuator_command``, ``actuator_force``, ``actuator_velocity``."""

    actuator: str = spec(ref="member")

    def build(self) -> Output:
        return Output(self.name, self.kind, actuator=self.actuator)


@dataclass(frozen=True, kw_only=True)
class EnergyOutput(_Output):
    """``energy``: kinetic, strain, gravity and total (J)."""

    def build(self) -> Output:
        return Output(self.name, self.kind)


@dataclass(frozen=True, kw_only=True)
class MemberShapeOutput(_Output):
    """``member_shape``: the positions of ``member``'s nodes."""

    member: str = spec(ref="member")

    def build(self) -> Output:
        return Output(self.name, self.kind, member=self.member)


@dataclass(frozen=True, kw_only=True)
class PlatformPoseOutput(_Output):
    """``platform_pose``: centroid and orientation of the triangle of 3 ``nodes``."""

    nodes: tuple[str, ...] = spec(ref="node")

    def check(self) -> None:
        if len(self.nodes) != 3:
            raise Invalid(f"a platform pose is defined by 3 nodes, got {len(self.nodes)}", "nodes")

    def build(self) -> Output:
        return Output(self.name, self.kind, nodes=self.nodes)


@dataclass(frozen=True, kw_only=True)
class JointAngleOutput(_Output):
    """``joint_angle``: rotation about a revolute axis at ``node`` of 1 member (to its reference)
    or of the second of 2 ``members`` relative to the first (rad)."""

    node: str = spec(ref="node", in_place="point")
    members: tuple[str, ...] = spec(ref="member")

    def check(self) -> None:
        if not 1 <= len(self.members) <= 2:
            raise Invalid(f"a joint angle relates 1 member (to its reference) or 2 members, got "
                          f"{name_list(self.members)}", "members")

    def build(self) -> Output:
        return Output(self.name, self.kind, self.node, nodes=self.members)


@dataclass(frozen=True, kw_only=True)
class ShellPointOutput(_Output):
    """``shell_point``: the mesh node of ``shell`` at ``at`` (m), on ``edge`` when given."""

    shell: str = spec(ref="shell")
    at: Vec3 = spec(unit="m")
    edge: EdgeRef | None = spec(None, ref="edge")

    def check(self) -> None:
        if self.edge is not None and self.edge[0] != self.shell:
            raise Invalid(f"edge '{self.edge[0]}.{self.edge[1]}' is not an edge of shell '{self.shell}'", "edge")

    def build(self) -> Output:
        return Output(self.name, self.kind, shell=self.shell, at=self.at, edge=self.edge)


@dataclass(frozen=True, kw_only=True)
class ShellShapeOutput(_Output):
    """``shell_shape``: every mesh node's position."""

    shell: str = spec(ref="shell")

    def build(self) -> Output:
        return Output(self.name, self.kind, shell=self.shell)


@dataclass(frozen=True)
class Output:
    name: str
    kind: str
    node: str | None = None
    member: str | None = None
    actuator: str | None = None
    nodes: tuple[str, ...] = ()      # platform_pose: 3 nodes; joint_angle: its members
    shell: str | None = None         # shell_point, shell_shape
    at: Vec3 | None = None           # shell_point: reference position of a mesh node (m)
    edge: EdgeRef | None = None      # shell_point: look for ``at`` on this edge only (coincident slit edges)

    yaml_form: ClassVar[OneOf] = OneOf("kind", {
        "node_position": NodeOutput, "node_displacement": NodeOutput, "section_vectors": SectionVectorsOutput,
        "actuator_length": ActuatorOutput, "actuator_command": ActuatorOutput, "actuator_force": ActuatorOutput,
        "energy": EnergyOutput, "member_shape": MemberShapeOutput, "platform_pose": PlatformPoseOutput,
        "actuator_velocity": ActuatorOutput, "joint_angle": JointAngleOutput, "shell_point": ShellPointOutput,
        "shell_shape": ShellShapeOutput}, "output kind '{}'")


# -- commands, limits -----------------------------------------------------------------------------

@dataclass(frozen=True)
class CommandProgramSpec:
    """A generator that commands several actuators together (see :mod:`flexmb_core.commands`).

    ``switch_blend`` (s): the t = 10 s branch switch is blended over [10 − T/2, 10 + T/2]
    (0: exact); ``blend_continuity``: C^k of both blends (2 quintic, 3 septic, 4 nonic)."""

    program: Literal["stewart_appendix"]
    actuators: tuple[str, ...] = spec(ref="member")
    start: Literal["exact", "blended"] = "blended"     # blended: a C² start from rest
    blend_time: float = spec(1.0, positive=True, unit="s")
    switch_blend: float = spec(0.0, nonneg=True, unit="s")
    blend_continuity: int = spec(2, lo=2, hi=4)

    def check(self) -> None:
        if len(set(self.actuators)) != len(self.actuators):
            raise Invalid(f"actuators listed twice: {name_list(self.actuators)}", "actuators")
        if self.switch_blend > 10.0:
            raise Invalid(f"the branch switch at t = 10 s is blended over [10 − T/2, 10 + T/2]; T must lie in "
                          f"[0, 10] s (0: the exact law), got {excerpt(self.switch_blend)}", "switch_blend")


@dataclass(frozen=True)
class PhysicalLimits:
    """The scene's ``limits:`` (issue 15; :mod:`flexmb_core.faults`): what a twin's state must not do.

    ``max_actuator_force`` (N, |axial force| of any actuator; inf: no bound),
    ``singular_configurations``: ``detect`` (a platform_pose with six legs that passes through a
    singular configuration into another assembly mode is a fault) or ``ignore``;
    ``on_violation``: ``report`` (status, /diagnostics, the recording; stepping goes on) or ``stop``
    (the violating step is rolled back and the twin stops stepping, holding its last good state).
    """

    max_actuator_force: float = spec(math.inf, positive=True, unit="N")
    singular_configurations: Literal["detect", "ignore"] = "detect"
    on_violation: Literal["report", "stop"] = "report"


# -- the file -------------------------------------------------------------------------------------

@dataclass(frozen=True, kw_only=True)
class IncludeItem:
    """An ``include:`` entry given as a mapping (:mod:`flexmb_core.scene.include`): a scene ``file``
    and the dotted-key ``overrides`` applied to it before it is merged."""

    file: str
    overrides: dict[str, Any] = spec(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class SceneFile:
    """The top-level keys of a scene file (``include:`` is resolved first,
    :mod:`flexmb_core.scene.include`). The loader reads them in the order their references need
    and assembles the :class:`Scene`."""

    name: str
    description: str = spec("", empty=True)
    materials: dict[str, Material]
    sections: dict[str, SectionSpec] = spec(default_factory=dict)
    nodes: dict[str, Vec3] = spec(default_factory=dict, unit="m")
    members: dict[str, Member] = spec(default_factory=dict)
    shells: dict[str, Shell] = spec(default_factory=dict)
    supports: tuple[Support, ...] = ()
    loads: Loads = spec(default_factory=Loads)
    point_masses: dict[str, PointMass] = spec(default_factory=dict)
    damping: Damping = spec(default_factory=Damping)
    solver: SolverSpec = spec(default_factory=SolverSpec)
    outputs: dict[str, Output] = spec(default_factory=dict)
    commands: CommandProgramSpec | None = None
    joints: tuple[Joint | ShellJoint, ...] = spec((), form=JOINTS)
    limits: PhysicalLimits | None = None


@dataclass(frozen=True)
class Scene:
    """A whole mechanism: what the compiler turns into a :class:`~flexmb_core.model.Model`
    (read from a :class:`SceneFile` by :func:`flexmb_core.scene.loader.scene_from_dict`)."""

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
