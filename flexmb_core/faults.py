"""Physical faults of a twin's state (issue 15): actuator forces beyond the scene's bound, and a
platform that passes through a singular configuration of its legs — the way a Stewart platform
slips into another assembly mode (e.g. mirrored below its base) while every step converges.

The scene's ``limits:`` section (:class:`~flexmb_core.scene.schema.PhysicalLimits`) sets the bound
and what the twin does on a violation; :class:`FaultMonitor` checks a state after each step.

Singular configurations: for every ``platform_pose`` output whose three nodes are the moving ends
of exactly six actuators (a Stewart–Gough platform), the leg Jacobian ``J`` (6 × 6; row i
``[uᵢᵀ, ((pᵢ − c) × uᵢ)ᵀ]`` with uᵢ the unit leg vector, pᵢ its platform end and c the platform
centroid) maps the platform's twist to the leg rates. ``det J`` vanishes at a singular
configuration and changes sign when the platform passes through one into another assembly mode;
the monitor compares its sign with the reference configuration's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .jit import KERNEL
from .model.model import Model


@dataclass(frozen=True)
class Fault:
    """One violation found in a state: ``kind`` (``actuator_force`` | ``assembly_mode``) and a
    readable ``detail``."""

    kind: str
    detail: str


class _Platform:
    """The six legs of one platform and the sign of its leg Jacobian at the reference state."""

    def __init__(self, model: Model, name: str, node_ids: np.ndarray, legs: np.ndarray, far: np.ndarray,
                 near: np.ndarray):
        self.name, self.node_ids, self.legs, self.far, self.near = name, node_ids, legs, far, near
        self._work = np.zeros((8, 6))       # the Jacobian (rows 0–5), the centroid, a leg's p and u
        self.sign0 = math.copysign(1.0, self.det(model.q0))

    def det(self, q: np.ndarray) -> float:
        """``det J`` at positions ``q`` (m³ · dimensionless: only its sign is used)."""
        return _leg_jacobian_det(q, self.node_ids, self.near, self.far, self._work)


@njit(nogil=True, **KERNEL)
def _leg_jacobian_det(q, node_ids, near, far, work):
    """det of the 6 × 6 leg Jacobian (module docstring) by Gaussian elimination with partial
    pivoting (a few µs; numpy's det and stacking cost ~0.2 ms a step), in ``work (8, 6)``: the
    Jacobian in rows 0–5, the centroid in row 6, a leg's point and unit vector in row 7."""
    a = work[:6]
    c = work[6, :3]
    p = work[7, :3]
    u = work[7, 3:]
    c[:] = 0.0
    for k in range(node_ids.shape[0]):
        for j in range(3):
            c[j] += q[node_ids[k, j]] / node_ids.shape[0]
    for i in range(6):
        for j in range(3):
            p[j] = q[near[i, j]]
            u[j] = p[j] - q[far[i, j]]
        n = np.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
        for j in range(3):
            u[j] /= n
            p[j] -= c[j]
        a[i, 0], a[i, 1], a[i, 2] = u[0], u[1], u[2]
        a[i, 3] = p[1] * u[2] - p[2] * u[1]
        a[i, 4] = p[2] * u[0] - p[0] * u[2]
        a[i, 5] = p[0] * u[1] - p[1] * u[0]
    det = 1.0
    for k in range(6):
        piv = k
        for i in range(k + 1, 6):
            if abs(a[i, k]) > abs(a[piv, k]):
                piv = i
        if a[piv, k] == 0.0:
            return 0.0
        if piv != k:
            for j in range(6):
                a[k, j], a[piv, j] = a[piv, j], a[k, j]
            det = -det
        det *= a[k, k]
        for i in range(k + 1, 6):
            f = a[i, k] / a[k, k]
            for j in range(k, 6):
                a[i, j] -= f * a[k, j]
    return det


def _platforms(model: Model) -> list[_Platform]:
    """The Stewart–Gough platforms of a model (see the module docstring)."""
    out = []
    ends = model.actuators.end_ydofs                       # (na, 6): start xyz ids, end xyz ids
    for o in model.scene.outputs:
        if o.kind != "platform_pose":
            continue
        node_ids = np.array([model.node_ydofs[model.node(n)] for n in o.nodes], dtype=np.int64)   # (3, 3)
        starts = {tuple(r) for r in node_ids.tolist()}
        legs, far, near = [], [], []
        for i, e in enumerate(ends):
            a, b = tuple(e[:3].tolist()), tuple(e[3:].tolist())
            if b in starts and a not in starts:
                legs.append(i), far.append(e[:3]), near.append(e[3:])
            elif a in starts and b not in starts:
                legs.append(i), far.append(e[3:]), near.append(e[:3])
        if len(legs) == 6:
            out.append(_Platform(model, o.name, node_ids, np.array(legs), np.ascontiguousarray(far, dtype=np.int64),
                                 np.ascontiguousarray(near, dtype=np.int64)))
    return out


class FaultMonitor:
    """Checks states against the scene's ``limits:`` (module docstring)."""

    def __init__(self, model: Model):
        self.model = model
        lim = model.scene.limits
        self.max_force = lim.max_actuator_force if lim is not None else math.inf
        self.detect_singular = lim.singular_configurations == "detect" if lim is not None else True
        self.stop = lim is not None and lim.on_violation == "stop"
        self.platforms = _platforms(model) if self.detect_singular else []

    @property
    def active(self) -> bool:
        return math.isfinite(self.max_force) or bool(self.platforms)

    def check(self, q: np.ndarray, forces: np.ndarray) -> list[Fault]:
        """The faults of positions ``q (ndof,)`` with actuator forces ``forces (na,)`` (N)."""
        faults = []
        if forces.size and math.isfinite(self.max_force):
            k = int(np.argmax(np.abs(forces)))
            if not abs(forces[k]) <= self.max_force:
                faults.append(Fault("actuator_force", f"actuator '{self.model.actuators.names[k]}' carries "
                                                      f"{forces[k]:.4g} N, beyond limits.max_actuator_force "
                                                      f"{self.max_force:.4g} N"))
        for p in self.platforms:
            d = p.det(q)
            if not math.copysign(1.0, d) == p.sign0 or d == 0.0:
                faults.append(Fault("assembly_mode", f"platform '{p.name}' passed through a singular configuration "
                                                     "of its legs (the sign of the leg Jacobian's determinant "
                                                     "changed): it is in another assembly mode"))
        return faults
