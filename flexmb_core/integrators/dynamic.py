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

import math

import numpy as np

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
from .fast import NumbaStep, accept_stretches, begin_stretches
from .fused import apply_increment, inertial_residual, update_rates, velocity_at


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
        self.lu = FixedPatternSolver(model)
        n = model.ndof
        self._ma = np.zeros(n)
        self._mass = compact_csr(*model.mass_csr)   # M without its stored zeros (same products)
        self._mass_blocks = mass_blocks(*self._mass)  # … and as M_s ⊗ I₃ where it is (same sums)
        self._backup = None
        self._free = model.free
        self._inv_scale = 1.0 / model.dof_scale[model.free]
        # Step-start rows q_n, v_n, a_n, ã_n, q̂, the Newton start q_p and the guard's start forces,
        # stacked so that the step guard takes them as one argument.
        self._ivec = np.zeros((7, n))
        self._q_n, self._v_n, self._a_n, self._at_n, self._q_hat, self._q_p, self._g_p = self._ivec
        self._w = np.zeros(n)
        self._q_eval = np.zeros(n)
        self._v_eval = np.zeros(n)
        self._damped = bool(model.material_damping)
        self._no_rate = np.zeros(model.actuators.l0.size)   # the rates argument when none is given
        self._rf = np.zeros(model.nsys)
        self._nf = model.nfree
        # Held tangent: [held (0/1), its coefficient c_a + c_m c_v, age in steps, refreshes so far];
        # an item of the step data that the numba step reads and writes in place (see the
        # properties below).
        self._tan = self.data.tan
        self.guard = StepGuard(model, tolerance=spec.tolerance, ledger=(self.data.gvec, self.data.react,
                                                                         self.data.led))
        # One numba call per step when it covers the model (bit-identical to _newton; None: the
        # Python path; set it to None to force that path).
        self.fast = None if NumbaStep.unsupported(model, spec) else NumbaStep(self)
        self._c_p = np.zeros(model.n_multipliers)   # constraint violations at the Newton start

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
    def _tangent_age(self) -> int:
        """Steps since the last tangent refresh."""
        return int(self._tan[T_AGE])

    @_tangent_age.setter
    def _tangent_age(self, age: int) -> None:
        self._tan[T_AGE] = age

    @property
    def tangent_updates(self) -> int:
        """Tangent refreshes so far."""
        return int(self._tan[T_COUNT])

    @tangent_updates.setter
    def tangent_updates(self, n: int) -> None:
        self._tan[T_COUNT] = n

    # -- start ------------------------------------------------------------------------------
    def warmup(self, state: State) -> None:
        """Compile (or load) every kernel a step calls — the numba step, or the Python Newton's
        kernels and the step guard's — by one throwaway step from ``state``, so that none
        compiles inside the time loop (a first real-time step would miss its deadline by seconds).
        The step data is put back as it was, with no held tangent; :meth:`initialize` then forms
        the loads and the guard's ledger."""
        saved = self.data.copy()
        st = self.data.state
        st.assign(state)
        if self.fast is not None:
            self.fast.attempt(st, self.spec.dt, st.lam.copy())
            self.fast.invalidate()
        else:
            self.initialize(st)
            self._newton(st, self.spec.dt, st.lam.copy())
        self.data.buf[:] = saved.buf
        self._factored_coef = None
        self._tangent_age = 0
        self.tangent_updates = 0

    def initialize(self, state: State) -> StepResult:
        """Consistent initial acceleration ``M_ff a_f = (f_ext − f_int − C v)_f`` (or zero)."""
        self._factored_coef = None
        if self.fast is not None:
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
        """Advance ``state`` by ``dt`` to the actuator stretches ``lam_new``.

        ``lam_rate``: dλ/dt at the end of the step (1/s), read by material damping only; default
        the second-order backward difference of λ_{n−1}, λ_n, λ_{n+1}. On failure the step is
        retried in 2, 4, … sub-steps (policy ``substep``) with the stretches interpolated linearly
        (and backward differences); ``state`` is left unchanged if nothing converges.
        """
        if state is not self.data.state:
            raise ValueError("the integrator advances the state of its step data only (sim.state)")
        if self._backup is None:
            self._backup = state.copy()
        res = self.fast.attempt(state, dt, lam_new, lam_rate) if self.fast is not None else None
        if res is None:
            self._backup.assign(state)
            res = self._newton(state, dt, lam_new, lam_rate)
            if self.fast is not None:
                self.fast.invalidate()
        elif not res.converged and self.spec.on_unconverged != "accept_flagged":
            self._backup.assign(state)      # the numba attempt leaves the step's start in place
        if res.converged or self.spec.on_unconverged != "substep":
            if not res.converged and self.spec.on_unconverged == "stop":
                state.assign(self._backup)
            return res
        # a failed step leaves the guard's energy ledger at the step's start: keep it for the splits
        self.guard.ledger_save()
        res = retry_in_pieces(res, lambda k, n, lam_k: self._piece(state, dt / n, lam_k, k), state,
                              self._backup, lam_new, self.spec.max_substep_levels, "sub-steps")
        if self.fast is not None:
            self.fast.invalidate()
        if not res.converged:
            self.guard.ledger_restore()
        return res

    def set_stretches(self, dt: float, lam_new: np.ndarray, lam_rate: np.ndarray | None) -> bool:
        """λ_{n+1} into the state's ``lam`` and, for damped models, its rate λ̇_{n+1} into
        ``lam_rate`` (given, or the backward difference over the stretch history): the numba
        step's :func:`~.fast.begin_stretches`. Returns whether any actuator moves in the step."""
        given = lam_rate is not None
        return begin_stretches(self.data.buf, self.data.lay, lam_new, lam_rate if given else self._no_rate, given,
                               self._damped, dt)

    def _piece(self, state: State, dt: float, lam_new: np.ndarray, k: int) -> StepResult:
        """Sub-step ``k`` of a split step (each split starts again from the step's start)."""
        if k == 1:
            self.guard.ledger_restore()
        res = self.fast.attempt(state, dt, lam_new) if self.fast is not None else None
        if res is None:
            res = self._newton(state, dt, lam_new)
            if self.fast is not None:
                self.fast.invalidate()
        return res

    def _newton(self, state: State, dt: float, lam_new: np.ndarray,
                lam_rate: np.ndarray | None = None) -> StepResult:
        m, ws, spec = self.model, self.ws, self.spec
        am, af, beta, gamma = self.am, self.af, self.beta, self.gamma
        c_tilde = 1.0 / (beta * dt * dt)
        c_a = (1.0 - am) / ((1.0 - af) * beta * dt * dt)
        c_v = gamma / (beta * dt)
        c_m = m.mass_damping
        free = self._free
        q_n, v_n, a_n, at_n, q_hat = self._q_n, self._v_n, self._a_n, self._at_n, self._q_hat
        q_n[:] = state.q
        v_n[:] = state.v
        a_n[:] = state.a
        at_n[:] = state.atil
        # q ↦ ã(q) = (q − q_hat)/(βΔt²); predictor: constant pseudo-acceleration (prescribed DOFs stay).
        np.multiply(at_n, (0.5 - beta) * dt * dt, out=q_hat)
        q_hat += q_n
        q_hat += dt * v_n
        t_new = state.t + dt
        damped = self._damped
        t_n = state.t
        lam_moved = self.set_stretches(dt, lam_new, lam_rate)
        ch = spec.integrator == "chung_hulbert"
        if ch and m.n_multipliers:
            raise ValueError("the chung_hulbert integrator does not support rigid corners (multipliers)")
        update_load_scales(m, ws, t_new - af * dt if ch else t_new)
        q = state.q
        q[free] = q_hat[free] + (beta * dt * dt) * at_n[free]
        apply_drives(m, q, t_new)
        self._q_p[:] = q
        if ch:
            # Newmark kinematics with a itself (ã ≡ a); inertia (1−αm) a_{n+1} + αm a_n through the
            # fused kernel with αf = 0; forces at q_{n+1−αf}; tangent (1−αf) K + (1−αm)/(βΔt²) M.
            c_a = (1.0 - am) / (beta * dt * dt)
            k_scale, am_r, af_r = 1.0 - af, am, 0.0
        else:
            k_scale, am_r, af_r = 1.0, am, af
        q_eval = self._q_eval if ch else q
        coef = c_a + c_m * c_v
        converged = False
        inc = math.inf
        rel = math.inf
        message = ""
        strain = 0.0
        guarded = self.guard.enabled
        u_p = 0.0
        diss_p = 0.0
        it = 0
        modified = spec.newton == "modified"
        refresh = (not modified or self._factored_coef != coef
                   or self._tangent_age >= spec.tangent_max_age)
        prev_inc = math.inf
        mb, mi, mj, mv = self._mass_blocks
        for it in range(1, spec.max_iterations + 1):
            if ch:
                np.multiply(q, 1.0 - af, out=q_eval)
                q_eval += af * q_n
            if damped:
                velocity_at(q, q_hat, at_n, v_n, c_tilde, gamma, dt, af if ch else 0.0, self._v_eval)
                strain = assemble(m, ws, q_eval, state.lam, refresh, state.mult, v=self._v_eval,
                                  lam_rate=state.lam_rate, c_v=c_v)
            else:
                strain = assemble(m, ws, q_eval, state.lam, refresh, state.mult)
            keep = it == 1 and guarded
            nr, ref = inertial_residual(q, q_hat, at_n, a_n, v_n, c_tilde, am_r, af_r, gamma, dt, c_m,
                                        mb, mi, mj, mv, ws.r, ws.f_ext, m.free_index, self._w, self._rf, keep,
                                        self._g_p)
            rel = nr / ref
            if keep:
                u_p = strain
                diss_p = ws.dissipation
                if m.n_multipliers:
                    self._c_p[:] = ws.rc
            viol = 0.0
            if m.n_multipliers:
                self._rf[self._nf:] = ws.rc
                viol = float(np.abs(ws.rc).max())
            if not math.isfinite(nr):
                message = f"non-finite residual at Newton iteration {it}"
                break
            if refresh:
                if k_scale != 1.0:
                    ws.kdata *= k_scale
                try:
                    self.lu.factor(ws.kdata, mass=m.mass_kdata, coef=coef)
                except RuntimeError as exc:
                    self._factored_coef = None
                    message = f"singular tangent at Newton iteration {it} ({exc})"
                    break
                self._factored_coef = coef
                self._tangent_age = 0
                self.tangent_updates += 1
            dq = self.lu.solve(self._rf)
            inc = apply_increment(q, free, dq, -1.0, self._inv_scale)
            if m.n_multipliers:
                state.mult -= dq[self._nf:]
            if not math.isfinite(inc):
                message = f"non-finite increment at Newton iteration {it}"
                break
            if inc <= spec.tolerance and viol <= spec.tolerance:
                converged = True
                break
            # Modified Newton keeps the factorization while it contracts fast; otherwise refresh.
            refresh = not modified or inc > spec.modified_contraction * prev_inc
            prev_inc = inc
        if not converged and not message:
            message = f"no convergence in {spec.max_iterations} iterations (increment {inc:.2e}, tolerance {spec.tolerance:.1e})"
        if ch:
            update_rates(q, q_hat, at_n, a_n, v_n, c_tilde, 0.0, 0.0, gamma, dt, state.a, state.v, state.atil)
        else:
            update_rates(q, q_hat, at_n, a_n, v_n, c_tilde, am, af, gamma, dt, state.a, state.v, state.atil)
        state.t = t_new
        guard = ""
        if converged and guarded:
            kin, grav = energies(m, state, self._mass_blocks)
            guard, why = self.guard.dynamic(self, state, dq, self._rf, self._c_p, c_v, af if ch else 0.0, u_p,
                                            strain, diss_p, kin, t_n, not ch and not lam_moved)
            if guard:
                converged = False
                message = why
                self.guard.rejections += 1
        if not converged:
            self._factored_coef = None   # a failed step never leaves a stale tangent behind
            if guard:
                return StepResult(False, it, rel, inc, 1, kin, strain, grav, message=message, guard=guard)
            return StepResult(False, it, rel, inc, 1, message=message)
        self._tangent_age += 1
        accept_stretches(self.data.buf, self.data.lay, t_n, t_new, self._damped)
        # Energies and residual are those of the last evaluated iterate: the accepted q differs from
        # it by one increment ≤ tolerance (saves a residual assembly per step).
        if guarded:
            self.guard.ledger_accept(t_new)
        else:
            kin, grav = energies(m, state, self._mass_blocks)
        return StepResult(True, it, rel, inc, 1, kin, strain, grav)
