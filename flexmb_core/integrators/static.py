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

import numpy as np

from ..errors import SceneError
from ..model.assembly import assemble
from ..model.model import Model
from ..model.workspace import State, Workspace
from ..scene.schema import SolverSpec
from ..solvers.guard import StepGuard
from ..solvers.linear import FixedPatternSolver
from ..solvers.result import StepResult
from ..solvers.substep import retry_in_pieces
from .critical import TangentLU
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
        self._w = position_mask(model)[:model.nfree]
        self._predicted = -1.0                     # ‖first Newton increment‖ of the step (m); −1: not yet
        # snap-through watch: on for static runs (one more tangent and factorization per step)
        watch = spec.analysis == "static" if monitor is None else monitor
        self.snap = SnapThroughMonitor(model, spec) if watch else None
        lacking = NumbaStatic.unsupported(model)
        if lacking:
            raise SceneError(f"{model.scene.source}:solver", f"the static Newton cannot run this model: {lacking}")
        self.fast = NumbaStatic(self)            # one numba call per load increment (static_step.py)

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
        return self.fast.solve(state, t, lam)
