"""The step guard: physical acceptance checks of a converged Newton root.

Newton's convergence test says the residual vanishes, not that the root is the physical one. A
step can converge onto a spurious root — the beam folded onto itself (Green–Lagrange strain is
blind to reflections), or a state with millions of joules of strain energy that no force
supplied. Three checks, from quantities the step has already computed, refuse such roots; the
refusal is an ordinary failed step, so the ``on_unconverged`` policy (sub-steps, stop, or accept
and flag) decides what happens next, and the reason stays in ``StepResult.message`` and
``StepResult.guard``.

1. **Orientation and the SVK limit point** (frame elements), at the section centroid of every
   axial station and node of every element: ``det F > 0`` (no section turned inside out), and
   every fibre stretch (axis, V1, V2) above ``1/√3``, where Saint-Venant–Kirchhoff's uniaxial
   stress ``E(λ³ − λ)/2`` peaks — below it the material law is unstable and a root there is an
   artefact of the model. Flags ``'inverted'``, ``'svk_limit'``.
2. **The incremental potential must not rise** (flag ``'energy'``). With ``λ(t_{n+1})``, the
   drives and the loads frozen, a step's equations are the stationarity of
   ``Φ(q) = U(q) − f_ext·q + ∫ M(a(q) + c_m v(q))·dq`` (+ moment, viscous and multiplier terms),
   ``a(q), v(q)`` the integrator's affine maps (statics: no inertia). The physical root is the
   minimizer reached from the Newton start ``q_p`` (the predictor, or the previous equilibrium):
   ``Φ(q) ≤ Φ(q_p)``. Actuator and drive work need no bookkeeping here (both are frozen in
   ``Φ``). ``U(q_p)`` is the strain energy of the first Newton iteration and ``U`` of the last,
   so ``Φ`` is compared between those two evaluated points with one mass mat-vec (a
   tolerance-sized increment times the loads can outweigh a stiff mechanism's whole strain
   energy, so the accepted ``q`` would not do). Conservative moments enter exactly, follower
   moments, Kelvin–Voigt forces and multipliers by the trapezoidal rule.
3. **The energy balance of the step** (dynamics, steps in which no actuator length changes; flag
   ``'energy'``): ``Δ(K + U) ≤ W_loads + W_drives + W_moments`` — kinetic plus strain energy
   can only grow by the work of the loads (gravity included) and of the driven supports (their
   reactions times their prescribed motion, trapezoidal rule); damping and the integrator's
   numerical dissipation only lower it. Check 2 is only as sharp as the predictor; this one does
   not depend on it (a tumbling beam whose high modes have polluted the accelerations has a
   predictor with 10⁵× the step's energy). A commanded actuator does work ``∂U/∂λ·Δλ`` that the
   step does not evaluate, so actuated steps rely on check 2, whose ``Φ`` holds ``λ_{n+1}`` at
   both ends.

Tolerances. Check 2 refuses a rise above ``rise_tolerance`` (1 %) of the size of ``Φ``'s terms,
check 3 a gain above ``balance_tolerance`` (50 %) of the energy present plus the work done; both
only beyond the energy resolution of a converged state, ``Σ tol·scale_i (|f_int,i| + |f_ext,i|) +
c_v tol √(c_M 2K)``, ``c_M = Σ|M_ij| s_i s_j``. Over the test suite and the reference bags no
physical root raises ``Φ`` beyond that resolution; the largest balance gain of a physical step is
6 % (the boom ringing after a 5 mm command step, generalized-α: not a Lyapunov function step by
step on a nonlinear problem), 0.6 % elsewhere; the spurious roots gain 65× (spin-up) to 3000×
(tumbling beam) — the tolerances sit an order of magnitude from both.

Cost: per step one call of :func:`flexmb_core.kernels.guard.frame_orientation` per frame group
and one of :func:`flexmb_core.kernels.guard.dynamic_guard` (a few passes over the unknowns, mass
rows of the driven DOFs only); no assembly, no mat-vec.

The checks run inside the numba steps (:func:`flexmb_core.integrators.fast.model_step`,
:func:`flexmb_core.integrators.static_step.static_newton`); :class:`StepGuard` holds what they need
(the frame stations, the energy ledger of dynamics), formats their refusals, and checks a state's
orientation from Python (:meth:`StepGuard.orientation`).
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels.guard import drive_reactions, frame_orientation
from ..model.model import Model
from ..model.shape import gauss_legendre, lagrange_1d
from ..model.step_data import drive_dof_ids

#: Lowest fibre stretch accepted: the compressive limit point of Saint-Venant–Kirchhoff.
SVK_LIMIT_STRETCH = 1.0 / math.sqrt(3.0)


class StepGuard:
    """Acceptance checks of converged Newton roots for one model (buffers allocated once).

    Parameters
    ----------
    model : Model
    tolerance : float — the Newton tolerance (scaled increment): sets the energy resolution of a
        converged state, below which checks 2 and 3 do not judge.
    rise_tolerance : float — relative rise of the incremental potential that is refused.
    balance_tolerance : float — relative energy gain (beyond the work done) that is refused.
    enabled : bool — False turns every check off (diagnostics only: spurious roots get through).
    ledger : (gvec (6, ndof), react (2, nd), led (5,)) — where the energy ledger of dynamics lives:
        the items of the run's :class:`~flexmb_core.model.step_data.StepData`, so that it rolls
        back with the state (default: arrays of its own, for statics).

    Attributes
    ----------
    rejections : int — roots refused so far.
    """

    def __init__(self, model: Model, *, tolerance: float = 1e-9, rise_tolerance: float = 1e-2,
                 balance_tolerance: float = 0.5, enabled: bool = True,
                 ledger: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None):
        self.model = model
        self.tolerance = tolerance
        self.rise_tolerance = rise_tolerance
        self.balance_tolerance = balance_tolerance
        self.enabled = enabled
        self.rejections = 0
        n = model.ndof
        self._stations = [self._frame_stations(model, g) for g in model.frame_groups]
        # Energy ledger of dynamics: the last accepted state (t, q, v), its K + U, its loads and
        # drive reactions. ``_gvec`` rows: two sets (f, q, v) — the ledger's at ``_il``, the
        # candidate end state of the step under way at 3 − ``_il`` — then the last Newton
        # iterate and scratch; ``_react`` rows: ledger ``_ir``, candidate 1 − ``_ir``. An
        # accepted step flips the indices (no copies).
        self._drive_ids = drive_dof_ids(model)
        nd = self._drive_ids.size
        if ledger is None:
            ledger = (np.zeros((6, n)), np.zeros((2, nd)), np.array([0.0, 0.0, math.nan, 0.0, 0.0]))
        # [il, ir, t, K + U, candidate K + U]: an array that the numba step reads and writes
        self._gvec, self._react, self._led = ledger
        self._saved = (math.nan, 0.0)
        self._saved_rows = np.zeros((3, n))
        self._saved_react = np.zeros(nd)
        # Σ_ij |M_ij| s_i s_j over the free DOFs: the kinetic energy of a state known to within
        # tol·s moves by at most c_v·tol·√(c_mass·2K) (Cauchy–Schwarz in the mass norm).
        mi, mj, mv = model.mass_csr
        rows = np.repeat(np.arange(n), np.diff(mi))
        keep = (model.free_index[rows] >= 0) & (model.free_index[mj] >= 0)
        self._c_mass = float(np.sum(np.abs(mv[keep]) * model.dof_scale[rows[keep]] * model.dof_scale[mj[keep]]))

    @staticmethod
    def _frame_stations(model: Model, g) -> tuple[np.ndarray, ...]:
        """Shape functions at the axial Gauss stations and the nodes; 1/det A⁰ and 1/|X'| there."""
        n = g.order + 1
        n_axial = g.w.shape[1] // g.nsec
        xi = np.concatenate((gauss_legendre(n_axial)[0], np.linspace(-1.0, 1.0, n)))
        phi, dphi = lagrange_1d(g.order, xi)
        q0 = model.q0[g.edofs].reshape(g.n_elements, n, 3, 3)       # (ne, node, [Y, V1, V2], xyz)
        xp = np.einsum("sa,eai->esi", dphi, q0[:, :, 0])             # (ne, ns, 3) X'
        v1 = np.einsum("sa,eai->esi", phi, q0[:, :, 1])
        v2 = np.einsum("sa,eai->esi", phi, q0[:, :, 2])
        det0 = np.einsum("esi,esi->es", xp, np.cross(v1, v2))
        return (np.ascontiguousarray(phi), np.ascontiguousarray(dphi), np.ascontiguousarray(1.0 / det0),
                np.ascontiguousarray(1.0 / np.linalg.norm(xp, axis=2)))

    # ledger scalars (views of _led)
    @property
    def _il(self) -> int:
        return int(self._led[0])

    @property
    def _ir(self) -> int:
        return int(self._led[1])

    @property
    def _t(self) -> float:
        return float(self._led[2])

    @property
    def _e(self) -> float:
        return float(self._led[3])

    # -- check 1 -------------------------------------------------------------------------------
    def orientation(self, q: np.ndarray, lam: np.ndarray) -> tuple[str, str]:
        """``('', '')`` or (flag, why): the configuration is not a physical one — an
        ``'inverted'`` section or a fibre stretch below the SVK limit point (``'svk_limit'``)."""
        for g, (phi, dphi, inv_det0, inv_len0) in zip(self.model.frame_groups, self._stations):
            jmin, smin, e = frame_orientation(q, g.edofs, g.act, lam, phi, dphi, inv_det0, inv_len0)
            if jmin <= 0.0:
                member = self.model.members[int(g.member[e])].name
                return "inverted", (f"step guard: inverted frame section (det F = {jmin:.3g} ≤ 0 in member "
                                    f"'{member}'), a reflection Green–Lagrange strain cannot see")
            if smin < SVK_LIMIT_STRETCH:
                return "svk_limit", (f"step guard: fibre stretch {smin:.3g} below 1/√3, the compressive limit "
                                     "point of the Saint-Venant–Kirchhoff law")
        return "", ""

    def energy_message(self, code: int, x: float, y: float, e_end: float, u_p: float, u_last: float) -> str:
        """The reason of a refusal by :func:`~flexmb_core.kernels.guard.dynamic_guard` (code 1:
        ``x, y`` = rise and size of Φ; code 2: gain and scale of the balance)."""
        if code == 1:
            return (f"step guard: spurious Newton root — the step's incremental potential rose by {x:.3g} J "
                    f"(strain energy {u_p:.4g} → {u_last:.4g} J); a physical root lowers it")
        return (f"step guard: spurious Newton root — kinetic + strain energy {self._e:.4g} → {e_end:.4g} J "
                f"against {e_end - self._e - x:.3g} J of work done by loads and drives in the step")

    # -- the energy ledger of dynamics -----------------------------------------------------------
    def ledger_start(self, t: float, kinetic: float, strain: float, f_ext: np.ndarray, r_int: np.ndarray,
                     q: np.ndarray, a: np.ndarray, v: np.ndarray) -> None:
        """Record the initial state at ``t`` (energies, loads, drive reactions)."""
        m, il = self.model, self._il
        self._led[2] = t
        self._led[3] = kinetic + strain
        self._gvec[il] = f_ext
        self._gvec[il + 1] = q
        self._gvec[il + 2] = v
        drive_reactions(r_int, a, v, m.mass_damping, *m.mass_csr, f_ext, self._drive_ids, self._react[self._ir])

    def ledger_save(self) -> None:
        """Keep the ledger of the step's start (sub-steps and roll-backs restore it)."""
        il = self._il
        self._saved_rows[:] = self._gvec[il:il + 3]
        self._saved_react[:] = self._react[self._ir]
        self._saved = (self._t, self._e)

    def ledger_restore(self) -> None:
        il = self._il
        self._gvec[il:il + 3] = self._saved_rows
        self._react[self._ir] = self._saved_react
        self._led[2], self._led[3] = self._saved
