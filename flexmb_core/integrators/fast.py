"""One numba call per time step for the common frame-only model (the B1 cantilever kind).

:class:`FastFrameStep` runs the first Newton attempt of a step of
:class:`~flexmb_core.integrators.dynamic.DynamicIntegrator` entirely inside :func:`frame_step`:
predictor, residual and (held or refreshed) tangent of the frame group, the inertial residual,
the skyline LU factor and solve, the modified-Newton refresh rule, the rates, the energies and
the step guard's checks. It calls the very kernels the Python path calls, in the same order, so
its results are bit-identical to it (``tests/unit/test_fast_step.py``); it only removes the
Python between them (≈ 70 µs per step on B1 before, see ``docs/benchmarks/b1_profile.md``).

It covers a model with exactly one frame group and nothing else that the step would have to
evaluate in Python: no trusses, shells, actuators, drives, moment loads, multipliers (rigid
corners, hinges, ties), command programs or material damping, and the Newmark or Arnold–Brüls
generalized-α integrator. :func:`FastFrameStep.unsupported` names what is missing otherwise and
the integrator keeps its Python path. A step the kernel cannot finish — no convergence, a refused
root, a pivot the skyline LU must not take (the Python path then pivots with SuperLU) — leaves the
state as it was and hands back to the integrator, whose ``on_unconverged`` policy proceeds as for
any failed attempt.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit

from ..kernels.frame3d import frame_group, frame_scratch, frame_structure
from ..kernels.guard import dynamic_guard, frame_orientation
from ..kernels.truss import truss_group
from ..model.model import FrameGroup, Model, TrussGroup
from ..scene.schema import SolverSpec
from ..signals import evaluate
from ..solvers.banded import _factor_kernel, _solve_kernel
from ..solvers.result import StepResult
from .energy import _energies
from .fused import apply_increment, inertial_residual, update_rates, velocity_at

# Return codes of frame_step.
OK, NO_CONVERGENCE, NON_FINITE_RESIDUAL, NON_FINITE_INCREMENT, PIVOT, INVERTED, SVK_LIMIT, ENERGY = range(8)

# Items of the packed arguments (rows of the layout table: offset, dims d0…d3, size). Read-only
# float pack ``cf``: model arrays (read-only like the model's, so the kernels called inside keep
# their one compiled signature) and the step constants. Read-only int pack ``ci``. Writable float
# pack ``wf``: arrays the Python path passes writable (copies) and the step's scratch. Writable
# int pack ``wi``: the skyline LU's symbolic structure and other writable index arrays.
(L_DSCALE, L_Q0, L_GRAV, L_DAX, L_DSEC, L_W, L_MAT, L_PAR, L_MV, L_TL0, L_TEA, L_TTAU,     # cf
 L_FREE, L_EDOFS, L_ACT, L_SMAP, L_MI, L_MJ, L_TEDOFS, L_TACT, L_TSMAP,              # ci
 L_INVS, L_MASSK, L_PHIST, L_DPHIST, L_SPT, L_HACC, L_GACC, L_TK, L_TG, L_D, L_FP, L_FD, L_EP, L_ED, L_BMAT,
 L_BDOT, L_GBAR, L_GDOT, L_QE, L_VE, L_RE, L_KE, L_KN, L_GPHI, L_GDPHI, L_GIDET, L_GILEN, L_VEVAL,
 L_WBUF, L_RF, L_DQ, L_KDATA, L_IVEC, L_LUWORK, L_TQE, L_TVE, L_TRE, L_TKE,          # wf
 L_SLOT, L_ZSLOT, L_BASE, L_LRP, L_LRL, L_LRH, L_URP, L_URL, L_URH, L_BLK, L_PERM, L_STRAIGHT,
 L_BLOCKS, L_DRIVE,                                                               # wi
 N_ITEMS) = range(74)
# Step constants in the L_PAR block of cf.
(P_AM, P_AF, P_BETA, P_GAMMA, P_CM, P_TOL, P_MAXIT, P_MODIFIED, P_CONTRACTION, P_MAXAGE, P_SVK, P_RISE, P_BAL,
 P_CMASS, P_PIVTOL, P_MINPIV, P_NSEC, P_ACCUM, P_DAMPED, N_PAR) = range(20)
# Output slots of io.
(IO_IT, IO_REL, IO_INC, IO_STRAIN, IO_KIN, IO_GRAV, IO_X, IO_Y, IO_EEND, IO_AUX, IO_UP, IO_DISS, N_IO) = range(13)


@njit(cache=True, nogil=True)
def frame_step(q, v, a, atil, lam, lam_rate, f_ext, r, env, inv_diag, lu_stats, gvec, react, cf, ci, wf, wi, lay,
               tan, led, io, t_n, dt, guarded, balance):
    """First Newton attempt of one dynamic step of a frame/truss model (see the module).

    State ``q, v, a, atil (ndof,)`` is advanced in place on success and left unchanged
    otherwise. ``lam, lam_rate (na,)``: the actuator stretches λ_{n+1} and their rates (1/s,
    read by damped elements only), set by the caller. ``balance``: the step moves no actuator,
    so the guard's energy balance (check 3) applies. The GIL is released: a caller's other
    threads (the node's executor) run while the step does. Shared with the Python path: ``f_ext`` (loads at t_{n+1}, set by the caller),
    ``r`` (internal force of the last evaluation), the skyline factors ``env, inv_diag,
    lu_stats`` (the held tangent) and the step guard's ledger rows ``gvec, react``. Everything
    else comes in four packs and their layout table ``lay`` (see the ``L_*`` items): every array
    argument costs dispatch time (≈ 0.1 µs), and a step has about a hundred of them.

    ``tan`` in/out: the integrator's held tangent [held, coefficient, age, refreshes]; ``led``
    in/out: the guard's ledger [il, ir, t, K + U, candidate K + U] (advanced here when the step is
    accepted); ``t_n, dt``: the step; ``guarded``: run the step guard. ``io`` out (``IO_*``):
    iterations, relative residual, increment, strain, kinetic and gravity energy, the guard's
    values (x, y, e_end, aux: element of an inverted section or the energy check's code) and the
    strain energy at the Newton start.

    Returns one of the codes ``OK, NO_CONVERGENCE, …, ENERGY``.
    """
    # -- unpack (views, no copies) --------------------------------------------------------------
    o = lay[L_DSCALE, 0]; dof_scale = cf[o:o + lay[L_DSCALE, 5]]
    o = lay[L_Q0, 0]; q0 = cf[o:o + lay[L_Q0, 5]]
    o = lay[L_GRAV, 0]; gravity = cf[o:o + lay[L_GRAV, 5]]
    o = lay[L_DAX, 0]
    dax = cf[o:o + lay[L_DAX, 5]].reshape((lay[L_DAX, 1], lay[L_DAX, 2], lay[L_DAX, 3], lay[L_DAX, 4]))
    o = lay[L_DSEC, 0]
    dsec = cf[o:o + lay[L_DSEC, 5]].reshape((lay[L_DSEC, 1], lay[L_DSEC, 2], lay[L_DSEC, 3], lay[L_DSEC, 4]))
    o = lay[L_W, 0]; w = cf[o:o + lay[L_W, 5]].reshape((lay[L_W, 1], lay[L_W, 2]))
    o = lay[L_MAT, 0]; mat = cf[o:o + lay[L_MAT, 5]].reshape((lay[L_MAT, 1], lay[L_MAT, 2]))
    o = lay[L_PAR, 0]; par = cf[o:o + lay[L_PAR, 5]]
    o = lay[L_TL0, 0]; t_l0 = cf[o:o + lay[L_TL0, 5]]
    o = lay[L_TEA, 0]; t_ea = cf[o:o + lay[L_TEA, 5]]
    o = lay[L_TTAU, 0]; t_tau = cf[o:o + lay[L_TTAU, 5]]
    o = lay[L_TEDOFS, 0]; t_edofs = ci[o:o + lay[L_TEDOFS, 5]].reshape((lay[L_TEDOFS, 1], lay[L_TEDOFS, 2]))
    o = lay[L_TACT, 0]; t_act = ci[o:o + lay[L_TACT, 5]]
    o = lay[L_TSMAP, 0]; t_smap = ci[o:o + lay[L_TSMAP, 5]].reshape((lay[L_TSMAP, 1], lay[L_TSMAP, 2]))
    o = lay[L_TQE, 0]; t_qe = wf[o:o + lay[L_TQE, 5]]
    o = lay[L_TVE, 0]; t_ve = wf[o:o + lay[L_TVE, 5]]
    o = lay[L_TRE, 0]; t_re = wf[o:o + lay[L_TRE, 5]]
    o = lay[L_TKE, 0]; t_ke = wf[o:o + lay[L_TKE, 5]].reshape((lay[L_TKE, 1], lay[L_TKE, 2]))
    o = lay[L_VEVAL, 0]; v_eval = wf[o:o + lay[L_VEVAL, 5]]
    o = lay[L_FREE, 0]; free = ci[o:o + lay[L_FREE, 5]]
    o = lay[L_EDOFS, 0]; edofs = ci[o:o + lay[L_EDOFS, 5]].reshape((lay[L_EDOFS, 1], lay[L_EDOFS, 2]))
    o = lay[L_ACT, 0]; act = ci[o:o + lay[L_ACT, 5]]
    o = lay[L_SMAP, 0]; smap = ci[o:o + lay[L_SMAP, 5]].reshape((lay[L_SMAP, 1], lay[L_SMAP, 2]))
    o = lay[L_INVS, 0]; inv_scale = wf[o:o + lay[L_INVS, 5]]
    o = lay[L_MV, 0]; m_data = cf[o:o + lay[L_MV, 5]]
    o = lay[L_MASSK, 0]; mass_kdata = wf[o:o + lay[L_MASSK, 5]]
    o = lay[L_PHIST, 0]
    phi_st = wf[o:o + lay[L_PHIST, 5]].reshape((lay[L_PHIST, 1], lay[L_PHIST, 2], lay[L_PHIST, 3]))
    o = lay[L_DPHIST, 0]
    dphi_st = wf[o:o + lay[L_DPHIST, 5]].reshape((lay[L_DPHIST, 1], lay[L_DPHIST, 2], lay[L_DPHIST, 3]))
    o = lay[L_SPT, 0]; s_pt = wf[o:o + lay[L_SPT, 5]].reshape((lay[L_SPT, 1], lay[L_SPT, 2], lay[L_SPT, 3]))
    o = lay[L_HACC, 0]; hacc = wf[o:o + lay[L_HACC, 5]].reshape((lay[L_HACC, 1], lay[L_HACC, 2], lay[L_HACC, 3]))
    o = lay[L_GACC, 0]; gacc = wf[o:o + lay[L_GACC, 5]]
    o = lay[L_TK, 0]; tk = wf[o:o + lay[L_TK, 5]].reshape((lay[L_TK, 1], lay[L_TK, 2], lay[L_TK, 3], lay[L_TK, 4]))
    o = lay[L_TG, 0]; tg = wf[o:o + lay[L_TG, 5]].reshape((lay[L_TG, 1], lay[L_TG, 2]))
    o = lay[L_D, 0]; d = wf[o:o + lay[L_D, 5]].reshape((lay[L_D, 1], lay[L_D, 2], lay[L_D, 3]))
    o = lay[L_FP, 0]; fp = wf[o:o + lay[L_FP, 5]].reshape((lay[L_FP, 1], lay[L_FP, 2], lay[L_FP, 3]))
    o = lay[L_FD, 0]; fd = wf[o:o + lay[L_FD, 5]].reshape((lay[L_FD, 1], lay[L_FD, 2], lay[L_FD, 3]))
    o = lay[L_EP, 0]; ep = wf[o:o + lay[L_EP, 5]].reshape((lay[L_EP, 1], lay[L_EP, 2]))
    o = lay[L_ED, 0]; ed = wf[o:o + lay[L_ED, 5]].reshape((lay[L_ED, 1], lay[L_ED, 2]))
    o = lay[L_BMAT, 0]; bmat = wf[o:o + lay[L_BMAT, 5]].reshape((lay[L_BMAT, 1], lay[L_BMAT, 2]))
    o = lay[L_BDOT, 0]; bdot = wf[o:o + lay[L_BDOT, 5]].reshape((lay[L_BDOT, 1], lay[L_BDOT, 2]))
    o = lay[L_GBAR, 0]; gbar = wf[o:o + lay[L_GBAR, 5]].reshape((lay[L_GBAR, 1], lay[L_GBAR, 2]))
    o = lay[L_GDOT, 0]; gdot = wf[o:o + lay[L_GDOT, 5]].reshape((lay[L_GDOT, 1], lay[L_GDOT, 2]))
    o = lay[L_QE, 0]; qe = wf[o:o + lay[L_QE, 5]]
    o = lay[L_VE, 0]; ve = wf[o:o + lay[L_VE, 5]]
    o = lay[L_RE, 0]; re = wf[o:o + lay[L_RE, 5]]
    o = lay[L_KE, 0]; ke = wf[o:o + lay[L_KE, 5]].reshape((lay[L_KE, 1], lay[L_KE, 2]))
    o = lay[L_KN, 0]; kn = wf[o:o + lay[L_KN, 5]].reshape((lay[L_KN, 1], lay[L_KN, 2]))
    o = lay[L_GPHI, 0]; gphi = wf[o:o + lay[L_GPHI, 5]].reshape((lay[L_GPHI, 1], lay[L_GPHI, 2]))
    o = lay[L_GDPHI, 0]; gdphi = wf[o:o + lay[L_GDPHI, 5]].reshape((lay[L_GDPHI, 1], lay[L_GDPHI, 2]))
    o = lay[L_GIDET, 0]; inv_det0 = wf[o:o + lay[L_GIDET, 5]].reshape((lay[L_GIDET, 1], lay[L_GIDET, 2]))
    o = lay[L_GILEN, 0]; inv_len0 = wf[o:o + lay[L_GILEN, 5]].reshape((lay[L_GILEN, 1], lay[L_GILEN, 2]))
    o = lay[L_WBUF, 0]; w_buf = wf[o:o + lay[L_WBUF, 5]]
    o = lay[L_RF, 0]; rf = wf[o:o + lay[L_RF, 5]]
    o = lay[L_DQ, 0]; dq = wf[o:o + lay[L_DQ, 5]]
    o = lay[L_KDATA, 0]; kdata = wf[o:o + lay[L_KDATA, 5]]
    o = lay[L_IVEC, 0]; ivec = wf[o:o + lay[L_IVEC, 5]].reshape((lay[L_IVEC, 1], lay[L_IVEC, 2]))
    o = lay[L_LUWORK, 0]; lu_work = wf[o:o + lay[L_LUWORK, 5]]
    o = lay[L_MI, 0]; m_indptr = ci[o:o + lay[L_MI, 5]]
    o = lay[L_MJ, 0]; m_indices = ci[o:o + lay[L_MJ, 5]]
    o = lay[L_SLOT, 0]; slot = wi[o:o + lay[L_SLOT, 5]]
    o = lay[L_ZSLOT, 0]; zero_slots = wi[o:o + lay[L_ZSLOT, 5]]
    o = lay[L_BASE, 0]; base = wi[o:o + lay[L_BASE, 5]]
    o = lay[L_LRP, 0]; lrun_ptr = wi[o:o + lay[L_LRP, 5]]
    o = lay[L_LRL, 0]; lrun_lo = wi[o:o + lay[L_LRL, 5]]
    o = lay[L_LRH, 0]; lrun_hi = wi[o:o + lay[L_LRH, 5]]
    o = lay[L_URP, 0]; urun_ptr = wi[o:o + lay[L_URP, 5]]
    o = lay[L_URL, 0]; urun_lo = wi[o:o + lay[L_URL, 5]]
    o = lay[L_URH, 0]; urun_hi = wi[o:o + lay[L_URH, 5]]
    o = lay[L_BLK, 0]; blk_ptr = wi[o:o + lay[L_BLK, 5]]
    o = lay[L_PERM, 0]; perm = wi[o:o + lay[L_PERM, 5]]
    o = lay[L_STRAIGHT, 0]; straight = wi[o:o + lay[L_STRAIGHT, 5]]
    o = lay[L_BLOCKS, 0]
    blocks = wi[o:o + lay[L_BLOCKS, 5]].reshape((lay[L_BLOCKS, 1], lay[L_BLOCKS, 2], lay[L_BLOCKS, 3]))
    o = lay[L_DRIVE, 0]; drive_ids = wi[o:o + lay[L_DRIVE, 5]]
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
    nsec = int(par[P_NSEC])
    accumulate = par[P_ACCUM] != 0.0
    pivot_tol = par[P_PIVTOL]
    min_pivot_ratio = par[P_MINPIV]
    damped = par[P_DAMPED] != 0.0

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
    for k in range(nf):
        i = free[k]
        q[i] = q_hat[i] + c_bdt * at_n[i]
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
    # a bool from data, not the literal False: a literal argument compiles a second signature of
    # frame_group and its element kernels (tests/unit/test_signatures.py)
    no_dlam = dt < 0.0
    v_k = v_eval if damped else ve
    # -- Newton ------------------------------------------------------------------------------------
    for it in range(1, max_it + 1):
        for i in range(n):
            r[i] = 0.0
        if refresh:
            for i in range(kdata.size):
                kdata[i] = 0.0
        if damped:
            velocity_at(q, q_hat, at_n, v_n, c_tilde, gamma, dt, 0.0, v_eval)
        # the sums in assembly.assemble's order: frame group, then bars (bit-identical)
        strain = 0.0
        diss = 0.0
        u_g, dp_g = frame_group(q, v_k, edofs, dax, dsec, w, nsec, mat, act, lam, lam_rate, c_vk, smap,
                                refresh, no_dlam, r, kdata, d, fp, fd, ep, ed, bmat, bdot, gbar, gdot, qe, ve,
                                re, ke, kn, straight, phi_st, dphi_st, s_pt, blocks, hacc, gacc, tk, tg)
        strain += u_g
        diss += dp_g
        if t_edofs.shape[0]:
            u_g, dp_g = truss_group(q, v_k, t_edofs, t_l0, t_ea, t_tau, t_act, lam, lam_rate, c_vk, t_smap,
                                    refresh, r, kdata, t_qe, t_ve, t_re, t_ke)
            strain += u_g
            diss += dp_g
        keep = it == 1 and guarded
        nr, ref = inertial_residual(q, q_hat, at_n, a_n, v_n, c_tilde, am, af, gamma, dt, c_m,
                                    m_indptr, m_indices, m_data, r, f_ext, free, w_buf, rf, keep, g_p)
        rel = nr / ref
        if keep:
            u_p = strain
            diss_p = diss
        if not math.isfinite(nr):
            code = NON_FINITE_RESIDUAL
            break
        if refresh:
            step = _factor_kernel(kdata, mass_kdata, coef, slot, accumulate, zero_slots, base, lrun_ptr,
                                  lrun_lo, lrun_hi, urun_ptr, urun_lo, urun_hi, blk_ptr, env, inv_diag,
                                  pivot_tol, lu_stats)
            if step >= 0 or not lu_stats[0] > 0.0 or lu_stats[1] < min_pivot_ratio * lu_stats[0]:
                tan[0] = 0.0
                code = PIVOT
                break
            tan[0] = 1.0
            tan[1] = coef
            tan[2] = 0.0
            tan[3] += 1.0
        _solve_kernel(rf, perm, base, lrun_ptr, lrun_lo, lrun_hi, urun_ptr, urun_lo, urun_hi, env, inv_diag,
                      lu_work, dq)
        inc = apply_increment(q, free, dq, -1.0, inv_scale)
        if not math.isfinite(inc):
            code = NON_FINITE_INCREMENT
            break
        if inc <= tol:
            code = OK
            break
        refresh = (not modified) or inc > contraction * prev_inc
        prev_inc = inc
    update_rates(q, q_hat, at_n, a_n, v_n, c_tilde, am, af, gamma, dt, a, v, atil)
    kin = 0.0
    grav = 0.0
    if code == OK:
        kin, grav = _energies(m_indptr, m_indices, m_data, v, q, q0, gravity)
    # -- the step guard ------------------------------------------------------------------------------
    if code == OK and guarded:
        jmin, smin, emin = frame_orientation(q, edofs, act, lam, gphi, gdphi, inv_det0, inv_len0)
        if jmin <= 0.0:
            code = INVERTED
            io[IO_X] = jmin
            io[IO_AUX] = emin
        elif smin < par[P_SVK]:
            code = SVK_LIMIT
            io[IO_X] = smin
        else:
            extra_p = 0.0
            extra_size = 0.0
            check_balance = balance and led[2] == t_n
            if damped:          # viscous work by the trapezoidal rule (StepGuard.dynamic)
                wv = (diss - diss_p) / (2.0 * c_v)
                extra_p += wv
                extra_size += abs(wv)
            g, x, y, e_end = dynamic_guard(q, dq, free, dof_scale, ivec, gvec, int(led[0]), react, int(led[1]),
                                           m_indptr, m_indices, m_data, f_ext, r, rf, a, v, drive_ids, c_m, c_v,
                                           tol, par[P_CMASS], par[P_RISE], par[P_BAL], u_p, strain, 1.0, extra_p,
                                           extra_size, 0.0, kin, led[3], check_balance)
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
        for i in range(n):         # the step's start, for the integrator's policy
            q[i] = q_n[i]
            v[i] = v_n[i]
            a[i] = a_n[i]
            atil[i] = at_n[i]
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


# Model fields frame_step accounts for (used, or checked empty above). A field added to Model
# later keeps a model on the Python path whenever it is not empty, until it is looked at here.
_KNOWN_MODEL_FIELDS = frozenset((
    "scene", "ndof", "q0", "dof_scale", "free", "free_index", "indptr", "indices", "mass_kdata", "mass_csr",
    "frame_groups", "truss", "moments", "load_vectors", "load_signals", "gravity_vector", "gravity_signal",
    "actuators", "members", "node_names", "node_ydofs", "mass_damping", "total_mass", "drives", "program",
    "program_index", "nsys", "corner_dofs", "corner_alpha", "corner_smap", "hinge_dofs", "hinge_alpha",
    "hinge_beta", "hinge_smap", "node_lookup", "member_lookup", "shell_groups", "shells", "tie_dofs",
    "tie_alpha", "tie_smap"))


def _empty(value) -> bool:
    return value is None or (hasattr(value, "__len__") and len(value) == 0)


class FastFrameStep:
    """The numba step of :func:`frame_step`, bound to one integrator's model, workspace, solver
    and guard (everything it touches is allocated here or there, once)."""

    @staticmethod
    def unsupported(model: Model, spec: SolverSpec) -> str:
        """'' when :func:`frame_step` covers every step of this model, else what it lacks."""
        if spec.analysis != "dynamic" or spec.integrator not in ("newmark", "generalized_alpha"):
            return f"integrator {spec.integrator}"
        if spec.on_unconverged == "accept_flagged":
            return "on_unconverged: accept_flagged (keeps the failed iterate, which the kernel does not)"
        if len(model.frame_groups) > 1:
            return f"{len(model.frame_groups)} frame groups"
        if getattr(model, "shell_groups", ()):
            return "shell elements"
        if model.drives is not None:
            return "driven supports"
        if model.n_multipliers:
            return "Lagrange multipliers"
        mo = model.moments
        if mo.follower_vdofs.shape[0] or mo.cons_vdofs.shape[0]:
            return "moment loads"
        unknown = [f.name for f in dataclasses.fields(model)
                   if f.name not in _KNOWN_MODEL_FIELDS and not _empty(getattr(model, f.name))]
        if unknown:
            return f"model features this step does not know: {', '.join(unknown)}"
        return ""

    def __init__(self, integ):
        m, ws = integ.model, integ.ws
        self.integ = integ
        self.model = m
        if m.frame_groups:
            g, st, gst = m.frame_groups[0], ws.frame_structure[0], integ.guard._stations[0]
            scratch = ws.frame_scratch[0]
        else:       # bars only: an empty frame group keeps the kernel's one signature
            g = _empty_frame_group()
            st, gst = frame_structure(g), StepGuard._frame_stations(m, g)
            scratch = frame_scratch(g.w.shape[1], g.dax.shape[2])
        tg = m.truss if m.truss is not None else _empty_truss_group()
        sky = integ.lu.skyline
        guard = integ.guard
        n = m.ndof
        lay = np.zeros((N_ITEMS, 6), dtype=np.int64)
        par = np.zeros(N_PAR)
        spec = integ.spec
        par[P_AM], par[P_AF], par[P_BETA], par[P_GAMMA] = integ.am, integ.af, integ.beta, integ.gamma
        par[P_CM], par[P_TOL], par[P_MAXIT] = m.mass_damping, spec.tolerance, spec.max_iterations
        par[P_MODIFIED] = spec.newton == "modified"
        par[P_CONTRACTION], par[P_MAXAGE] = spec.modified_contraction, spec.tangent_max_age
        par[P_SVK], par[P_RISE], par[P_BAL] = SVK_LIMIT_STRETCH, guard.rise_tolerance, guard.balance_tolerance
        par[P_CMASS], par[P_PIVTOL], par[P_MINPIV] = guard._c_mass, sky.pivot_tol, integ.lu.min_pivot_ratio
        par[P_NSEC], par[P_ACCUM] = g.nsec, sky._accumulate
        par[P_DAMPED] = bool(m.material_damping)
        mi, mj, mv = integ._mass
        cf = _Packer(lay, np.float64)
        for item, arr in ((L_DSCALE, m.dof_scale), (L_Q0, m.q0), (L_GRAV, m.gravity_vector), (L_DAX, g.dax),
                          (L_DSEC, g.dsec), (L_W, g.w), (L_MAT, g.mat), (L_PAR, par), (L_MV, mv), (L_TL0, tg.l0),
                          (L_TEA, tg.ea), (L_TTAU, tg.tau)):
            cf.add(item, arr)
        ci = _Packer(lay, np.int64)
        for item, arr in ((L_FREE, m.free), (L_EDOFS, g.edofs), (L_ACT, g.act), (L_SMAP, g.smap), (L_MI, mi),
                          (L_MJ, mj), (L_TEDOFS, tg.edofs), (L_TACT, tg.act), (L_TSMAP, tg.smap)):
            ci.add(item, arr)
        wf = _Packer(lay, np.float64)
        for item, arr in ((L_INVS, integ._inv_scale), (L_MASSK, m.mass_kdata), (L_PHIST, st[1]),
                          (L_DPHIST, st[2]), (L_SPT, st[3]), (L_HACC, st[5]), (L_GACC, st[6]), (L_TK, st[7]),
                          (L_TG, st[8])):
            wf.add(item, arr)
        for item, arr in zip(range(L_D, L_KN + 1), scratch):
            wf.add(item, np.zeros_like(arr))                  # own scratch, same shapes
        for item, arr in zip((L_GPHI, L_GDPHI, L_GIDET, L_GILEN), gst):
            wf.add(item, arr)
        for item, arr in ((L_VEVAL, np.zeros(n)), (L_WBUF, np.zeros(n)), (L_RF, np.zeros(m.nsys)),
                          (L_DQ, np.zeros(m.nsys)), (L_KDATA, np.zeros(m.nnz)), (L_IVEC, np.zeros((7, n))),
                          (L_LUWORK, np.zeros(sky.n)), (L_TQE, np.zeros(6)), (L_TVE, np.zeros(6)),
                          (L_TRE, np.zeros(6)), (L_TKE, np.zeros((6, 6)))):
            wf.add(item, arr)
        wi = _Packer(lay, np.int64)
        for item, arr in ((L_SLOT, sky._slot), (L_ZSLOT, sky._zero_slots),
                          (L_BASE, sky._base), (L_LRP, sky._lrun[0]), (L_LRL, sky._lrun[1]), (L_LRH, sky._lrun[2]),
                          (L_URP, sky._urun[0]), (L_URL, sky._urun[1]), (L_URH, sky._urun[2]),
                          (L_BLK, sky._blk_ptr), (L_PERM, sky.perm), (L_STRAIGHT, st[0]), (L_BLOCKS, st[4]),
                          (L_DRIVE, guard._drive_ids)):
            wi.add(item, arr)
        self._lay = lay
        self._packs = (cf.build(False), ci.build(False), wf.build(True), wi.build(True))
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
        # from this time on every load signal is constant (a finished ramp, a constant), so f_ext,
        # once formed there, stays: no signal is evaluated any more
        sigs = list(m.load_signals) + ([m.gravity_signal] if self._gravity else [])
        self._still_after = max([_constant_after(x) for x in sigs], default=-math.inf)
        self._still = False

    def invalidate(self) -> None:
        """Someone else (the Python path, ``initialize``) formed ``f_ext``: recompute it next time."""
        self._scales[:] = math.nan
        self._g_scale = math.nan
        self._still = False

    def loads(self, t: float) -> None:
        """``f_ext`` at ``t`` as :func:`~flexmb_core.model.assembly.update_load_scales` forms it
        (the same operations: bit-identical), recomputed only when a signal changed."""
        if self._still:
            return
        m, ws = self.model, self.integ.ws
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
        f_ext, r, env, inv_diag, stats = self._shared
        cf, ci, wf, wi = self._packs
        code = frame_step(state.q, state.v, state.a, state.atil, lam, rates, f_ext, r, env, inv_diag, stats,
                          guard._gvec, guard._react, cf, ci, wf, wi, self._lay, tan, guard._led, self._io, t_n, dt,
                          guard.enabled, balance)
        if tan[0] != 0.0:
            lu._active = lu.skyline
            lu.skyline._factored = True
        it, rel, inc, strain, kin, grav = self._io[:IO_X].tolist()
        integ.ws.dissipation = self._io[IO_DISS]
        if code == OK:
            state.t = t_n + dt
            integ.accept_stretches(t_n, t_n + dt)
            return StepResult(True, int(it), rel, inc, 1, kin, strain, grav)
        if lam.size:                    # the step's start, for the integrator's policy
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
            member = m.members[int(m.frame_groups[0].member[int(io[IO_AUX])])].name
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


def _empty_frame_group() -> FrameGroup:
    """A frame group of no elements (linear, one point), for models of bars only."""
    i0 = np.zeros(0, dtype=np.int64)
    return FrameGroup(order=1, nsec=1, edofs=np.zeros((0, 18), dtype=np.int64), dax=np.zeros((0, 1, 6, 3)),
                      dsec=np.zeros((0, 1, 6, 3)), w=np.zeros((0, 1)), mat=np.zeros((0, 7)), act=i0,
                      smap=np.zeros((0, 324), dtype=np.int64), member=i0)


def _empty_truss_group() -> TrussGroup:
    i0 = np.zeros(0, dtype=np.int64)
    return TrussGroup(edofs=np.zeros((0, 6), dtype=np.int64), l0=np.zeros(0), ea=np.zeros(0), act=i0,
                      smap=np.zeros((0, 36), dtype=np.int64), member=i0, tau=np.zeros(0))


from ..solvers.guard import SVK_LIMIT_STRETCH, StepGuard  # noqa: E402  (after the kernel: no import cycle at compile)
