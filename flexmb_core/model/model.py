"""The compiled, read-only model: arrays grouped by element kind, DOF maps, sparse pattern, names."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..scene.schema import Scene, Signal
from ..servo import ServoParams


@dataclass(frozen=True)
class FrameGroup:
    """Frame (and frame-actuator) elements of one order and one section rule.

    Arrays: ``edofs (ne, 9n)`` int64; ``dax, dsec (ne, nip, 3n, 3)``; ``w (ne, nip)`` (m³);
    ``mat (ne, 7)`` [E, E_t, G, G_t, κ_t, k_s, τ] with τ = η/E the Kelvin–Voigt retardation time
    (s, 0: undamped); ``act (ne,)`` actuator id or −1;
    ``smap (ne, (9n)²)`` CSR position per local entry (−1 where a DOF is prescribed);
    ``member (ne,)`` member id.
    """

    order: int
    nsec: int
    edofs: np.ndarray
    dax: np.ndarray
    dsec: np.ndarray
    w: np.ndarray
    mat: np.ndarray
    act: np.ndarray
    smap: np.ndarray
    member: np.ndarray

    @property
    def n_elements(self) -> int:
        return self.edofs.shape[0]


@dataclass(frozen=True)
class TrussGroup:
    """2-node bars (trusses and bar actuators): ``edofs (ne, 6)``, ``l0, ea (ne,)``, ``act``, ``smap``,
    ``tau (ne,)`` Kelvin–Voigt retardation time η/E (s, 0: undamped)."""

    edofs: np.ndarray
    l0: np.ndarray
    ea: np.ndarray
    act: np.ndarray
    smap: np.ndarray
    member: np.ndarray
    tau: np.ndarray

    @property
    def n_elements(self) -> int:
        return self.edofs.shape[0]


@dataclass(frozen=True)
class ShellGroup:
    """Cubic shell triangles sharing one quadrature (SPEC §2, :mod:`flexmb_core.kernels.shell`).

    ``quadrature`` (n, n_ζ); rule arrays shared by the group: ``phi (npt, 10)``, ``dphi (npt, 10, 2)``,
    ``zeta (npt,)``; per element: ``edofs (ne, 70)`` [Y, G, a] per node, ``a0inv (ne, npt, 3, 3)``,
    ``w (ne, npt)`` (m³), ``mat (ne, 5)`` [λ, μ (Pa), h0/2 (m), the assumed-strain weights γ_m, γ_s
    (:mod:`flexmb_core.kernels.shell`)], ``const (ne, 6 + nip + npt, 9)`` the state-independent
    numbers of each element's kernel (:func:`~flexmb_core.kernels.shell.shell_constants`),
    ``smap (ne, 4900)``.
    """

    quadrature: tuple[int, int]
    edofs: np.ndarray
    phi: np.ndarray
    dphi: np.ndarray
    zeta: np.ndarray
    a0inv: np.ndarray
    w: np.ndarray
    mat: np.ndarray
    const: np.ndarray
    smap: np.ndarray

    @property
    def n_elements(self) -> int:
        return self.edofs.shape[0]


@dataclass(frozen=True)
class ShellInfo:
    """Where a shell lives in the DOF vector: per mesh node its global node id ``nodes (N,)``,
    ``ydofs (N, 3)``, ``gdofs (N, 3)`` (director G), ``adofs (N,)`` (strain rate); ``tri (ne, 10)``
    mesh-node connectivity; ``edges`` name → mesh-node ids along the edge; ``x0, normal0 (N, 3)``
    the reference positions and unit normals."""

    name: str
    nodes: np.ndarray
    ydofs: np.ndarray
    gdofs: np.ndarray
    adofs: np.ndarray
    tri: np.ndarray
    edges: dict
    x0: np.ndarray
    normal0: np.ndarray


@dataclass(frozen=True)
class MomentLoads:
    """Moments through section vectors (see :mod:`flexmb_core.kernels.moments`)."""

    follower_vdofs: np.ndarray      # (nf, 6)
    follower_mbody: np.ndarray      # (nf, 3)
    follower_smap: np.ndarray       # (nf, 36)
    follower_signals: tuple[Signal, ...]
    cons_vdofs: np.ndarray          # (nc, 3)
    cons_axes: np.ndarray           # (nc, 3, 3)
    cons_magnitude: np.ndarray      # (nc,)
    cons_smap: np.ndarray           # (nc, 9)
    cons_signals: tuple[Signal, ...]


@dataclass(frozen=True)
class MemberInfo:
    """Where a member lives in the DOF vector.

    ``nodes (m,)`` global node ids along the member; ``ydofs (m, 3)``; ``vdofs (m, 6)`` the member's
    own [V1, V2] ids at each of its nodes (−1 for bars).
    """

    name: str
    kind: str
    nodes: np.ndarray
    ydofs: np.ndarray
    vdofs: np.ndarray
    length: float


@dataclass(frozen=True)
class Actuators:
    names: tuple[str, ...]
    member: np.ndarray              # (na,) member id
    l0: np.ndarray                  # (na,) reference length (m)
    commands: tuple[Signal | None, ...]
    stroke: np.ndarray              # (na, 2) (m); [0, inf] when undeclared
    end_ydofs: np.ndarray           # (na, 6) ids of the two end positions
    servo: ServoParams | None = None   # the actuators that declare a servo (None: none does)


@dataclass(frozen=True)
class Drives:
    """Prescribed motion: node positions ``Y(t) = Y⁰ + d s(t)`` and section vectors
    ``V(t) = R(a, θ(t)) V⁰`` (Rodrigues), one entry per driven support.

    ``y_ids (nd, 3)``, ``y0 (nd, 3)``, ``direction (nd, 3)``, ``axis (nd, 3)``;
    ``v_ids (nv, 3)``, ``v0 (nv, 3)``, ``v_drive (nv,)`` the drive that turns each vector.
    """

    y_ids: np.ndarray
    y0: np.ndarray
    direction: np.ndarray
    distance: tuple[Signal | None, ...]
    axis: np.ndarray
    angle: tuple[Signal | None, ...]
    v_ids: np.ndarray
    v0: np.ndarray
    v_drive: np.ndarray


@dataclass(frozen=True)
class Model:
    """Everything the time loop reads; nothing in it changes after :func:`compile_scene`."""

    scene: Scene
    ndof: int
    q0: np.ndarray                  # (ndof,) reference configuration
    dof_scale: np.ndarray           # (ndof,) m for positions, 1 for vectors (convergence test)
    free: np.ndarray                # (nfree,) ids of free DOFs
    free_index: np.ndarray          # (ndof,) position among free DOFs or −1
    indptr: np.ndarray              # CSR pattern of the free–free tangent
    indices: np.ndarray
    mass_kdata: np.ndarray          # (nnz,) M on the tangent pattern
    mass_csr: tuple[np.ndarray, np.ndarray, np.ndarray]  # full M (indptr, indices, data)
    frame_groups: tuple[FrameGroup, ...]
    truss: TrussGroup | None
    moments: MomentLoads
    load_vectors: np.ndarray        # (nl, ndof) nodal force patterns (N)
    load_signals: tuple[Signal, ...]
    gravity_vector: np.ndarray      # (ndof,) = M · u_g (N) for the scene's gravity (zeros if none)
    gravity_signal: Signal
    actuators: Actuators
    members: tuple[MemberInfo, ...]
    node_names: tuple[str, ...]
    node_ydofs: np.ndarray          # (nnodes, 3)
    mass_damping: float
    total_mass: float
    drives: Drives | None = None        # prescribed motion, or None
    program: object | None = None       # command program (flexmb_core.commands), or None
    program_index: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    nsys: int = 0                       # size of the linear system: free DOFs, then multipliers
    corner_dofs: np.ndarray = field(default_factory=lambda: np.zeros((0, 12), dtype=np.int64))
    corner_alpha: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    corner_smap: np.ndarray = field(default_factory=lambda: np.zeros((0, 324), dtype=np.int64))
    hinge_dofs: np.ndarray = field(default_factory=lambda: np.zeros((0, 12), dtype=np.int64))
    hinge_alpha: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    hinge_beta: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    hinge_smap: np.ndarray = field(default_factory=lambda: np.zeros((0, 196), dtype=np.int64))
    node_lookup: dict[str, int] = field(default_factory=dict)
    member_lookup: dict[str, int] = field(default_factory=dict)
    shell_groups: tuple[ShellGroup, ...] = ()
    shells: tuple[ShellInfo, ...] = ()
    tie_dofs: np.ndarray = field(default_factory=lambda: np.zeros((0, 9), dtype=np.int64))
    tie_alpha: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    tie_smap: np.ndarray = field(default_factory=lambda: np.zeros((0, 144), dtype=np.int64))

    @property
    def nfree(self) -> int:
        return self.free.size

    @property
    def material_damping(self) -> bool:
        """True when some element has Kelvin–Voigt damping (a material with ``eta`` > 0)."""
        return (any(bool(np.any(g.mat[:, 6] > 0.0)) for g in self.frame_groups)
                or (self.truss is not None and bool(np.any(self.truss.tau > 0.0))))

    @property
    def n_multipliers(self) -> int:
        """Lagrange multipliers (6 per rigid corner, 2 per off-plane hinge, 3 per shell–frame tie),
        numbered after the free DOFs."""
        return self.nsys - self.nfree

    @property
    def nnz(self) -> int:
        return self.indices.size

    def node(self, name: str) -> int:
        """Global node id of a named node (``KeyError`` names the known ones)."""
        try:
            return self.node_lookup[name]
        except KeyError:
            raise KeyError(f"unknown node '{name}'; known: {sorted(self.scene.nodes)}") from None

    def shell(self, name: str) -> ShellInfo:
        for info in self.shells:
            if info.name == name:
                return info
        raise KeyError(f"unknown shell '{name}'; known: {[i.name for i in self.shells]}")

    def member(self, name: str) -> MemberInfo:
        try:
            return self.members[self.member_lookup[name]]
        except KeyError:
            raise KeyError(f"unknown member '{name}'; known: {sorted(self.member_lookup)}") from None

    def summary(self) -> dict:
        """Counts for ``flexmb check``."""
        kinds: dict[str, int] = {}
        for g in self.frame_groups:
            for e in range(g.n_elements):
                k = "actuator(frame)" if g.act[e] >= 0 else "frame"
                kinds[k] = kinds.get(k, 0) + 1
        if self.truss is not None:
            for e in range(self.truss.n_elements):
                k = "actuator(bar)" if self.truss.act[e] >= 0 else "truss"
                kinds[k] = kinds.get(k, 0) + 1
        n_shell = sum(g.n_elements for g in self.shell_groups)
        if n_shell:
            kinds["shell"] = n_shell
        return {"scene": self.scene.name, "dofs": self.ndof, "free_dofs": self.nfree,
                "prescribed_dofs": self.ndof - self.nfree, "nodes": len(self.node_names),
                "members": len(self.members), "elements": kinds, "actuators": list(self.actuators.names),
                "tangent_nonzeros": self.nnz, "mass_kg": self.total_mass,
                "material_damping": self.material_damping,
                "rigid_corners": self.corner_dofs.shape[0], "multiplier_hinges": self.hinge_dofs.shape[0],
                "shells": {i.name: {"elements": int(i.tri.shape[0]), "nodes": int(i.nodes.size)} for i in self.shells},
                "shell_frame_ties": self.tie_dofs.shape[0],
                "frame_groups": [f"order {g.order}, {g.n_elements} el., {g.w.shape[1]} points/el."
                                 for g in self.frame_groups]}
