"""One numba call per time step: the Newton attempt of a dynamic step, for every element kind.

:class:`NumbaStep` runs the first Newton attempt of a step of
:class:`~flexmb_core.integrators.dynamic.DynamicIntegrator` entirely inside :func:`model_step`:
predictor and driven supports, the residual and (held or refreshed) tangent of every frame group,
the bars, every shell group, the multiplier constraints (rigid corners, off-plane hinges, director
ties) and the moment loads, the inertial residual, the skyline LU factor and solve, the
modified-Newton refresh rule, the rates, the energies and the step guard's checks. It calls the
very kernels the Python path calls, in the same order, so the states it produces are bit-identical
to it (``tests/unit/test_fast_step.py``); it only removes the Python between them.

Not covered (:meth:`NumbaStep.unsupported` names it and the integrator keeps its Python path):
the Chung–Hulbert integrator (kept to show it is not objective). A step the kernel cannot finish —
no convergence, a refused root — leaves the state as it was (under ``accept_flagged``: at the last
iterate, as the Python path leaves it) and hands back to the integrator, whose ``on_unconverged``
policy proceeds as for any failed attempt; its sub-steps are numba steps too. A pivot the skyline
LU must not take hands the attempt to the Python path, which pivots with SuperLU.

Arguments. A step needs about 150 arrays, and every array argument of a numba call costs
dispatch time (≈ 0.1 µs), so they travel in four flat packs — read-only floats ``cf`` and ints
``ci`` (model arrays, read-only like the model's so that the kernels called inside keep their one
compiled signature), writable floats ``wf`` and ints ``wi`` (scratch, the skyline structure) —
with a layout table ``lay``: row ``[offset, d0, d1, d2, d3, size]`` per item. Items of the whole
model are rows ``L_*``; frame group ``k`` has rows ``F0 + k·NF + F_*`` and shell group ``k`` rows
``S0 + k·NS + S_*`` (``F0, S0`` and the group counts in the step constants).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit
from numba.extending import register_jitable

from ..kernels.constraints import director_tie_group, hinge_group, rigid_corner_group
from ..kernels.frame3d import frame_group, frame_scratch, frame_structure
from ..kernels.guard import conservative_moment_work, dynamic_guard, frame_orientation
from ..kernels.moments import conservative_moments, follower_moments
from ..kernels.shell import shell_group, shell_scratch
from ..kernels.truss import truss_group
from ..model.assembly import apply_drives
from ..model.model import Model, TrussGroup
from ..scene.schema import SolverSpec
from ..signals import evaluate
from ..solvers.banded import _factor_kernel, _solve_kernel
from ..solvers.result import StepResult
from .energy import _energies
from .fused import apply_increment, inertial_residual, update_rates, velocity_at

# Return codes of model_step.
OK, NO_CONVERGENCE, NON_FINITE_RESIDUAL, NON_FINITE_INCREMENT, PIVOT, INVERTED, SVK_LIMIT, ENERGY = range(8)

# Items of the whole model (rows of the layout table).
(L_DSCALE, L_Q0, L_GRAV, L_PAR, L_MV, L_TL0, L_TEA, L_TTAU, L_CALPHA, L_HALPHA, L_HBETA, L_TIEALPHA,
 L_FMBODY, L_CAXES, L_CMAG,                                                                   # cf
 L_FREE, L_MI, L_MJ, L_TEDOFS, L_TACT, L_TSMAP, L_CDOFS, L_CSMAP, L_HDOFS, L_HSMAP, L_TIEDOFS, L_TIESMAP,
 L_FVDOFS, L_FSMAP, L_MVDOFS, L_MSMAP, L_DRVIDX,                                              # ci
 L_INVS, L_MASSK, L_VEVAL, L_WBUF, L_RF, L_DQ, L_KDATA, L_IVEC, L_LUWORK, L_TQE, L_TVE, L_TRE, L_TKE,
 L_SDV, L_SDFA, L_SF, L_SBMAT, L_SCB, L_SQE, L_SRE, L_SKE, L_CKE, L_HKE, L_TIEKE, L_RC, L_CP, L_MULTN,
 L_FSCALE, L_MSCALE, L_RM, L_QL, L_KDUMMY, L_DRVVAL,                                          # wf
 L_SLOT, L_ZSLOT, L_BASE, L_LRP, L_LRL, L_LRH, L_URP, L_URL, L_URH, L_BLK, L_PERM, L_DRIVE,   # wi
 N_ITEMS) = range(78)
# Items of one frame group (rows F0 + k·NF + item).
(F_DAX, F_DSEC, F_W, F_MAT,                                                                   # cf
 F_EDOFS, F_ACT, F_SMAP, F_NSEC,                                                              # ci
 F_PHIST, F_DPHIST, F_SPT, F_HACC, F_GACC, F_TK, F_TG, F_D, F_FP, F_FD, F_EP, F_ED, F_BMAT, F_BDOT, F_GBAR,
 F_GDOT, F_QE, F_VE, F_RE, F_KE, F_KN, F_GPHI, F_GDPHI, F_GIDET, F_GILEN,                     # wf
 F_STRAIGHT, F_BLOCKS,                                                                        # wi
 NF) = range(36)
# Items of one shell group (rows S0 + k·NS + item).
S_PHI, S_DPHI, S_ZETA, S_A0INV, S_W, S_MAT, S_EDOFS, S_SMAP, NS = range(9)
# Step constants in the L_PAR block of cf.
(P_AM, P_AF, P_BETA, P_GAMMA, P_CM, P_TOL, P_MAXIT, P_MODIFIED, P_CONTRACTION, P_MAXAGE, P_SVK, P_RISE, P_BAL,
 P_CMASS, P_PIVTOL, P_MINPIV, P_ACCUM, P_DAMPED, P_NFG, P_NSG, P_F0, P_S0, P_NMULT, P_KEEP, N_PAR) = range(25)
# Output slots of io.
(IO_IT, IO_REL, IO_INC, IO_STRAIN, IO_KIN, IO_GRAV, IO_X, IO_Y, IO_EEND, IO_AUX, IO_UP, IO_DISS, IO_GROUP,
 N_IO) = range(14)


# Views of a pack (register_jitable: inlined into the caller, so that a view of a read-only and
# of a writable pack are not two signatures of one dispatcher).
@register_jitable
def _v1(p, row):
    return p[row[0]:row[0] + row[5]]


@register_jitable
def _v2(p, row):
    return p[row[0]:row[0] + row[5]].reshape((row[1], row[2]))


@register_jitable
def _v3(p, row):
    return p[row[0]:row[0] + row[5]].reshape((row[1], row[2], row[3]))


@register_jitable
def _v4(p, row):
    return p[row[0]:row[0] + row[5]].reshape((row[1], row[2], row[3], row[4]))


@njit(cache=True, nogil=True)
def _assemble(q, v_k, lam, lam_rate, c_vk, refresh, no_dlam, mult, r, kdata, cf, ci, wf, wi, lay, par):
    """Internal forces (+ multiplier forces, − moment loads) into ``r`` and their tangent into
    ``kdata`` when ``refresh``, in :func:`flexmb_core.model.assembly.assemble`'s order (the sums
    bit-identical); the violations into the ``L_RC`` item. Returns (strain energy, dissipation)."""
    for i in range(r.size):
        r[i] = 0.0
    if refresh:
        for i in range(kdata.size):
            kdata[i] = 0.0
    strain = 0.0
    diss = 0.0
    f0 = int(par[P_F0])
    for k in range(int(par[P_NFG])):
        b = f0 + k * NF
        u, dp = frame_group(q, v_k, _v2(ci, lay[b + F_EDOFS]), _v4(cf, lay[b + F_DAX]), _v4(cf, lay[b + F_DSEC]),
                            _v2(cf, lay[b + F_W]), ci[lay[b + F_NSEC, 0]], _v2(cf, lay[b + F_MAT]),
                            _v1(ci, lay[b + F_ACT]), lam, lam_rate, c_vk, _v2(ci, lay[b + F_SMAP]), refresh, no_dlam,
                            r, kdata, _v3(wf, lay[b + F_D]), _v3(wf, lay[b + F_FP]), _v3(wf, lay[b + F_FD]),
                            _v2(wf, lay[b + F_EP]), _v2(wf, lay[b + F_ED]), _v2(wf, lay[b + F_BMAT]),
                            _v2(wf, lay[b + F_BDOT]), _v2(wf, lay[b + F_GBAR]), _v2(wf, lay[b + F_GDOT]),
                            _v1(wf, lay[b + F_QE]), _v1(wf, lay[b + F_VE]), _v1(wf, lay[b + F_RE]),
                            _v2(wf, lay[b + F_KE]), _v2(wf, lay[b + F_KN]), _v1(wi, lay[b + F_STRAIGHT]),
                            _v3(wf, lay[b + F_PHIST]), _v3(wf, lay[b + F_DPHIST]), _v3(wf, lay[b + F_SPT]),
                            _v3(wi, lay[b + F_BLOCKS]), _v3(wf, lay[b + F_HACC]), _v1(wf, lay[b + F_GACC]),
                            _v4(wf, lay[b + F_TK]), _v2(wf, lay[b + F_TG]))
        strain += u
        diss += dp
    t_edofs = _v2(ci, lay[L_TEDOFS])
    if t_edofs.shape[0]:
        u, dp = truss_group(q, v_k, t_edofs, _v1(cf, lay[L_TL0]), _v1(cf, lay[L_TEA]), _v1(cf, lay[L_TTAU]),
                            _v1(ci, lay[L_TACT]), lam, lam_rate, c_vk, _v2(ci, lay[L_TSMAP]), refresh, r, kdata,
                            _v1(wf, lay[L_TQE]), _v1(wf, lay[L_TVE]), _v1(wf, lay[L_TRE]), _v2(wf, lay[L_TKE]))
        strain += u
        diss += dp
    s0 = int(par[P_S0])
    for k in range(int(par[P_NSG])):
        b = s0 + k * NS
        strain += shell_group(q, _v2(ci, lay[b + S_EDOFS]), _v2(cf, lay[b + S_PHI]), _v3(cf, lay[b + S_DPHI]),
                              _v1(cf, lay[b + S_ZETA]), _v4(cf, lay[b + S_A0INV]), _v2(cf, lay[b + S_W]),
                              _v2(cf, lay[b + S_MAT]), _v2(ci, lay[b + S_SMAP]), refresh, r, kdata,
                              _v2(wf, lay[L_SDV]), _v3(wf, lay[L_SDFA]), _v2(wf, lay[L_SF]), _v2(wf, lay[L_SBMAT]),
                              _v2(wf, lay[L_SCB]), _v1(wf, lay[L_SQE]), _v1(wf, lay[L_SRE]), _v2(wf, lay[L_SKE]))
    rc = _v1(wf, lay[L_RC])
    c_dofs = _v2(ci, lay[L_CDOFS])
    h_dofs = _v2(ci, lay[L_HDOFS])
    tie_dofs = _v2(ci, lay[L_TIEDOFS])
    nc = c_dofs.shape[0]
    if nc:
        rigid_corner_group(q, mult, c_dofs, _v3(cf, lay[L_CALPHA]), _v2(ci, lay[L_CSMAP]), refresh, r, rc, kdata,
                           _v2(wf, lay[L_CKE]))
    if h_dofs.shape[0]:
        hinge_group(q, mult, 6 * nc, h_dofs, _v2(cf, lay[L_HALPHA]), _v3(cf, lay[L_HBETA]), _v2(ci, lay[L_HSMAP]),
                    refresh, r, rc, kdata, _v2(wf, lay[L_HKE]))
    if tie_dofs.shape[0]:
        director_tie_group(q, mult, 6 * nc + 2 * h_dofs.shape[0], tie_dofs, _v2(cf, lay[L_TIEALPHA]),
                           _v2(ci, lay[L_TIESMAP]), refresh, r, rc, kdata, _v2(wf, lay[L_TIEKE]))
    f_vdofs = _v2(ci, lay[L_FVDOFS])
    if f_vdofs.shape[0]:
        follower_moments(q, f_vdofs, _v2(cf, lay[L_FMBODY]), _v1(wf, lay[L_FSCALE]), _v2(ci, lay[L_FSMAP]), refresh,
                         r, kdata)
    m_vdofs = _v2(ci, lay[L_MVDOFS])
    if m_vdofs.shape[0]:
        conservative_moments(q, m_vdofs, _v3(cf, lay[L_CAXES]), _v1(cf, lay[L_CMAG]), _v1(wf, lay[L_MSCALE]),
                             _v2(ci, lay[L_MSMAP]), refresh, r, kdata)
    return strain, diss


@njit(cache=True, nogil=True)
def _moment_work(q, q_p, no_k, cf, ci, wf, lay):
    """Work of the moment loads from ``q_p`` to ``q`` (J), as
    :meth:`~flexmb_core.solvers.guard.StepGuard.moment_work` forms it (its follower part sums
    ``r·(q_p − q)`` in a loop where numpy's dot sums pairwise: the last bits of a guard value
    may differ, never a state)."""
    w = 0.0
    m_vdofs = _v2(ci, lay[L_MVDOFS])
    if m_vdofs.shape[0]:
        w += conservative_moment_work(q, q_p, m_vdofs, _v3(cf, lay[L_CAXES]), _v1(cf, lay[L_CMAG]),
                                      _v1(wf, lay[L_MSCALE]))
    f_vdofs = _v2(ci, lay[L_FVDOFS])
    if f_vdofs.shape[0]:
        rm = _v1(wf, lay[L_RM])
        for i in range(rm.size):
            rm[i] = 0.0
        for x in (q_p, q):
            follower_moments(x, f_vdofs, _v2(cf, lay[L_FMBODY]), _v1(wf, lay[L_FSCALE]), _v2(ci, lay[L_FSMAP]),
                             no_k, rm, _v1(wf, lay[L_KDUMMY]))
        s = 0.0
        for i in range(rm.size):
            s += rm[i] * (q_p[i] - q[i])
        w += 0.5 * s
    return w


@njit(cache=True, nogil=True)
def model_step(q, v, a, atil, lam, lam_rate, mult, f_ext, r, env, inv_diag, lu_stats, gvec, react, cf, ci, wf, wi,
               lay, tan, led, io, t_n, dt, guarded, balance):
    """First Newton attempt of one dynamic step (see the module).

    State ``q, v, a, atil (ndof,)`` and the multipliers ``mult (nmult,)`` are advanced in place on
    success and left unchanged otherwise. ``lam, lam_rate (na,)``: the actuator stretches
    λ_{n+1} and their rates (1/s, read by damped elements only), set by the caller. ``balance``:
    the step moves no actuator, so the guard's energy balance (check 3) applies. The GIL is
    released: a caller's other threads (the node's executor) run while the step does. Shared
    with the Python path: ``f_ext`` (loads at t_{n+1}, set by the caller), ``r`` (internal
    force of the last evaluation), the skyline factors ``env, inv_diag, lu_stats`` (the held
    tangent) and the step guard's ledger rows ``gvec, react``. Everything else comes in the
    packs ``cf, ci, wf, wi`` and their layout table ``lay`` (see the module); the caller writes
    the driven supports' values at t_{n+1} and the moment scales into their ``wf`` items.

    ``tan`` in/out: the integrator's held tangent [held, coefficient, age, refreshes]; ``led``
    in/out: the guard's ledger [il, ir, t, K + U, candidate K + U] (advanced here when the step is
    accepted); ``t_n, dt``: the step; ``guarded``: run the step guard. ``io`` out (``IO_*``):
    iterations, relative residual, increment, strain, kinetic and gravity energy, the guard's
    values (x, y, e_end, aux: element of an inverted section or the energy check's code, and the
    frame group of that section) and the strain energy at the Newton start.

    Returns one of the codes ``OK, NO_CONVERGENCE, …, ENERGY``.
    """
    par = _v1(cf, lay[L_PAR])
    free = _v1(ci, lay[L_FREE])
    m_indptr = _v1(ci, lay[L_MI])
    m_indices = _v1(ci, lay[L_MJ])
    m_data = _v1(cf, lay[L_MV])
    ivec = _v2(wf, lay[L_IVEC])
    rf = _v1(wf, lay[L_RF])
    dq = _v1(wf, lay[L_DQ])
    kdata = _v1(wf, lay[L_KDATA])
    rc = _v1(wf, lay[L_RC])
    c_p = _v1(wf, lay[L_CP])
    mult_n = _v1(wf, lay[L_MULTN])
    inv_scale = _v1(wf, lay[L_INVS])
    v_eval = _v1(wf, lay[L_VEVAL])
    drv_idx = _v1(ci, lay[L_DRVIDX])
    drv_val = _v1(wf, lay[L_DRVVAL])
    am = par[P_AM]
    af = par[P_AF]
    beta = par[P_BETA]
    gamma = par[P_GAMMA]
    c_m = par[P_CM]
    tol = par[P_TOL]
    max_it = int(par[P_MAXIT])
    modified = par[P_MODIFIED] != 0.0
    contraction = par[P_CONTRACTION]
    max_age = int(par[P_MAXAGE])
    accumulate = par[P_ACCUM] != 0.0
    pivot_tol = par[P_PIVTOL]
    min_pivot_ratio = par[P_MINPIV]
    damped = par[P_DAMPED] != 0.0
    nmult = int(par[P_NMULT])
    nfg = int(par[P_NFG])
    f0 = int(par[P_F0])

    # -- predictor (Python path: DynamicIntegrator._newton) -------------------------------------
    n = q.size
    nf = free.size
    q_n = ivec[0]
    v_n = ivec[1]
    a_n = ivec[2]
    at_n = ivec[3]
    q_hat = ivec[4]
    q_p = ivec[5]
    g_p = ivec[6]
    c_tilde = 1.0 / (beta * dt * dt)
    c_a = (1.0 - am) / ((1.0 - af) * beta * dt * dt)
    c_v = gamma / (beta * dt)
    c_pred = (0.5 - beta) * dt * dt
    c_bdt = beta * dt * dt
    for i in range(n):
        q_n[i] = q[i]
        v_n[i] = v[i]
        a_n[i] = a[i]
        at_n[i] = atil[i]
        h = at_n[i] * c_pred
        h += q_n[i]
        h += dt * v_n[i]
        q_hat[i] = h
    for i in range(nmult):
        mult_n[i] = mult[i]
    for k in range(nf):
        i = free[k]
        q[i] = q_hat[i] + c_bdt * at_n[i]
    for k in range(drv_idx.size):       # driven supports at t_{n+1} (apply_drives, by the caller)
        q[drv_idx[k]] = drv_val[k]
    for i in range(n):
        q_p[i] = q[i]
    coef = c_a + c_m * c_v
    held = tan[0] != 0.0
    refresh = (not modified) or (not held) or tan[1] != coef or tan[2] >= max_age
    prev_inc = math.inf
    inc = math.inf
    rel = math.inf
    strain = 0.0
    u_p = 0.0
    code = NO_CONVERGENCE
    it = 0
    diss = 0.0
    diss_p = 0.0
    # Undamped: the rates are not read, and the stretch rates and c_v are zero as in
    # assembly.assemble's undamped call (ws.zero_v, ws.zero_lam_rate).
    c_vk = c_v if damped else 0.0
    # bools from data, not the literal False: a literal argument compiles a second signature of
    # the kernels it is passed to (tests/unit/test_signatures.py)
    no_dlam = dt < 0.0
    v_k = v_eval        # undamped: stays zero (ws.zero_v of the Python path), the kernels do not read it
    # -- Newton ------------------------------------------------------------------------------------
    for it in range(1, max_it + 1):
        if damped:
            velocity_at(q, q_hat, at_n, v_n, c_tilde, gamma, dt, 0.0, v_eval)
        strain, diss = _assemble(q, v_k, lam, lam_rate, c_vk, refresh, no_dlam, mult, r, kdata, cf, ci, wf, wi,
                                 lay, par)
        keep = it == 1 and guarded
        nr, ref = inertial_residual(q, q_hat, at_n, a_n, v_n, c_tilde, am, af, gamma, dt, c_m,
                                    m_indptr, m_indices, m_data, r, f_ext, free, _v1(wf, lay[L_WBUF]), rf, keep, g_p)
        rel = nr / ref
        if keep:
            u_p = strain
            diss_p = diss
            for i in range(nmult):
                c_p[i] = rc[i]
        viol = 0.0
        for i in range(nmult):
            rf[nf + i] = rc[i]
            if abs(rc[i]) > viol:
                viol = abs(rc[i])
        if not math.isfinite(nr):
            code = NON_FINITE_RESIDUAL
            break
        if refresh:
            step = _factor_kernel(kdata, _v1(wf, lay[L_MASSK]), coef, _v1(wi, lay[L_SLOT]), accumulate,
                                  _v1(wi, lay[L_ZSLOT]), _v1(wi, lay[L_BASE]), _v1(wi, lay[L_LRP]),
                                  _v1(wi, lay[L_LRL]), _v1(wi, lay[L_LRH]), _v1(wi, lay[L_URP]), _v1(wi, lay[L_URL]),
                                  _v1(wi, lay[L_URH]), _v1(wi, lay[L_BLK]), env, inv_diag, pivot_tol, lu_stats, nmult)
            if step >= 0 or not lu_stats[0] > 0.0 or lu_stats[1] < min_pivot_ratio * lu_stats[0]:
                tan[0] = 0.0
                code = PIVOT
                break
            tan[0] = 1.0
            tan[1] = coef
            tan[2] = 0.0
            tan[3] += 1.0
        _solve_kernel(rf, _v1(wi, lay[L_PERM]), _v1(wi, lay[L_BASE]), _v1(wi, lay[L_LRP]), _v1(wi, lay[L_LRL]),
                      _v1(wi, lay[L_LRH]), _v1(wi, lay[L_URP]), _v1(wi, lay[L_URL]), _v1(wi, lay[L_URH]), env,
                      inv_diag, _v1(wf, lay[L_LUWORK]), dq)
        inc = apply_increment(q, free, dq, -1.0, inv_scale)
        for i in range(nmult):
            mult[i] -= dq[nf + i]
        if not math.isfinite(inc):
            code = NON_FINITE_INCREMENT
            break
        if inc <= tol and viol <= tol:
            code = OK
            break
        refresh = (not modified) or inc > contraction * prev_inc
        prev_inc = inc
    update_rates(q, q_hat, at_n, a_n, v_n, c_tilde, am, af, gamma, dt, a, v, atil)
    kin = 0.0
    grav = 0.0
    if code == OK:
        kin, grav = _energies(m_indptr, m_indices, m_data, v, q, _v1(cf, lay[L_Q0]), _v1(cf, lay[L_GRAV]))
    # -- the step guard ------------------------------------------------------------------------------
    if code == OK and guarded:
        for k in range(nfg):
            b = f0 + k * NF
            jmin, smin, emin = frame_orientation(q, _v2(ci, lay[b + F_EDOFS]), _v1(ci, lay[b + F_ACT]), lam,
                                                 _v2(wf, lay[b + F_GPHI]), _v2(wf, lay[b + F_GDPHI]),
                                                 _v2(wf, lay[b + F_GIDET]), _v2(wf, lay[b + F_GILEN]))
            if jmin <= 0.0:
                code = INVERTED
                io[IO_X] = jmin
                io[IO_AUX] = emin
                io[IO_GROUP] = k
                break
            if smin < par[P_SVK]:
                code = SVK_LIMIT
                io[IO_X] = smin
                break
    if code == OK and guarded:
        extra_p = 0.0
        extra_size = 0.0
        w_mom = 0.0
        if _v2(ci, lay[L_FVDOFS]).shape[0] or _v2(ci, lay[L_MVDOFS]).shape[0]:
            q_l = _v1(wf, lay[L_QL])           # the last evaluated iterate
            for i in range(n):
                q_l[i] = q[i]
            for k in range(nf):
                q_l[free[k]] += dq[k]
            w = _moment_work(q_l, q_p, no_dlam, cf, ci, wf, lay)
            extra_p = -w
            extra_size = abs(w)
            w_mom = _moment_work(q, q_n, no_dlam, cf, ci, wf, lay)
        if damped:          # viscous work by the trapezoidal rule (StepGuard.dynamic)
            wv = (diss - diss_p) / (2.0 * c_v)
            extra_p += wv
            extra_size += abs(wv)
        if nmult:
            wm = 0.0
            for i in range(nmult):
                wm += mult[i] * (rc[i] - c_p[i])
            extra_p += wm
            extra_size += abs(wm)
        check_balance = balance and led[2] == t_n
        g, x, y, e_end = dynamic_guard(q, dq, free, _v1(cf, lay[L_DSCALE]), ivec, gvec, int(led[0]), react,
                                       int(led[1]), m_indptr, m_indices, m_data, f_ext, r, rf, a, v,
                                       _v1(wi, lay[L_DRIVE]), c_m, c_v, tol, par[P_CMASS], par[P_RISE], par[P_BAL],
                                       u_p, strain, 1.0, extra_p, extra_size, w_mom, kin, led[3], check_balance)
        led[4] = e_end
        io[IO_X] = x
        io[IO_Y] = y
        io[IO_EEND] = e_end
        io[IO_AUX] = g
        io[IO_UP] = u_p
        if g != 0:
            code = ENERGY
    io[IO_IT] = it
    io[IO_REL] = rel
    io[IO_INC] = inc
    io[IO_STRAIN] = strain
    io[IO_KIN] = kin
    io[IO_GRAV] = grav
    io[IO_DISS] = diss
    if code != OK:
        if code != PIVOT:
            tan[0] = 0.0           # a failed step never leaves a stale tangent behind
        if code == PIVOT or par[P_KEEP] == 0.0:
            for i in range(n):     # the step's start, for the integrator's policy (or the Python path)
                q[i] = q_n[i]
                v[i] = v_n[i]
                a[i] = a_n[i]
                atil[i] = at_n[i]
            for i in range(nmult):
                mult[i] = mult_n[i]
        return code
    tan[2] += 1.0
    if guarded:                    # the guard's ledger moves to the accepted state (ledger_accept)
        led[2] = t_n + dt
        led[3] = led[4]
        led[0] = 3.0 - led[0]
        led[1] = 1.0 - led[1]
    return OK


def _constant_after(sig) -> float:
    """Time after which ``sig`` is constant (+inf if never: sine, spin-up, tables of unknown end)."""
    if sig.kind == "constant":
        return -math.inf
    if sig.kind == "ramp":
        return sig.t0 + sig.duration
    if sig.kind == "table" and len(sig.table_t):
        return float(sig.table_t[-1])           # held outside the table
    return math.inf


class _Packer:
    """Builds one pack (a flat array) and its rows of the layout table."""

    def __init__(self, lay: np.ndarray, dtype):
        self.lay = lay
        self.dtype = dtype
        self.parts: list[np.ndarray] = []
        self.size = 0

    def add(self, item: int, arr) -> None:
        arr = np.ascontiguousarray(arr, dtype=self.dtype)
        dims = list(arr.shape) + [1] * (4 - arr.ndim)
        self.lay[item, 0] = self.size
        self.lay[item, 1:5] = dims
        self.lay[item, 5] = arr.size
        self.parts.append(arr.ravel())
        self.size += arr.size

    def build(self, writable: bool) -> np.ndarray:
        buf = np.concatenate(self.parts) if self.parts else np.zeros(0, self.dtype)
        buf = np.ascontiguousarray(buf, dtype=self.dtype)
        buf.setflags(write=writable)
        return buf


# Model fields model_step accounts for. A field added to Model later keeps a model on the Python
# path whenever it is not empty, until it is looked at here.
_KNOWN_MODEL_FIELDS = frozenset((
    "scene", "ndof", "q0", "dof_scale", "free", "free_index", "indptr", "indices", "mass_kdata", "mass_csr",
    "frame_groups", "truss", "moments", "load_vectors", "load_signals", "gravity_vector", "gravity_signal",
    "actuators", "members", "node_names", "node_ydofs", "mass_damping", "total_mass", "drives", "program",
    "program_index", "nsys", "corner_dofs", "corner_alpha", "corner_smap", "hinge_dofs", "hinge_alpha",
    "hinge_beta", "hinge_smap", "node_lookup", "member_lookup", "shell_groups", "shells", "tie_dofs",
    "tie_alpha", "tie_smap"))


def _empty(value) -> bool:
    return value is None or (hasattr(value, "__len__") and len(value) == 0)


class NumbaStep:
    """The numba step of :func:`model_step`, bound to one integrator's model, workspace, solver
    and guard (everything it touches is allocated here or there, once)."""

    @staticmethod
    def unsupported(model: Model, spec: SolverSpec) -> str:
        """'' when :func:`model_step` covers every step of this model, else what it lacks."""
        if spec.analysis != "dynamic" or spec.integrator not in ("newmark", "generalized_alpha"):
            return f"integrator {spec.integrator}"
        unknown = [f.name for f in dataclasses.fields(model)
                   if f.name not in _KNOWN_MODEL_FIELDS and not _empty(getattr(model, f.name))]
        if unknown:
            return f"model features this step does not know: {', '.join(unknown)}"
        return ""

    def __init__(self, integ):
        m, ws = integ.model, integ.ws
        self.integ = integ
        self.model = m
        tg = m.truss if m.truss is not None else _empty_truss_group()
        mo = m.moments
        sky = integ.lu.skyline
        guard = integ.guard
        n = m.ndof
        nfg, nsg = len(m.frame_groups), len(m.shell_groups)
        lay = np.zeros((N_ITEMS + nfg * NF + nsg * NS, 6), dtype=np.int64)
        par = np.zeros(N_PAR)
        spec = integ.spec
        par[P_AM], par[P_AF], par[P_BETA], par[P_GAMMA] = integ.am, integ.af, integ.beta, integ.gamma
        par[P_CM], par[P_TOL], par[P_MAXIT] = m.mass_damping, spec.tolerance, spec.max_iterations
        par[P_MODIFIED] = spec.newton == "modified"
        par[P_CONTRACTION], par[P_MAXAGE] = spec.modified_contraction, spec.tangent_max_age
        par[P_SVK], par[P_RISE], par[P_BAL] = SVK_LIMIT_STRETCH, guard.rise_tolerance, guard.balance_tolerance
        par[P_CMASS], par[P_PIVTOL], par[P_MINPIV] = guard._c_mass, sky.pivot_tol, integ.lu.min_pivot_ratio
        par[P_ACCUM], par[P_DAMPED] = sky._accumulate, bool(m.material_damping)
        par[P_NFG], par[P_NSG], par[P_F0], par[P_S0] = nfg, nsg, N_ITEMS, N_ITEMS + nfg * NF
        par[P_NMULT] = m.n_multipliers
        # accept_flagged keeps a failed attempt's last iterate, as the Python path leaves it
        self._keep_failed = spec.on_unconverged == "accept_flagged"
        par[P_KEEP] = self._keep_failed
        mi, mj, mv = integ._mass
        cf, ci = _Packer(lay, np.float64), _Packer(lay, np.int64)
        wf, wi = _Packer(lay, np.float64), _Packer(lay, np.int64)
        for item, arr in ((L_DSCALE, m.dof_scale), (L_Q0, m.q0), (L_GRAV, m.gravity_vector), (L_PAR, par),
                          (L_MV, mv), (L_TL0, tg.l0), (L_TEA, tg.ea), (L_TTAU, tg.tau), (L_CALPHA, m.corner_alpha),
                          (L_HALPHA, m.hinge_alpha), (L_HBETA, m.hinge_beta), (L_TIEALPHA, m.tie_alpha),
                          (L_FMBODY, mo.follower_mbody), (L_CAXES, mo.cons_axes), (L_CMAG, mo.cons_magnitude)):
            cf.add(item, arr)
        drive_ids = guard._drive_ids
        for item, arr in ((L_FREE, m.free), (L_MI, mi), (L_MJ, mj), (L_TEDOFS, tg.edofs), (L_TACT, tg.act),
                          (L_TSMAP, tg.smap), (L_CDOFS, m.corner_dofs), (L_CSMAP, m.corner_smap),
                          (L_HDOFS, m.hinge_dofs), (L_HSMAP, m.hinge_smap), (L_TIEDOFS, m.tie_dofs),
                          (L_TIESMAP, m.tie_smap), (L_FVDOFS, mo.follower_vdofs), (L_FSMAP, mo.follower_smap),
                          (L_MVDOFS, mo.cons_vdofs), (L_MSMAP, mo.cons_smap), (L_DRVIDX, drive_ids)):
            ci.add(item, arr)
        nm = m.n_multipliers
        for item, arr in ((L_INVS, integ._inv_scale), (L_MASSK, m.mass_kdata), (L_VEVAL, np.zeros(n)),
                          (L_WBUF, np.zeros(n)), (L_RF, np.zeros(m.nsys)), (L_DQ, np.zeros(m.nsys)),
                          (L_KDATA, np.zeros(m.nnz)), (L_IVEC, np.zeros((7, n))), (L_LUWORK, np.zeros(sky.n)),
                          (L_TQE, np.zeros(6)), (L_TVE, np.zeros(6)), (L_TRE, np.zeros(6)), (L_TKE, np.zeros((6, 6))),
                          (L_CKE, np.zeros((18, 18))), (L_HKE, np.zeros((14, 14))), (L_TIEKE, np.zeros((12, 12))),
                          (L_RC, np.zeros(nm)), (L_CP, np.zeros(nm)), (L_MULTN, np.zeros(nm)),
                          (L_FSCALE, np.ones(mo.follower_vdofs.shape[0])), (L_MSCALE, np.ones(mo.cons_vdofs.shape[0])),
                          (L_RM, np.zeros(n)), (L_QL, np.zeros(n)), (L_KDUMMY, np.zeros(0)),
                          (L_DRVVAL, np.zeros(drive_ids.size))):
            wf.add(item, arr)
        for item, arr in zip(range(L_SDV, L_SKE + 1), shell_scratch()):
            wf.add(item, arr)
        for item, arr in ((L_SLOT, sky._slot), (L_ZSLOT, sky._zero_slots), (L_BASE, sky._base),
                          (L_LRP, sky._lrun[0]), (L_LRL, sky._lrun[1]), (L_LRH, sky._lrun[2]), (L_URP, sky._urun[0]),
                          (L_URL, sky._urun[1]), (L_URH, sky._urun[2]), (L_BLK, sky._blk_ptr), (L_PERM, sky.perm),
                          (L_DRIVE, drive_ids)):
            wi.add(item, arr)
        for k, (g, st, gst) in enumerate(zip(m.frame_groups, ws.frame_structure, guard._stations)):
            b = N_ITEMS + k * NF
            for item, arr in ((F_DAX, g.dax), (F_DSEC, g.dsec), (F_W, g.w), (F_MAT, g.mat)):
                cf.add(b + item, arr)
            for item, arr in ((F_EDOFS, g.edofs), (F_ACT, g.act), (F_SMAP, g.smap), (F_NSEC, [g.nsec])):
                ci.add(b + item, arr)
            for item, arr in ((F_PHIST, st[1]), (F_DPHIST, st[2]), (F_SPT, st[3]), (F_HACC, st[5]),
                              (F_GACC, st[6]), (F_TK, st[7]), (F_TG, st[8])):
                wf.add(b + item, arr)
            for item, arr in zip(range(F_D, F_KN + 1), frame_scratch(g.w.shape[1], g.dax.shape[2])):
                wf.add(b + item, arr)
            for item, arr in zip((F_GPHI, F_GDPHI, F_GIDET, F_GILEN), gst):
                wf.add(b + item, arr)
            wi.add(b + F_STRAIGHT, st[0])
            wi.add(b + F_BLOCKS, st[4])
        for k, g in enumerate(m.shell_groups):
            b = N_ITEMS + nfg * NF + k * NS
            for item, arr in ((S_PHI, g.phi), (S_DPHI, g.dphi), (S_ZETA, g.zeta), (S_A0INV, g.a0inv), (S_W, g.w),
                              (S_MAT, g.mat)):
                cf.add(b + item, arr)
            ci.add(b + S_EDOFS, g.edofs)
            ci.add(b + S_SMAP, g.smap)
        self._lay = lay
        self._packs = (cf.build(False), ci.build(False), wf.build(True), wi.build(True))
        wbuf = self._packs[2]

        def view(item):
            o, size = lay[item, 0], lay[item, 5]
            return wbuf[o:o + size]

        self._follower_scale, self._cons_scale = view(L_FSCALE), view(L_MSCALE)
        self._drive_values, self._drive_ids = view(L_DRVVAL), drive_ids
        self._q_drive = np.zeros(n) if m.drives is not None else None
        self._io = np.zeros(N_IO)
        na = m.actuators.l0.size
        self._lam_n = np.zeros(na)          # λ_n and its rate at the step's start (restored on failure)
        self._rate_n = np.zeros(na)
        self._zero_rate = np.zeros(na)      # undamped: the elements read no stretch rate
        self._shared = (ws.f_ext, ws.r, sky._env, sky._inv_diag, sky._stats)
        self._signals = m.load_signals
        self._scales = np.full(len(m.load_signals), math.nan)
        self._g_scale = math.nan
        self._gravity = bool(np.any(m.gravity_vector != 0.0))
        # from this time on every load signal is constant (a finished ramp, a constant), so f_ext
        # and the moment scales, once formed there, stay: no signal is evaluated any more
        sigs = (list(m.load_signals) + list(mo.follower_signals) + list(mo.cons_signals)
                + ([m.gravity_signal] if self._gravity else []))
        self._still_after = max([_constant_after(x) for x in sigs], default=-math.inf)
        self._still = False

    def invalidate(self) -> None:
        """Someone else (the Python path, ``initialize``) formed ``f_ext``: recompute it next time."""
        self._scales[:] = math.nan
        self._g_scale = math.nan
        self._still = False

    def loads(self, t: float) -> None:
        """``f_ext`` and the moment scales at ``t`` as
        :func:`~flexmb_core.model.assembly.update_load_scales` forms them (the same operations:
        bit-identical), ``f_ext`` recomputed only when a signal changed."""
        if self._still:
            return
        m, ws = self.model, self.integ.ws
        mo = m.moments
        for i, s in enumerate(mo.follower_signals):
            self._follower_scale[i] = evaluate(s, t)
        for i, s in enumerate(mo.cons_signals):
            self._cons_scale[i] = evaluate(s, t)
        changed = False
        sc = ws.load_scale
        for i, s in enumerate(self._signals):
            x = evaluate(s, t)
            if x != sc[i] or self._scales[i] != x:
                sc[i] = x
                self._scales[i] = x
                changed = True
        gs = evaluate(m.gravity_signal, t) if self._gravity else 0.0
        if gs != self._g_scale:
            self._g_scale = gs
            changed = True
        if changed:
            if m.load_vectors.shape[0]:
                np.dot(sc, m.load_vectors, out=ws.f_ext)
            else:
                ws.f_ext[:] = 0.0
            if gs != 0.0:
                ws.f_ext += gs * m.gravity_vector
        self._still = t >= self._still_after

    def drives(self, q: np.ndarray, t: float) -> None:
        """The driven supports' DOFs at ``t`` into their ``wf`` item (by :func:`apply_drives`
        itself on a copy of ``q``: the same operations as the Python path's)."""
        if self._q_drive is None:
            return
        self._q_drive[:] = q
        apply_drives(self.model, self._q_drive, t)
        np.take(self._q_drive, self._drive_ids, out=self._drive_values)

    def attempt(self, state, dt: float, lam_new: np.ndarray, lam_rate: np.ndarray | None = None
                ) -> StepResult | None:
        """The first Newton attempt of the step ``state.t → state.t + dt`` to the actuator
        stretches ``lam_new`` (rates ``lam_rate`` or, for damped models, the integrator's backward
        difference): the result (state advanced when converged, unchanged otherwise), or ``None``
        when the integrator's Python path must make the attempt (a held SuperLU factorization, a
        pivot for SuperLU)."""
        integ = self.integ
        lu = integ.lu
        tan = integ._tan
        if tan[0] != 0.0 and lu._active is not lu.skyline:
            return None                 # a held SuperLU factorization: the Python path reuses it
        guard = integ.guard
        t_n = state.t
        lam = state.lam
        if lam.size:                    # the step's start, restored if the attempt fails
            self._lam_n[:] = lam
            self._rate_n[:] = state.lam_rate
        balance = not integ.set_stretches(state, dt, lam_new, lam_rate)
        rates = state.lam_rate if integ._damped else self._zero_rate
        self.loads(t_n + dt)
        self.drives(state.q, t_n + dt)
        f_ext, r, env, inv_diag, stats = self._shared
        cf, ci, wf, wi = self._packs
        code = model_step(state.q, state.v, state.a, state.atil, lam, rates, state.mult, f_ext, r, env, inv_diag,
                          stats, guard._gvec, guard._react, cf, ci, wf, wi, self._lay, tan, guard._led, self._io, t_n,
                          dt, guard.enabled, balance)
        if tan[0] != 0.0:
            lu._active = lu.skyline
            lu.skyline._factored = True
        it, rel, inc, strain, kin, grav = self._io[:IO_X].tolist()
        integ.ws.dissipation = self._io[IO_DISS]
        if code == OK:
            state.t = t_n + dt
            integ.accept_stretches(t_n, t_n + dt)
            return StepResult(True, int(it), rel, inc, 1, kin, strain, grav)
        if self._keep_failed and code != PIVOT:
            state.t = t_n + dt          # the failed iterate at t_{n+1}, λ_{n+1} in force (accept_flagged)
        elif lam.size:                  # the step's start, for the integrator's policy
            lam[:] = self._lam_n
            state.lam_rate[:] = self._rate_n
        return self._failure(code, int(it), rel, inc, strain, kin, grav)

    def _failure(self, code: int, it: int, rel: float, inc: float, strain: float, kin: float,
                 grav: float) -> StepResult | None:
        """The failed attempt as the Python path reports it (same messages and flags)."""
        integ, m, spec, io = self.integ, self.model, self.integ.spec, self._io
        guard = integ.guard
        if code == PIVOT:
            integ._factored_coef = None
            return None
        flag, message = "", ""
        if code == NO_CONVERGENCE:
            message = (f"no convergence in {spec.max_iterations} iterations (increment {inc:.2e}, "
                       f"tolerance {spec.tolerance:.1e})")
        elif code == NON_FINITE_RESIDUAL:
            message = f"non-finite residual at Newton iteration {it}"
        elif code == NON_FINITE_INCREMENT:
            message = f"non-finite increment at Newton iteration {it}"
        elif code == INVERTED:
            flag = "inverted"
            group = m.frame_groups[int(io[IO_GROUP])]
            member = m.members[int(group.member[int(io[IO_AUX])])].name
            message = (f"step guard: inverted frame section (det F = {io[IO_X]:.3g} ≤ 0 in member "
                       f"'{member}'), a reflection Green–Lagrange strain cannot see")
        elif code == SVK_LIMIT:
            flag = "svk_limit"
            message = (f"step guard: fibre stretch {io[IO_X]:.3g} below 1/√3, the compressive limit point of "
                       "the Saint-Venant–Kirchhoff law")
        else:
            flag = "energy"
            message = guard.energy_message(int(io[IO_AUX]), io[IO_X], io[IO_Y], io[IO_EEND], io[IO_UP], strain)
        if flag:
            guard.rejections += 1
            return StepResult(False, it, rel, inc, 1, kin, strain, grav, message=message, guard=flag)
        return StepResult(False, it, rel, inc, 1, message=message)


def _empty_truss_group() -> TrussGroup:
    i0 = np.zeros(0, dtype=np.int64)
    return TrussGroup(edofs=np.zeros((0, 6), dtype=np.int64), l0=np.zeros(0), ea=np.zeros(0), act=i0,
                      smap=np.zeros((0, 36), dtype=np.int64), member=i0, tau=np.zeros(0))


from ..solvers.guard import SVK_LIMIT_STRETCH  # noqa: E402  (after the kernel: no import cycle at compile)
