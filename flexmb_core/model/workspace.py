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
    ``servo_x, servo_v (ns,)``: output length (m) and rate (m/s) of the actuators that declare a
    servo (``model.actuators.servo``, :mod:`flexmb_core.servo`), empty without; they roll back
    with the rest of the state when a step is rejected.
    """

    t: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    atil: np.ndarray
    lam: np.ndarray
    mult: np.ndarray        # (6·corners,) Lagrange multipliers of rigid corners (N·m)
    lam_rate: np.ndarray | None = None   # (na,) 1/s; zeros when not given
    servo_x: np.ndarray | None = None    # (ns,) m; empty when not given
    servo_v: np.ndarray | None = None    # (ns,) m/s

    def __post_init__(self) -> None:
        if self.lam_rate is None:
            self.lam_rate = np.zeros(self.lam.shape)
        if self.servo_x is None:
            self.servo_x = np.zeros(0)
        if self.servo_v is None:
            self.servo_v = np.zeros(self.servo_x.shape)

    @classmethod
    def at_rest(cls, model: Model, t: float = 0.0) -> "State":
        n = model.ndof
        servo = model.actuators.servo
        ns = 0 if servo is None else servo.size
        servo_x = np.zeros(ns) if servo is None else model.actuators.l0[servo.index].copy()
        return cls(t, model.q0.copy(), np.zeros(n), np.zeros(n), np.zeros(n),
                   np.ones(model.actuators.l0.size), np.zeros(model.n_multipliers), None, servo_x, np.zeros(ns))

    def copy(self) -> "State":
        return State(self.t, self.q.copy(), self.v.copy(), self.a.copy(), self.atil.copy(), self.lam.copy(),
                     self.mult.copy(), self.lam_rate.copy(), self.servo_x.copy(), self.servo_v.copy())

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
        self.servo_x[:] = other.servo_x
        self.servo_v[:] = other.servo_v


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
