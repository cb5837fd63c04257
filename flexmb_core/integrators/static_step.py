"""One numba call per load increment of statics: Newton on ``f_int(q; λ(t)) = f_ext(t)``.

:class:`NumbaStatic` runs the Newton of a load increment of
:class:`~flexmb_core.integrators.static.StaticSolver` inside :func:`static_newton`: a full Newton
step per iteration (every element group, bars, shells, multipliers, moment loads; tangent, skyline
LU factor and solve, with static pivoting, augmentation and refinement where the factors are
suspect — near a critical point, where statics meets indefinite tangents:
:func:`~.packs.factor_packed`, :func:`~.packs.solve_packed`), the convergence test on the scaled
increment and the constraint violation, the residual at the root, and the step guard's checks of a
static root (orientation of the frame sections; the incremental potential ``Φ = U − f_ext·q`` +
moment and multiplier terms must not rise). It is the only Newton of statics: until 2026-11-29 a
Python loop, bit-identical to it, made the increments whose tangent needed SuperLU; the step
references of that time (``tests/step_cases.py``) hold it to those results.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..jit import KERNEL
from ..kernels.guard import energy_resolution, frame_orientation
from ..model.assembly import update_load_scales
from ..solvers.result import StepResult
from .energy import compact_csr, gravity_potential
from .fast import INVERTED, NO_CONVERGENCE, NON_FINITE_INCREMENT, NON_FINITE_RESIDUAL, OK, SINGULAR, SVK_LIMIT
from .packs import (F_ACT, F_EDOFS, F_GDPHI, F_GIDET, F_GILEN, F_GPHI, L_CP, L_DQ, L_DRVIDX, L_DRVVAL, L_DSCALE, L_FREE,
                    L_FVDOFS, L_GRAV, L_INVS, L_KDATA, L_MULTN, L_MVDOFS, L_PAR, L_Q0, L_QL, L_RC, L_RF, L_VEVAL,
                    L_ZLAM, N_PAR, NF, P_F0, P_KEEP, P_MAXIT, P_MINPIV, P_NFG, P_NMULT, P_PIVTOL, P_RISE, P_SVK, P_TOL,
                    ModelPacks, assemble_packed, factor_packed, moment_work_packed, singular_note, solve_packed,
                    unknown_fields, view1, view2)

RISE = 7            # the root raised the incremental potential (guard flag 'energy')

# Output slots of io.
(SO_IT, SO_REL, SO_INC, SO_STRAIN, SO_GRAV, SO_PRED, SO_X, SO_Y, SO_AUX, SO_GROUP, SO_UP, SO_OMEGA,
 N_SO) = range(13)


@njit(nogil=True, **KERNEL)
def static_newton(q, lam, mult, f_ext, r, env, inv_diag, lu_stats, wmask, cf, ci, wf, wi, lay, io, guarded):
    """Newton on the static equilibrium at the loads ``f_ext`` and stretches ``lam`` in force,
    from ``q`` (see the module). ``q (ndof,)`` and ``mult (nmult,)`` end at the root on success
    and at the increment's start otherwise (the caller's policy takes it from there). The driven
    DOFs' values come in their ``wf`` item. ``wmask (nfree,)`` 1.0 on the free positions (the
    tangent's prediction of the step measures those).

    ``io`` out (``SO_*``): iterations, relative residual at the root, last scaled increment,
    strain energy at the root, gravity energy, the first increment's norm over the positions (m),
    the guard's values (x, y: rise and size of Φ, or the section's det F / fibre stretch; aux:
    its element; its frame group), the strain energy at the Newton start and the largest backward
    error of the linear solves (:func:`~.packs.solve_packed`).

    Returns ``OK``, ``NO_CONVERGENCE``, ``NON_FINITE_RESIDUAL``, ``NON_FINITE_INCREMENT``,
    ``SINGULAR`` (a tangent that cannot be factored), ``INVERTED``, ``SVK_LIMIT`` or ``RISE``.
    """
    par = view1(cf, lay[L_PAR])
    free = view1(ci, lay[L_FREE])
    rf = view1(wf, lay[L_RF])
    dq = view1(wf, lay[L_DQ])
    kdata = view1(wf, lay[L_KDATA])
    rc = view1(wf, lay[L_RC])
    c_p = view1(wf, lay[L_CP])
    mult_n = view1(wf, lay[L_MULTN])
    q_p = view1(wf, lay[L_QL])           # the Newton start (the guard's Φ is measured from it)
    inv_scale = view1(wf, lay[L_INVS])
    zero_v = view1(wf, lay[L_VEVAL])     # statics: no rates
    zero_lam = view1(wf, lay[L_ZLAM])
    drv_idx = view1(ci, lay[L_DRVIDX])
    drv_val = view1(wf, lay[L_DRVVAL])
    tol = par[P_TOL]
    max_it = int(par[P_MAXIT])
    nmult = int(par[P_NMULT])
    nfg = int(par[P_NFG])
    f0 = int(par[P_F0])
    n = q.size
    nf = free.size
    for k in range(drv_idx.size):        # driven supports at t (apply_drives, by the caller)
        q[drv_idx[k]] = drv_val[k]
    for i in range(n):
        q_p[i] = q[i]
    for i in range(nmult):
        mult_n[i] = mult[i]
    want_k = tol >= 0.0                  # True and False from data (a literal compiles another signature)
    no_k = tol < 0.0
    no_dlam = no_k
    code = NO_CONVERGENCE
    inc = math.inf
    rel = math.inf
    u_p = 0.0
    it = 0
    predicted = -1.0
    io[SO_OMEGA] = 0.0
    for it in range(1, max_it + 1):
        strain, _ = assemble_packed(q, zero_v, lam, zero_lam, 0.0, want_k, no_dlam, mult, r, kdata, cf, ci, wf,
                                    wi, lay, par)
        if it == 1:
            u_p = strain
            for i in range(nmult):
                c_p[i] = rc[i]
        finite = True
        for k in range(nf):
            i = free[k]
            rf[k] = r[i] - f_ext[i]
            if not math.isfinite(rf[k]):
                finite = False
        viol = 0.0
        for i in range(nmult):
            rf[nf + i] = rc[i]
            if not math.isfinite(rc[i]):
                finite = False
            if abs(rc[i]) > viol:
                viol = abs(rc[i])
        if not finite:
            code = NON_FINITE_RESIDUAL
            break
        if not factor_packed(kdata, kdata, 0.0, env, inv_diag, lu_stats, nmult, wf, wi, lay, par):
            code = SINGULAR
            break
        # an inaccurate solve (a singular tangent) still gives a regularized direction (fast.py)
        omega = solve_packed(rf, dq, env, inv_diag, lu_stats, wf, wi, lay, par)
        if omega > io[SO_OMEGA]:
            io[SO_OMEGA] = omega
        finite = True
        for i in range(nf + nmult):
            if not math.isfinite(dq[i]):
                finite = False
        if not finite:
            code = NON_FINITE_INCREMENT
            break
        if it == 1:                      # the tangent's prediction of the whole step
            s = 0.0
            for k in range(nf):
                s += wmask[k] * dq[k] * dq[k]
            predicted = math.sqrt(s)
        inc = 0.0
        for k in range(nf):
            q[free[k]] -= dq[k]
            x = abs(dq[k]) * inv_scale[k]
            if x > inc:
                inc = x
        for i in range(nmult):
            mult[i] -= dq[nf + i]
        nr = 0.0                         # the residual solved, against the forces of that iterate
        ni = 0.0
        ne = 0.0
        for k in range(nf):
            i = free[k]
            nr += rf[k] * rf[k]
            ni += r[i] * r[i]
            ne += f_ext[i] * f_ext[i]
        rel = math.sqrt(nr) / max(math.sqrt(ni), math.sqrt(ne), 1e-300)
        if inc <= tol and viol <= tol:
            code = OK
            break
    io[SO_IT] = it
    io[SO_INC] = inc
    io[SO_REL] = rel
    io[SO_PRED] = predicted
    if code != OK:
        if par[P_KEEP] == 0.0:                       # accept_flagged keeps the iterate
            for i in range(n):
                q[i] = q_p[i]
            for i in range(nmult):
                mult[i] = mult_n[i]
        return code
    strain, _ = assemble_packed(q, zero_v, lam, zero_lam, 0.0, no_k, no_dlam, mult, r, kdata, cf, ci, wf, wi, lay,
                                par)
    nr = 0.0
    ni = 0.0
    ne = 0.0
    for k in range(nf):
        i = free[k]
        x = r[i] - f_ext[i]
        nr += x * x
        ni += r[i] * r[i]
        ne += f_ext[i] * f_ext[i]
    rel = math.sqrt(nr) / max(math.sqrt(ni), math.sqrt(ne), 1e-300)
    grav = gravity_potential(q, view1(cf, lay[L_Q0]), view1(cf, lay[L_GRAV]))
    io[SO_REL] = rel
    io[SO_STRAIN] = strain
    io[SO_GRAV] = grav
    io[SO_UP] = u_p
    if not guarded:
        return OK
    for k in range(nfg):                 # check 1: orientation and the SVK limit point
        b = f0 + k * NF
        jmin, smin, emin = frame_orientation(q, view2(ci, lay[b + F_EDOFS]), view1(ci, lay[b + F_ACT]), lam,
                                             view2(wf, lay[b + F_GPHI]), view2(wf, lay[b + F_GDPHI]),
                                             view2(wf, lay[b + F_GIDET]), view2(wf, lay[b + F_GILEN]))
        if jmin <= 0.0:
            io[SO_X] = jmin
            io[SO_AUX] = emin
            io[SO_GROUP] = k
            return INVERTED
        if smin < par[P_SVK]:
            io[SO_X] = smin
            return SVK_LIMIT
    w_ext = 0.0                          # check 2: Φ(q) ≤ Φ(q_p) beyond the energy resolution
    for i in range(n):
        w_ext += f_ext[i] * (q[i] - q_p[i])
    w_mom = 0.0
    if view2(ci, lay[L_FVDOFS]).shape[0] or view2(ci, lay[L_MVDOFS]).shape[0]:
        w_mom = moment_work_packed(q, q_p, no_k, cf, ci, wf, lay)
    w_mult = 0.0
    for i in range(nmult):
        w_mult += mult[i] * (rc[i] - c_p[i])
    rise = (strain - u_p) + (0.0 + (-w_ext) + (-w_mom) + w_mult)
    size = abs(strain) + abs(u_p) + (0.0 + abs(w_ext) + abs(w_mom) + abs(w_mult))
    floor = energy_resolution(free, view1(cf, lay[L_DSCALE]), tol, r, f_ext)
    io[SO_X] = rise
    io[SO_Y] = size
    if rise > par[P_RISE] * size and rise > floor:
        return RISE
    return OK


class NumbaStatic:
    """The numba Newton of :func:`static_newton`, bound to one :class:`StaticSolver`'s model,
    workspace, solver and guard."""

    @staticmethod
    def unsupported(model) -> str:
        """'' when :func:`static_newton` covers this model, else what it lacks."""
        unknown = unknown_fields(model)
        return f"model features this step does not know: {', '.join(unknown)}" if unknown else ""

    def __init__(self, solver):
        m, ws = solver.model, solver.ws
        self.solver = solver
        self.model = m
        sky = solver.lu.skyline
        guard = solver.guard
        par = np.zeros(N_PAR)
        par[P_TOL], par[P_MAXIT] = solver.spec.tolerance, solver.spec.max_iterations
        par[P_SVK], par[P_RISE] = SVK_LIMIT_STRETCH, guard.rise_tolerance
        par[P_PIVTOL], par[P_MINPIV] = sky.pivot_tol, solver.lu.min_pivot_ratio
        par[P_KEEP] = solver.spec.on_unconverged == "accept_flagged"
        mass = compact_csr(*m.mass_csr)          # statics: no inertia, the block form unused
        self.packs = ModelPacks(m, ws, sky, guard, solver._inv_scale, mass, (1, *mass), par)
        self._wmask = np.ascontiguousarray(solver._w, dtype=np.float64)
        self._io = np.zeros(N_SO)

    def solve(self, state, t: float, lam: np.ndarray) -> StepResult:
        """The equilibrium at pseudo-time ``t`` from ``state.q`` (loads, stretches and drives at
        ``t``); on failure ``state`` is as it was (under ``accept_flagged``: at the last
        iterate)."""
        solver, m, ws, p = self.solver, self.model, self.solver.ws, self.packs
        state.lam[:] = lam
        state.t = t
        update_load_scales(m, ws, t)
        p.follower_scale[:] = ws.follower_scale
        p.cons_scale[:] = ws.cons_scale
        p.drives(state.q, t)
        sky = solver.lu.skyline
        cf, ci, wf, wi = p.packs
        guard = solver.guard
        code = static_newton(state.q, state.lam, state.mult, ws.f_ext, ws.r, sky._env, sky._inv_diag, sky._stats,
                             self._wmask, cf, ci, wf, wi, p.lay, self._io, guard.enabled)
        io = self._io
        it, inc, rel = int(io[SO_IT]), io[SO_INC], io[SO_REL]
        if solver._predicted < 0.0 and io[SO_PRED] >= 0.0:     # the first increment of the load step
            solver._predicted = io[SO_PRED]
        strain, grav = io[SO_STRAIN], io[SO_GRAV]
        if code == OK:
            return StepResult(True, it, rel, inc, 1, 0.0, strain, grav)
        note = singular_note(io[SO_OMEGA])
        if code == NO_CONVERGENCE:
            return StepResult(False, it, rel, inc, 1,
                              message=f"no convergence in {solver.spec.max_iterations} iterations (increment {inc:.2e})"
                                      f"{note}")
        if code == NON_FINITE_RESIDUAL:
            return StepResult(False, it, rel, inc, 1, message=f"non-finite residual at iteration {it}{note}")
        if code == NON_FINITE_INCREMENT:
            return StepResult(False, it, rel, inc, 1, message=f"non-finite increment at iteration {it}{note}")
        if code == SINGULAR:
            return StepResult(False, it, rel, inc, 1,
                              message=f"singular tangent at iteration {it} (a non-finite pivot, or a zero matrix)")
        guard.rejections += 1
        if code == INVERTED:
            group = m.frame_groups[int(io[SO_GROUP])]
            member = m.members[int(group.member[int(io[SO_AUX])])].name
            flag, why = "inverted", (f"step guard: inverted frame section (det F = {io[SO_X]:.3g} ≤ 0 in member "
                                     f"'{member}'), a reflection Green–Lagrange strain cannot see")
        elif code == SVK_LIMIT:
            flag, why = "svk_limit", (f"step guard: fibre stretch {io[SO_X]:.3g} below 1/√3, the compressive limit "
                                      "point of the Saint-Venant–Kirchhoff law")
        else:
            flag, why = "energy", (f"step guard: spurious Newton root — the step's incremental potential rose by "
                                   f"{io[SO_X]:.3g} J (strain energy {io[SO_UP]:.4g} → {strain:.4g} J); a physical "
                                   "root lowers it")
        return StepResult(False, it, rel, inc, 1, 0.0, strain, grav, message=why, guard=flag)


from ..solvers.guard import SVK_LIMIT_STRETCH  # noqa: E402  (after the kernel: no import cycle at compile)
