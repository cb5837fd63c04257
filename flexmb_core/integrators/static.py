"""Static equilibrium by load (pseudo-time) stepping with Newton–Raphson and step bisection.

Every quantity that depends on time (load signals, actuator commands) is evaluated at the
pseudo-time of the increment, so a static run is a sequence of equilibria t_k = k·T/N.

Load stepping cannot pass a limit point: past it the equilibrium it converges to (if any) lies on
another branch. :class:`SnapThroughMonitor` reports such a step, a **snap-through**, when the step
**jumped**: its converged increment of the free nodal positions is more than :data:`JUMP_RATIO`
times the first Newton increment, the tangent's linear prediction of the same load increment. On a
smooth path the two agree to first order in the step (ratios 0.8–1.2 measured on the shipped static
scenes and on Lee's frame before its limit point), while a jump to a distant branch is several
times longer (Lee's frame 3.8–12×, the shallow arch 23×). A jump whose step also changed the
number of negative pivots of the tangent (a critical point was passed,
:mod:`flexmb_core.integrators.critical`) is a ``critical_point+jump``.

A step that changes the pivot count *without* jumping passed a **bifurcation** and stayed on the
(now unstable) fundamental branch: that is reported among the bifurcations, not as a snap-through
(the run did not change branch): e.g. ``scenes/shell_roll_up.yaml`` loses stability out of its
plane (a lateral mode of the rolled strip) between M/M_max = 0.75 and 0.875.

Path following through limit points and snap-backs: :mod:`flexmb_core.integrators.path_following`.
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
from .critical import TangentLU
from .energy import gravity_potential
from .path_following import dof_index, position_mask
from .static_step import NumbaStatic

# A converged load step longer than this many times its tangent prediction is a jump between
# branches (see the module docstring).
JUMP_RATIO = 3.0


class SnapThroughMonitor:
    """Watches a load-stepping run for snap-throughs (see the module docstring).

    Attributes
    ----------
    events : list[dict] — one per snap-through: ``step``, ``t`` (pseudo-time), ``displacement``
        and ``displacement_before`` (the ``solver.monitor`` component, m; None without one),
        ``kind`` (``jump`` | ``critical_point+jump``), ``negative_pivots`` [before, after] and
        ``jump_ratio``.
    bifurcations : list[dict] — one per critical point passed without a jump, the same keys, and
        ``kind`` ``stability_loss`` (more negative pivots) or ``stability_gain``.
    """

    def __init__(self, model: Model, spec: SolverSpec):
        self.model = model
        self.pivots = TangentLU(model)
        self.w = position_mask(model)[:model.nfree]
        self.monitor = dof_index(model, spec.monitor) if spec.monitor is not None else -1
        self.events: list[dict] = []
        self.bifurcations: list[dict] = []
        self.steps = 0
        self._count: int | None = None
        self._u_prev = 0.0

    def _u(self, q: np.ndarray) -> float | None:
        return float(q[self.monitor] - self.model.q0[self.monitor]) if self.monitor >= 0 else None

    def observe(self, q_start: np.ndarray, q: np.ndarray, t: float, kdata: np.ndarray,
                predicted: float) -> None:
        """A converged step from ``q_start`` to ``q`` (ndof,) whose tangent at ``q`` is ``kdata``;
        ``predicted`` = ‖first Newton increment‖ of the free positions (m), 0 for the first solve."""
        count = self.pivots.count(kdata)
        free = self.model.free
        moved = float(np.linalg.norm((q[free] - q_start[free])[self.w]))
        ratio = moved / predicted if predicted > 0.0 else 0.0
        critical = self.steps > 0 and count is not None and self._count is not None and count != self._count
        jump = self.steps > 0 and ratio > JUMP_RATIO
        if critical or jump:
            event = {"step": self.steps, "t": t, "displacement_before": self._u(q_start), "displacement": self._u(q),
                     "negative_pivots": [self._count, count], "jump_ratio": ratio}
            if jump:
                self.events.append({**event, "kind": "critical_point+jump" if critical else "jump"})
            else:
                self.bifurcations.append({**event, "kind": "stability_loss" if count > self._count
                                          else "stability_gain"})
        if count is not None:
            self._count = count
        self.steps += 1


class StaticSolver:
    """Newton on ``f_int(q; λ(t)) = f_ext(t)`` for the free DOFs."""

    def __init__(self, model: Model, ws: Workspace, spec: SolverSpec, *, monitor: bool | None = None):
        self.model = model
        self.ws = ws
        self.spec = spec
        self.lu = FixedPatternSolver(model)
        self._inv_scale = 1.0 / model.dof_scale[model.free]
        self._backup: State | None = None
        self.guard = StepGuard(model, tolerance=spec.tolerance)
        self._q_p = np.zeros(model.ndof)            # Newton start of the increment under way
        self._c_p = np.zeros(model.n_multipliers)
        self._w = position_mask(model)[:model.nfree]
        self._predicted = -1.0                     # ‖first Newton increment‖ of the step (m); −1: not yet
        # snap-through watch: on for static runs (one more tangent and factorization per step)
        watch = spec.analysis == "static" if monitor is None else monitor
        self.snap = SnapThroughMonitor(model, spec) if watch else None
        # One numba call per load increment (bit-identical states; None: the Python loop, which
        # also makes the increments whose tangent needs SuperLU's pivoting)
        self.fast = None if NumbaStatic.unsupported(model) else NumbaStatic(self)

    def solve_at(self, state: State, t: float, lam: np.ndarray) -> StepResult:
        """Equilibrium at pseudo-time ``t`` starting from ``state.q``. On failure, the policy
        ``on_unconverged`` applies as in dynamics: ``substep`` bisects the load increment,
        ``stop`` restores the state, ``accept_flagged`` keeps the flagged iterate."""
        if self._backup is None:
            self._backup = state.copy()
        self._backup.assign(state)
        self._predicted = -1.0
        res = self._newton(state, t, lam)
        if not res.converged and self.spec.on_unconverged == "substep":
            t0 = self._backup.t
            res = retry_in_pieces(res, lambda k, n, lam_k: self._newton(state, t0 + (t - t0) * k / n, lam_k),
                                  state, self._backup, lam, self.spec.max_substep_levels, "load increments")
        elif not res.converged and self.spec.on_unconverged == "stop":
            state.assign(self._backup)
        if res.converged and self.snap is not None:
            assemble(self.model, self.ws, state.q, state.lam, True, state.mult)
            self.snap.observe(self._backup.q, state.q, t, self.ws.kdata, max(self._predicted, 0.0))
        return res

    def _newton(self, state: State, t: float, lam: np.ndarray) -> StepResult:
        if self.fast is not None:
            res = self.fast.solve(state, t, lam)
            if res is not None:
                return res
        # A diverging iterate overflows (norms of huge residuals, inf − inf): every value that
        # matters is checked for finiteness and a failure is reported in the StepResult, so numpy
        # need not print warnings on the way.
        with np.errstate(all="ignore"):
            return self._newton_steps(state, t, lam)

    def _newton_steps(self, state: State, t: float, lam: np.ndarray) -> StepResult:
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
            if it == 1 and self._predicted < 0.0:    # the tangent's prediction of the whole step
                self._predicted = float(np.linalg.norm(dq[:nf][self._w]))
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
        grav = gravity_potential(state.q, m.q0, m.gravity_vector)
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
