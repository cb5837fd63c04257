"""Static equilibrium by load (pseudo-time) stepping with Newton–Raphson and step bisection.

Every quantity that depends on time (load signals, actuator commands) is evaluated at the
pseudo-time of the increment, so a static run is a sequence of equilibria t_k = k·T/N.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.assembly import apply_drives, assemble, update_load_scales
from ..model.model import Model
from ..model.workspace import State, Workspace
from ..scene.schema import SolverSpec
from ..solvers.guard import StepGuard
from ..solvers.linear import FixedPatternSolver
from ..solvers.result import StepResult
from ..solvers.substep import retry_in_pieces
from .energy import energies


class StaticSolver:
    """Newton on ``f_int(q; λ(t)) = f_ext(t)`` for the free DOFs."""

    def __init__(self, model: Model, ws: Workspace, spec: SolverSpec):
        self.model = model
        self.ws = ws
        self.spec = spec
        self.lu = FixedPatternSolver(model)
        self._inv_scale = 1.0 / model.dof_scale[model.free]
        self._backup: State | None = None
        self.guard = StepGuard(model, tolerance=spec.tolerance)
        self._q_p = np.zeros(model.ndof)            # Newton start of the increment under way
        self._c_p = np.zeros(model.n_multipliers)

    def solve_at(self, state: State, t: float, lam: np.ndarray) -> StepResult:
        """Equilibrium at pseudo-time ``t`` starting from ``state.q``. On failure, the policy
        ``on_unconverged`` applies as in dynamics: ``substep`` bisects the load increment,
        ``stop`` restores the state, ``accept_flagged`` keeps the flagged iterate."""
        if self._backup is None:
            self._backup = state.copy()
        self._backup.assign(state)
        res = self._newton(state, t, lam)
        if res.converged or self.spec.on_unconverged != "substep":
            if not res.converged and self.spec.on_unconverged == "stop":
                state.assign(self._backup)
            return res
        t0 = self._backup.t
        return retry_in_pieces(res, lambda k, n, lam_k: self._newton(state, t0 + (t - t0) * k / n, lam_k),
                               state, self._backup, lam, self.spec.max_substep_levels, "load increments")

    def _newton(self, state: State, t: float, lam: np.ndarray) -> StepResult:
        m, ws, spec = self.model, self.ws, self.spec
        free = m.free
        state.lam[:] = lam
        state.t = t
        update_load_scales(m, ws, t)
        q = state.q
        apply_drives(m, q, t)
        self._q_p[:] = q
        u_p = 0.0
        inc, rel, message, converged, it = math.inf, math.inf, "", False, 0
        nf = m.nfree
        rf = np.zeros(m.nsys)
        for it in range(1, spec.max_iterations + 1):
            strain = assemble(m, ws, q, lam, True, state.mult)
            if it == 1:
                u_p = strain
                if m.n_multipliers:
                    self._c_p[:] = ws.rc
            rf[:nf] = (ws.r - ws.f_ext)[free]
            rf[nf:] = ws.rc
            if not np.all(np.isfinite(rf)):
                message = f"non-finite residual at iteration {it}"
                break
            try:
                self.lu.factor(ws.kdata)
            except RuntimeError as exc:
                message = (f"singular tangent at iteration {it} ({exc}); "
                           "a mechanism with a free motion needs a support")
                break
            dq = self.lu.solve(-rf)
            if not np.all(np.isfinite(dq)):
                message = f"non-finite increment at iteration {it}"
                break
            q[free] += dq[:nf]
            state.mult += dq[nf:]
            inc = float(np.max(np.abs(dq[:nf]) * self._inv_scale))
            ref = max(np.linalg.norm(ws.r[free]), np.linalg.norm(ws.f_ext[free]), 1e-300)
            rel = float(np.linalg.norm(rf[:nf]) / ref)
            viol = float(np.abs(rf[nf:]).max()) if m.n_multipliers else 0.0
            if inc <= spec.tolerance and viol <= spec.tolerance:
                converged = True
                break
        if not converged:
            if not message:
                message = f"no convergence in {spec.max_iterations} iterations (increment {inc:.2e})"
            return StepResult(False, it, rel, inc, 1, message=message)
        strain = assemble(m, ws, q, lam, False, state.mult)
        rf = (ws.r - ws.f_ext)[free]
        ref = max(np.linalg.norm(ws.r[free]), np.linalg.norm(ws.f_ext[free]), 1e-300)
        rel = float(np.linalg.norm(rf) / ref)
        _, grav = energies(m, state)
        if self.guard.enabled:
            flag, why = self._guard(state, u_p, strain)
            if flag:
                self.guard.rejections += 1
                return StepResult(False, it, rel, inc, 1, 0.0, strain, grav, message=why, guard=flag)
        return StepResult(True, it, rel, inc, 1, 0.0, strain, grav)

    def _guard(self, state: State, u_p: float, u_end: float) -> tuple[str, str]:
        """The step guard on the converged ``state.q`` (statics: ``Φ = U − f_ext·q`` + moments and
        multiplier terms, from the Newton start): ``('', '')`` or (flag, reason)."""
        m, ws, g = self.model, self.ws, self.guard
        q = state.q
        flag, why = g.orientation(q, state.lam)
        if flag:
            return flag, why
        dq = q - self._q_p
        w_ext = float(ws.f_ext @ dq)
        w_mom = g.moment_work(q, self._q_p, ws.follower_scale, ws.cons_scale)
        w_mult = float(state.mult @ (ws.rc - self._c_p)) if m.n_multipliers else 0.0
        return g.potential_rise((-w_ext, -w_mom, w_mult), u_p, u_end, g.resolution(ws.r, ws.f_ext))
