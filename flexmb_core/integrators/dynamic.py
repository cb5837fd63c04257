"""Implicit dynamics with Newton–Raphson: Newmark (β, γ) and generalized-α in the Arnold–Brüls
form (equilibrium at t_{n+1}, SPEC §1.7). Newmark is the αm = αf = 0 member of the family.

Unknowns at t_{n+1}: q. With the pseudo-acceleration ã,
    ã(q) = (q − q_n − Δt v_n − Δt²(½−β) ã_n) / (β Δt²)
    a(q) = ((1−αm) ã(q) + αm ã_n − αf a_n) / (1−αf),   v(q) = v_n + Δt[(1−γ) ã_n + γ ã(q)]
    residual  r(q) = f_int(q, v(q); λ_{n+1}, λ̇_{n+1}) + M (a + c_m v) − f_ext(t_{n+1})
    tangent   K + c_v C + (c_a + c_m c_v) M,  c_a = (1−αm)/((1−αf) β Δt²),  c_v = γ/(β Δt)

f_int holds the elastic and, for materials with ``eta`` > 0, the Kelvin–Voigt viscous forces;
K = ∂f_int/∂q at fixed v (non-symmetric with damping) and C = ∂f_int/∂v. The actuator stretch rate
λ̇_{n+1} (read by damped actuators only) is the second-order backward difference of the last three
stretches unless the caller passes it (first order on the first step after a start or a restore:
a first-order rate would leave an O(Δt) viscous-force error, EA·τ·λ̈·Δt/2, in the leg forces).

``chung_hulbert`` is the original generalized-α (Chung & Hulbert 1993): inertia at t_{n+1−αm} and
internal/external forces at the *interpolated configuration* q_{n+1−αf} = (1−αf) q_{n+1} + αf q_n.
Interpolating absolute positions and vectors of a rotating body shortens it, so this form is not
objective for positional unknowns (SPEC §1.7); it is kept to demonstrate that, not for use.

Newton is either full (tangent every iteration) or modified: the factorization is kept across
iterations and steps while each increment shrinks by at least ``modified_contraction``, and is
refreshed when it does not, when Δt changes, or after ``tangent_max_age`` steps.
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from ..model.assembly import apply_drives, assemble, assemble_constraints, update_load_scales
from ..model.model import Model
from ..model.step_data import T_AGE, T_COEF, T_COUNT, T_HELD, StepData
from ..model.workspace import State, Workspace
from ..scene.schema import SolverSpec
from ..solvers.guard import StepGuard
from ..solvers.linear import FixedPatternSolver
from ..solvers.result import StepResult
from ..solvers.substep import retry_in_pieces
from .energy import compact_csr, csr_matvec, energies, mass_blocks
from .fast import NumbaStep


def alpha_parameters(spec: SolverSpec) -> tuple[float, float, float, float]:
    """(αm, αf, β, γ) of the chosen integrator."""
    if spec.integrator == "newmark":
        return 0.0, 0.0, spec.beta, spec.gamma
    rho = spec.rho_inf
    am = (2.0 * rho - 1.0) / (rho + 1.0)
    af = rho / (rho + 1.0)
    gamma = 0.5 + af - am
    if spec.integrator == "chung_hulbert":
        return am, af, 0.25 * (1.0 - am + af) ** 2, gamma
    beta = 0.25 * (gamma + 0.5) ** 2
    return am, af, beta, gamma


class DynamicIntegrator:
    """One implicit step at a time; owns the linear solver and scratch vectors.

    ``data``: the run's :class:`~flexmb_core.model.step_data.StepData` (default: its own). The
    integrator steps ``data.state`` only; the stretch history, the held tangent's bookkeeping and
    the guard's ledger are items of ``data``, so that a rollback of ``data`` restores them too."""

    def __init__(self, model: Model, ws: Workspace, spec: SolverSpec, data: StepData | None = None):
        self.model = model
        self.data = StepData(model) if data is None else data
        self.ws = ws
        self.spec = spec
        self.am, self.af, self.beta, self.gamma = alpha_parameters(spec)
        lacking = NumbaStep.unsupported(model, spec)
        if lacking:
            raise SceneError(f"{model.scene.source}:solver", f"the dynamic step cannot run this model: {lacking}")
        self.lu = FixedPatternSolver(model)
        n = model.ndof
        self._ma = np.zeros(n)
        self._mass = compact_csr(*model.mass_csr)   # M without its stored zeros (same products)
        self._mass_blocks = mass_blocks(*self._mass)  # … and as M_s ⊗ I₃ where it is (same sums)
        self._backup = None
        self._free = model.free
        self._inv_scale = 1.0 / model.dof_scale[model.free]
        self._nf = model.nfree
        # Held tangent: [held (0/1), its coefficient c_a + c_m c_v, age in steps, refreshes so far];
        # an item of the step data that the numba step reads and writes in place.
        self._tan = self.data.tan
        self.guard = StepGuard(model, tolerance=spec.tolerance, ledger=(self.data.gvec, self.data.react,
                                                                         self.data.led))
        self.fast = NumbaStep(self)      # the step: one numba call (integrators/fast.py)

    @property
    def _factored_coef(self) -> float | None:
        """Tangent coefficient of the held factorization, or None."""
        return float(self._tan[T_COEF]) if self._tan[T_HELD] != 0.0 else None

    @_factored_coef.setter
    def _factored_coef(self, coef: float | None) -> None:
        if coef is None:
            self._tan[T_HELD] = 0.0
        else:
            self._tan[T_HELD] = 1.0
            self._tan[T_COEF] = coef

    @property
    def tangent_updates(self) -> int:
        """Tangent refreshes so far."""
        return int(self._tan[T_COUNT])

    # -- start ------------------------------------------------------------------------------
    def warmup(self, state: State) -> None:
        """Compile (or load) every kernel a step calls by one throwaway numba step from
        ``state``, so that none compiles inside the time loop (a first real-time step would miss
        its deadline by seconds). The step data is put back as it was, with no held tangent;
        :meth:`initialize` then forms the loads and the guard's ledger."""
        saved = self.data.copy()
        st = self.data.state
        st.assign(state)
        self.fast.attempt(st, self.spec.dt, st.lam.copy())
        self.fast.attempts(st.t, self.spec.dt, st.lam.copy(), 1)     # Simulator.run's batches
        self.fast.invalidate()
        self.data.buf[:] = saved.buf
        self._tan[T_HELD] = self._tan[T_AGE] = self._tan[T_COUNT] = 0.0

    def initialize(self, state: State) -> StepResult:
        """Consistent initial acceleration ``M_ff a_f = (f_ext − f_int − C v)_f`` (or zero)."""
        self._factored_coef = None
        self.fast.invalidate()
        m, ws = self.model, self.ws
        update_load_scales(m, ws, state.t)
        apply_drives(m, state.q, state.t)
        strain = assemble(m, ws, state.q, state.lam, False, v=state.v, lam_rate=state.lam_rate)
        state.a[:] = 0.0
        if self.spec.initial_acceleration == "consistent":
            csr_matvec(*self._mass, state.v, self._ma)
            rhs = np.zeros(m.nsys)
            rhs[:self._nf] = (ws.f_ext - ws.r - m.mass_damping * self._ma)[self._free]
            if m.n_multipliers:
                # [M Gᵀ; G 0][a; λ] = [f − f_int; 0]: only the corner Jacobian G goes into kdata
                # (at λ = 0 the corners add nothing to the forces already in ws.r).
                ws.kdata[:] = 0.0
                assemble_constraints(m, ws, state.q, ws.no_mult, True)
                self.lu.factor(ws.kdata, mass=m.mass_kdata, coef=1.0)
            else:
                self.lu.factor(m.mass_kdata)
            sol = self.lu.solve(rhs)
            state.a[self._free] = sol[:self._nf]
            state.mult[:] = sol[self._nf:]
        state.atil[:] = state.a
        kin, grav = energies(m, state, self._mass_blocks)
        self.guard.ledger_start(state.t, kin, strain, ws.f_ext, ws.r, state.q, state.a, state.v)
        return StepResult(True, 0, 0.0, 0.0, 1, kin, strain, grav)

    # -- one step ---------------------------------------------------------------------------
    def step(self, state: State, dt: float, lam_new: np.ndarray,
             lam_rate: np.ndarray | None = None) -> StepResult:
        """Advance ``state`` by ``dt`` to the actuator stretches ``lam_new``: one call of the numba
        step (:meth:`~.fast.NumbaStep.attempt`).

        ``lam_rate``: dλ/dt at the end of the step (1/s), read by material damping only; default
        the second-order backward difference of λ_{n−1}, λ_n, λ_{n+1}. On failure the step is
        retried in 2, 4, … sub-steps (policy ``substep``) with the stretches interpolated linearly
        (and backward differences); ``state`` is left unchanged if nothing converges.
        """
        self._check(state)
        return self._settle(state, dt, lam_new, self.fast.attempt(state, dt, lam_new, lam_rate))

    def steps(self, state: State, dt: float, lam_new: np.ndarray,
              count: int) -> tuple[int, StepResult, np.ndarray, bool]:
        """Up to ``count`` steps ``dt`` in one numba call, where the integrator's numba step
        batches them (:meth:`~.fast.NumbaStep.batches`), to the stretches ``lam_new``: the same for
        every step ``(na,)``, or one row per step ``(k, na)`` (no rates given): what as many
        :meth:`step` calls would give. Stops after the first step that fails its attempt, which the
        policy then settles as :meth:`step` does. Returns the steps the numba call accepted, the
        last step's result (that settled one, if any), the tally of the accepted ones
        (:meth:`~.fast.NumbaStep.attempts`) and whether the last step was settled."""
        self._check(state)
        done, res, tally = self.fast.attempts(state.t, dt, lam_new, count)
        failed = not res.converged
        if failed:
            res = self._settle(state, dt, lam_new[done] if lam_new.ndim == 2 else lam_new, res)
        return done, res, tally, failed

    def _check(self, state: State) -> None:
        if state is not self.data.state:
            raise ValueError("the integrator advances the state of its step data only (sim.state)")
        if self._backup is None:
            self._backup = state.copy()

    def _settle(self, state: State, dt: float, lam_new: np.ndarray, res: StepResult) -> StepResult:
        """The step's result after its first attempt ``res``: that one when it converged or the
        policy is not ``substep``, else the split step's."""
        # a failed attempt leaves the state at the step's start (accept_flagged: at its last iterate)
        if res.converged or self.spec.on_unconverged != "substep":
            return res
        self._backup.assign(state)
        # a failed step leaves the guard's energy ledger at the step's start: keep it for the splits
        self.guard.ledger_save()
        res = retry_in_pieces(res, lambda k, n, lam_k: self._piece(state, dt / n, lam_k, k), state,
                              self._backup, lam_new, self.spec.max_substep_levels, "sub-steps")
        self.fast.invalidate()
        if not res.converged:
            self.guard.ledger_restore()
        return res

    def _piece(self, state: State, dt: float, lam_new: np.ndarray, k: int) -> StepResult:
        """Sub-step ``k`` of a split step (each split starts again from the step's start)."""
        if k == 1:
            self.guard.ledger_restore()
        return self.fast.attempt(state, dt, lam_new)
