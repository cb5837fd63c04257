"""Mutable simulation data: :class:`State` (what evolves) and :class:`Workspace` (buffers)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kernels.frame3d import frame_scratch, frame_structure
from ..kernels.shell import shell_scratch
from .model import Model


@dataclass
class State:
    """Time, unknowns and their rates, and the actuator stretches in force.

    ``q, v, a (ndof,)``: positions/vectors, velocities, accelerations; ``atil (ndof,)`` the
    generalized-α pseudo-acceleration (equals ``a`` for Newmark); ``lam (na,)`` actuator
    stretch L_cmd/L0; ``lam_rate (na,)`` its rate dλ/dt (1/s), which material damping reads
    (commanded extension moves the actuator's reference and is not damped); the dynamic
    integrator keeps it for models with material damping, it stays zero otherwise.
    """

    t: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    atil: np.ndarray
    lam: np.ndarray
    mult: np.ndarray        # (6·corners,) Lagrange multipliers of rigid corners (N·m)
    lam_rate: np.ndarray | None = None   # (na,) 1/s; zeros when not given

    def __post_init__(self) -> None:
        if self.lam_rate is None:
            self.lam_rate = np.zeros(self.lam.shape)

    @classmethod
    def at_rest(cls, model: Model, t: float = 0.0) -> "State":
        n = model.ndof
        return cls(t, model.q0.copy(), np.zeros(n), np.zeros(n), np.zeros(n),
                   np.ones(model.actuators.l0.size), np.zeros(model.n_multipliers))

    def copy(self) -> "State":
        return State(self.t, self.q.copy(), self.v.copy(), self.a.copy(), self.atil.copy(), self.lam.copy(),
                     self.mult.copy(), self.lam_rate.copy())

    def assign(self, other: "State") -> None:
        """Copy ``other`` into this state's arrays (no allocation)."""
        self.t = other.t
        self.q[:] = other.q
        self.v[:] = other.v
        self.a[:] = other.a
        self.atil[:] = other.atil
        self.lam[:] = other.lam
        self.mult[:] = other.mult
        self.lam_rate[:] = other.lam_rate


class Workspace:
    """Every buffer the time loop touches, allocated once per model."""

    def __init__(self, model: Model):
        n = model.ndof
        self.r = np.zeros(n)            # internal force (+ follower loads), full
        self.kdata = np.zeros(model.nnz)
        self.f_ext = np.zeros(n)
        self.frame_scratch = [frame_scratch(g.w.shape[1], g.dax.shape[2]) for g in model.frame_groups]
        # straight-element structure per frame group (which elements take the fast kernel)
        self.frame_structure = [frame_structure(g) for g in model.frame_groups]
        self.truss_scratch = (np.zeros(6), np.zeros(6), np.zeros(6), np.zeros((6, 6)))   # qe, ve, re, ke
        self.shell_scratch = shell_scratch() if model.shell_groups else None
        self.zero_v = np.zeros(n)                   # rates of an undamped evaluation (statics, modes)
        self.zero_lam_rate = np.zeros(model.actuators.l0.size)
        self.dissipation = 0.0                      # material damping power of the last assembly (W)
        self.follower_scale = np.ones(model.moments.follower_vdofs.shape[0])
        self.cons_scale = np.ones(model.moments.cons_vdofs.shape[0])
        self.load_scale = np.ones(model.load_vectors.shape[0])
        self.dudlam = np.zeros(model.actuators.l0.size)
        self.rc = np.zeros(model.n_multipliers)     # constraint violations of rigid corners
        self.corner_ke = np.zeros((18, 18))
        self.hinge_ke = np.zeros((14, 14))
        self.tie_ke = np.zeros((12, 12))
        self.no_mult = np.zeros(model.n_multipliers)
