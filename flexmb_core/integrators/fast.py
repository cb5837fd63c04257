"""One numba call per time step: the Newton of a dynamic step, for every element kind.

:class:`NumbaStep` runs each Newton attempt of a step of
:class:`~flexmb_core.integrators.dynamic.DynamicIntegrator` entirely inside :func:`model_step`:
predictor and driven supports, the residual and (held or refreshed) tangent of every frame group,
the bars, every shell group, the multiplier constraints (rigid corners, off-plane hinges, director
ties) and the moment loads, the inertial residual, the skyline LU factor and solve (static pivoting,
augmentation and refinement where the factors are suspect: :func:`~.packs.factor_packed`,
:func:`~.packs.solve_packed`), the modified-Newton refresh rule and the held tangent that follows
the shells' rotation (:mod:`~flexmb_core.kernels.corotation`), the rates, the energies and the
step guard's checks. It is the only Newton of dynamics: until 2026-11-29 a Python loop made the
attempts whose tangent the skyline LU handed to SuperLU, and the two were bit-identical; the
step references of that time (``tests/step_cases.py``) hold it to those results.

Every integrator: generalized-α, Newmark and the Chung–Hulbert form (kept to show it is not
objective; with multipliers it is refused, :meth:`NumbaStep.unsupported` names that). A step the
kernel cannot finish — no convergence, a refused root, a tangent that cannot be factored — leaves
the state as it was (under ``accept_flagged``: at the last iterate) and hands back to the
integrator, whose ``on_unconverged`` policy proceeds as for any failed attempt; its sub-steps are
numba steps too.

:func:`model_steps` runs several such steps in one call for :meth:`Simulator.run
<flexmb_core.simulator.Simulator.run>` when nothing changes between them that Python would set
(:meth:`NumbaStep.batches`); the arithmetic is that of as many calls of :func:`model_step`.

The arrays travel in the packs of :mod:`.packs` (:class:`~.packs.ModelPacks`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..jit import KERNEL
from ..kernels.corotation import body_rotations, rotate_triplets
from ..kernels.guard import dynamic_guard, frame_orientation
from ..model.model import Model
from ..model.step_data import (C_T, C_T_HIST, C_T_PREV, D_A, D_ATIL, D_CLOCK, D_GVEC, D_LAM, D_LAMCAND, D_LAMHIST,
                               D_LAMRATE, D_LED, D_MULT, D_Q, D_QREF, D_REACT, D_TAN, D_V)
from ..scene.schema import SolverSpec
from ..signals import evaluate
from ..solvers.result import StepResult
from .energy import _energies
from .fused import advance_stretches, apply_increment, inertial_residual, update_rates, velocity_at
from .packs import (F_ACT, F_EDOFS, F_GDPHI, F_GIDET, F_GILEN, F_GPHI, L_BI, L_BJ, L_BV, L_CP, L_DQ, L_DRIVE, L_DRVIDX,
                    L_DRVVAL, L_DSCALE, L_FPOS, L_FREE, L_FVDOFS, L_GRAV, L_INVS, L_IVEC, L_KDATA, L_LAMN, L_MASSK,
                    L_MI, L_MJ, L_MULTN, L_MV, L_MVDOFS, L_PAR, L_Q0, L_QEVAL, L_QL, L_RATEN, L_RBODY, L_RC, L_RF,
                    L_RMAT, L_RNODE, L_RRHS, L_VEVAL, L_WBUF, L_ZLAM, NF, N_PAR, P_AF, P_AM, P_BAL, P_BETA, P_CH, P_CM,
                    P_CMASS, P_CONTRACTION, P_COROT, P_DAMPED,
                    P_F0, P_GAMMA, P_KEEP, P_MAXAGE, P_MAXIT, P_MBLOCK, P_MINPIV, P_MODIFIED, P_NFG, P_NMULT, P_PIVTOL,
                    P_RISE, P_SVK, P_TOL, ModelPacks, assemble_packed, factor_packed, moment_work_packed,
                    singular_note, solve_packed, unknown_fields, view1, view2)

# Return codes of model_step.
OK, NO_CONVERGENCE, NON_FINITE_RESIDUAL, NON_FINITE_INCREMENT, SINGULAR, INVERTED, SVK_LIMIT, ENERGY = range(8)

# Output slots of io.
(IO_IT, IO_REL, IO_INC, IO_STRAIN, IO_KIN, IO_GRAV, IO_X, IO_Y, IO_EEND, IO_AUX, IO_UP, IO_DISS, IO_GROUP,
 IO_OMEGA, N_IO) = range(15)


@njit(nogil=True, **KERNEL)
def begin_stretches(d, dlay, lam_new, rate_new, rate_given, damped, dt):
    """λ_{n+1} = ``lam_new (na,)`` into the stretches of the step data ``d`` (layout ``dlay``),
    which hold λ_n on entry, and for ``damped`` models its rate λ̇_{n+1} (1/s) into its rates:
    ``rate_new (na,)`` when ``rate_given``, else the second-order backward difference over the
    stretch history (first order when the history is not that of the data's time, e.g. the first
    step after a start); λ_n is kept as the history's candidate. Returns whether any actuator
    moves in the step ``dt`` (s)."""
    clock = view1(d, dlay[D_CLOCK])
    rate = view1(d, dlay[D_LAMRATE])
    t_n = clock[C_T]
    if damped and rate_given:
        for i in range(rate.size):
            rate[i] = rate_new[i]
    difference = damped and not rate_given
    h0 = 0.0
    if difference and t_n == clock[C_T_HIST]:
        h0 = t_n - clock[C_T_PREV]
    return advance_stretches(lam_new, view1(d, dlay[D_LAM]), view1(d, dlay[D_LAMHIST]), view1(d, dlay[D_LAMCAND]),
                             rate, dt, h0, difference, damped)


@njit(nogil=True, **KERNEL)
def accept_stretches(d, dlay, t_n, t_new, damped):
    """The step ``t_n → t_new`` (s) was accepted: for ``damped`` models λ_n joins the stretch
    history of the step data ``d`` (layout ``dlay``), which now belongs to the state at ``t_new``."""
    if damped:
        lam_hist = view1(d, dlay[D_LAMHIST])
        lam_cand = view1(d, dlay[D_LAMCAND])
        for i in range(lam_hist.size):
            lam_hist[i] = lam_cand[i]
        clock = view1(d, dlay[D_CLOCK])
        clock[C_T_PREV] = t_n
        clock[C_T_HIST] = t_new


@njit(nogil=True, **KERNEL)
def model_step(d, dlay, lam_new, rate_new, rate_given, f_ext, r, env, inv_diag, lu_stats, cf, ci, wf, wi, lay, io, dt,
               guarded):
    """First Newton attempt of one dynamic step from the time ``t_n`` of the step data (see the
    module).

    ``d``: the buffer of the run's :class:`~flexmb_core.model.step_data.StepData`, ``dlay`` its
    layout table. Its time, its state ``q, v, a, atil (ndof,)`` and the multipliers ``mult
    (nmult,)`` are advanced in place on success and left unchanged otherwise. Its ``lam (na,)``
    takes the actuator stretches ``lam_new`` (λ_{n+1}) and, for damped models, its ``lam_rate``
    their rate (1/s): ``rate_new (na,)`` when ``rate_given``, else the backward difference over
    the stretch history (:func:`begin_stretches`), which moves on when the step is accepted
    (:func:`accept_stretches`); a failed step leaves λ_n and its rate. Its ``tan`` in/out: the
    held tangent [held, coefficient, age, refreshes], and ``q_ref`` the unknowns it was formed at
    (with ``P_COROT``, each shell's rotation since then rotates its solves); ``led`` in/out: the
    guard's ledger [il, ir, t, K + U, candidate K + U] (advanced here when the step is accepted)
    with its rows ``gvec, react``. The guard's energy balance (check 3) applies to steps that move no actuator. The GIL
    is released: a caller's other threads (the node's executor) run while the step does. Shared
    with the workspace and the integrator's LU: ``f_ext`` (loads at t_{n+1}, set by the caller),
    ``r`` (internal force of the last evaluation) and the skyline factors ``env, inv_diag,
    lu_stats`` (the held tangent). Everything else comes in the packs
    ``cf, ci, wf, wi`` and their layout table ``lay`` (see the module); the caller writes the
    driven supports' values at t_{n+1} and the moment scales into their ``wf`` items.

    ``dt``: the step; ``guarded``: run the step guard. ``io`` out (``IO_*``):
    iterations, relative residual, increment, strain, kinetic and gravity energy, the guard's
    values (x, y, e_end, aux: element of an inverted section or the energy check's code, and the
    frame group of that section), the strain energy at the Newton start, and the largest backward
    error of the step's linear solves (0 unless a tangent's factors were suspect,
    :func:`~.packs.solve_packed`).

    Returns one of the codes ``OK, NO_CONVERGENCE, …, ENERGY``.
    """
    clock = view1(d, dlay[D_CLOCK])
    t_n = clock[C_T]
    q = view1(d, dlay[D_Q])
    v = view1(d, dlay[D_V])
    a = view1(d, dlay[D_A])
    atil = view1(d, dlay[D_ATIL])
    lam = view1(d, dlay[D_LAM])
    mult = view1(d, dlay[D_MULT])
    tan = view1(d, dlay[D_TAN])
    led = view1(d, dlay[D_LED])
    gvec = view2(d, dlay[D_GVEC])
    react = view2(d, dlay[D_REACT])
    par = view1(cf, lay[L_PAR])
    free = view1(ci, lay[L_FREE])
    m_indptr = view1(ci, lay[L_MI])
    m_indices = view1(ci, lay[L_MJ])
    m_data = view1(cf, lay[L_MV])
    mb = int(par[P_MBLOCK])                 # M in block form for the products (packs.mass_blocks)
    b_indptr = view1(ci, lay[L_BI])
    b_indices = view1(ci, lay[L_BJ])
    b_data = view1(cf, lay[L_BV])
    free_pos = view1(ci, lay[L_FPOS])
    ivec = view2(wf, lay[L_IVEC])
    rf = view1(wf, lay[L_RF])
    dq = view1(wf, lay[L_DQ])
    kdata = view1(wf, lay[L_KDATA])
    rc = view1(wf, lay[L_RC])
    c_p = view1(wf, lay[L_CP])
    mult_n = view1(wf, lay[L_MULTN])
    inv_scale = view1(wf, lay[L_INVS])
    v_eval = view1(wf, lay[L_VEVAL])
    drv_idx = view1(ci, lay[L_DRVIDX])
    drv_val = view1(wf, lay[L_DRVVAL])
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
    damped = par[P_DAMPED] != 0.0
    # undamped: the elements read no stretch rate (a zero item, whatever the state's rates hold)
    state_rate = view1(d, dlay[D_LAMRATE])
    lam_rate = state_rate if damped else view1(wf, lay[L_ZLAM])
    nmult = int(par[P_NMULT])
    nfg = int(par[P_NFG])
    f0 = int(par[P_F0])
    # Chung–Hulbert: Newmark kinematics with a itself (ã ≡ a), inertia
    # (1−αm) a_{n+1} + αm a_n (the inertial residual with αf = 0), forces at q_{n+1−αf} (and the
    # rates blended alike), tangent (1−αf) K + (1−αm)/(βΔt²) M
    ch = par[P_CH] != 0.0
    q_eval = view1(wf, lay[L_QEVAL])
    # -- the actuator stretches λ_{n+1} and their rate ----------------------------------------------
    lam_n = view1(wf, lay[L_LAMN])
    rate_n = view1(wf, lay[L_RATEN])
    for i in range(lam.size):           # the step's start, restored if the attempt fails
        lam_n[i] = lam[i]
        rate_n[i] = state_rate[i]
    moved = begin_stretches(d, dlay, lam_new, rate_new, rate_given, damped, dt)
    # the energy balance needs forces at t_{n+1}: not for Chung–Hulbert
    balance = not moved and not ch

    # -- predictor ---------------------------------------------------------------------------------
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
    af_r = af
    af_v = 0.0
    k_scale = 1.0
    if ch:
        c_a = (1.0 - am) / (beta * dt * dt)
        af_r = 0.0
        af_v = af
        k_scale = 1.0 - af
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
    # a held tangent follows the shells' rotation since it was formed (kernels/corotation.py)
    q_ref = view1(d, dlay[D_QREF])
    rot_nodes = view2(ci, lay[L_RNODE])
    rot_ptr = view1(ci, lay[L_RBODY])
    rot = view2(wf, lay[L_RMAT])
    rot_rhs = view1(wf, lay[L_RRHS])
    corot = par[P_COROT] != 0.0
    rotated = corot and not refresh
    if rotated:
        body_rotations(q, q_ref, rot_nodes, rot_ptr, rot)
    prev_inc = math.inf
    io[IO_OMEGA] = 0.0
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
    v_k = v_eval        # undamped: stays zero, the kernels do not read it
    q_force = q_eval if ch else q     # where the forces are evaluated
    # -- Newton ------------------------------------------------------------------------------------
    for it in range(1, max_it + 1):
        if ch:
            for i in range(n):
                h = q[i] * (1.0 - af)
                h += af * q_n[i]
                q_eval[i] = h
        if damped:
            velocity_at(q, q_hat, at_n, v_n, c_tilde, gamma, dt, af_v, v_eval)
        strain, diss = assemble_packed(q_force, v_k, lam, lam_rate, c_vk, refresh, no_dlam, mult, r, kdata, cf, ci,
                                       wf, wi, lay, par)
        keep = it == 1 and guarded
        nr, ref = inertial_residual(q, q_hat, at_n, a_n, v_n, c_tilde, am, af_r, gamma, dt, c_m, mb, b_indptr,
                                    b_indices, b_data, r, f_ext, free_pos, view1(wf, lay[L_WBUF]), rf, keep, g_p)
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
            if ch:
                for i in range(kdata.size):
                    kdata[i] *= k_scale
            if not factor_packed(kdata, view1(wf, lay[L_MASSK]), coef, env, inv_diag, lu_stats, nmult, wf, wi, lay,
                                 par):
                code = SINGULAR
                break
            tan[0] = 1.0
            tan[1] = coef
            tan[2] = 0.0
            tan[3] += 1.0
            if corot:
                for i in range(n):
                    q_ref[i] = q_force[i]
                rotated = False
        # a solve that refinement could not make accurate (a singular tangent) still gives a
        # regularized direction: whether it leads to a root is the convergence test's to say
        if rotated:                 # Δq = R A₀⁻¹ Rᵀ r
            for i in range(rf.size):
                rot_rhs[i] = rf[i]
            rotate_triplets(rot_rhs, rot_nodes, rot_ptr, rot, True)
            omega = solve_packed(rot_rhs, dq, env, inv_diag, lu_stats, wf, wi, lay, par)
            rotate_triplets(dq, rot_nodes, rot_ptr, rot, False)
        else:
            omega = solve_packed(rf, dq, env, inv_diag, lu_stats, wf, wi, lay, par)
        if omega > io[IO_OMEGA]:
            io[IO_OMEGA] = omega
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
    update_rates(q, q_hat, at_n, a_n, v_n, c_tilde, 0.0 if ch else am, af_r, gamma, dt, a, v, atil)
    kin = 0.0
    grav = 0.0
    if code == OK:
        kin, grav = _energies(mb, b_indptr, b_indices, b_data, v, q, view1(cf, lay[L_Q0]), view1(cf, lay[L_GRAV]))
    # -- the step guard ------------------------------------------------------------------------------
    if code == OK and guarded:
        for k in range(nfg):
            b = f0 + k * NF
            jmin, smin, emin = frame_orientation(q, view2(ci, lay[b + F_EDOFS]), view1(ci, lay[b + F_ACT]), lam,
                                                 view2(wf, lay[b + F_GPHI]), view2(wf, lay[b + F_GDPHI]),
                                                 view2(wf, lay[b + F_GIDET]), view2(wf, lay[b + F_GILEN]))
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
        if view2(ci, lay[L_FVDOFS]).shape[0] or view2(ci, lay[L_MVDOFS]).shape[0]:
            q_l = view1(wf, lay[L_QL])           # the last evaluated iterate
            for i in range(n):
                q_l[i] = q[i]
            for k in range(nf):
                q_l[free[k]] += dq[k]
            w = moment_work_packed(q_l, q_p, no_dlam, cf, ci, wf, lay)
            extra_p = -w
            extra_size = abs(w)
            w_mom = moment_work_packed(q, q_n, no_dlam, cf, ci, wf, lay)
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
        g, x, y, e_end = dynamic_guard(q, dq, free, view1(cf, lay[L_DSCALE]), ivec, gvec, int(led[0]), react,
                                       int(led[1]), m_indptr, m_indices, m_data, f_ext, r, rf, a, v,
                                       view1(wi, lay[L_DRIVE]), c_m, c_v, tol, par[P_CMASS], par[P_RISE], par[P_BAL],
                                       u_p, strain, 1.0 / (1.0 - af_v), extra_p, extra_size, w_mom, kin, led[3],
                                       check_balance)
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
        tan[0] = 0.0               # a failed step never leaves a stale tangent behind
        if par[P_KEEP] == 0.0:
            for i in range(n):     # the step's start, for the integrator's policy
                q[i] = q_n[i]
                v[i] = v_n[i]
                a[i] = a_n[i]
                atil[i] = at_n[i]
            for i in range(nmult):
                mult[i] = mult_n[i]
        if par[P_KEEP] != 0.0:
            clock[C_T] = t_n + dt  # the failed iterate at t_{n+1}, λ_{n+1} in force (accept_flagged)
        else:
            for i in range(lam.size):
                lam[i] = lam_n[i]
                state_rate[i] = rate_n[i]
        return code
    clock[C_T] = t_n + dt
    accept_stretches(d, dlay, t_n, t_n + dt, damped)
    tan[2] += 1.0
    if guarded:                    # the guard's ledger moves to the accepted state (ledger_accept)
        led[2] = t_n + dt
        led[3] = led[4]
        led[0] = 3.0 - led[0]
        led[1] = 1.0 - led[1]
    return OK


@njit(nogil=True, **KERNEL)
def model_steps(count, loads, lams, d, dlay, lam_new, rate_new, rate_given, f_ext, r, env, inv_diag, lu_stats, cf,
                ci, wf, wi, lay, io, dt, guarded, tally):
    """Up to ``count`` steps of :func:`model_step` (same arguments), one after the other at the
    same driven supports; stops at the first that fails, which leaves the state at its start as
    :func:`model_step` does. ``loads (count, ndof)``: the loads ``f_ext`` of each step (N), copied
    in before it; ``(0, ndof)``: ``f_ext`` as it is, for every step. ``lams (count, na)``: the
    actuator stretches λ_{n+1} of each step; ``(0, na)``: ``lam_new`` for every step. ``tally (4,)``
    out: steps accepted, their Newton iterations summed, the most in one step, the largest
    relative residual. ``io`` holds the last attempt's outputs. Returns the last attempt's code."""
    code = OK
    tally[:] = 0.0
    tabulated = loads.shape[0] > 0
    commanded = lams.shape[0] > 0
    for k in range(count):
        if tabulated:
            for i in range(f_ext.size):
                f_ext[i] = loads[k, i]
        lam_k = lams[k] if commanded else lam_new
        code = model_step(d, dlay, lam_k, rate_new, rate_given, f_ext, r, env, inv_diag, lu_stats, cf, ci, wf, wi,
                          lay, io, dt, guarded)
        if code != OK:
            break
        tally[0] += 1.0
        tally[1] += io[IO_IT]
        tally[2] = max(tally[2], io[IO_IT])
        tally[3] = max(tally[3], io[IO_REL])
    return code


# Steps of one model_steps call whose loads are tabulated (a load ramp): a table of this many rows
TABLE_STEPS = 256


def _constant_after(sig) -> float:
    """Time after which ``sig`` is constant (+inf if never: sine, spin-up, tables of unknown end)."""
    if sig.kind == "constant":
        return -math.inf
    if sig.kind == "ramp":
        return sig.t0 + sig.duration
    if sig.kind == "table" and len(sig.table_t):
        return float(sig.table_t[-1])           # held outside the table
    return math.inf


class NumbaStep:
    """The numba step of :func:`model_step`, bound to one integrator's model, workspace, solver
    and guard (everything it touches is allocated here or there, once)."""

    @staticmethod
    def unsupported(model: Model, spec: SolverSpec) -> str:
        """'' when :func:`model_step` covers every step of this model, else what it lacks."""
        if spec.analysis != "dynamic":
            return f"analysis {spec.analysis}"
        if spec.integrator == "chung_hulbert" and model.n_multipliers:
            return "the chung_hulbert integrator does not support rigid corners (multipliers)"
        unknown = unknown_fields(model)
        if unknown:
            return f"model features this step does not know: {', '.join(unknown)}"
        return ""

    def __init__(self, integ):
        m, ws = integ.model, integ.ws
        self.integ = integ
        self.model = m
        mo = m.moments
        sky = integ.lu.skyline
        guard = integ.guard
        par = np.zeros(N_PAR)
        spec = integ.spec
        par[P_AM], par[P_AF], par[P_BETA], par[P_GAMMA] = integ.am, integ.af, integ.beta, integ.gamma
        par[P_CM], par[P_TOL], par[P_MAXIT] = m.mass_damping, spec.tolerance, spec.max_iterations
        par[P_MODIFIED] = spec.newton == "modified"
        par[P_CONTRACTION], par[P_MAXAGE] = spec.modified_contraction, spec.tangent_max_age
        par[P_SVK], par[P_RISE], par[P_BAL] = SVK_LIMIT_STRETCH, guard.rise_tolerance, guard.balance_tolerance
        par[P_CMASS], par[P_PIVTOL], par[P_MINPIV] = guard._c_mass, sky.pivot_tol, integ.lu.min_pivot_ratio
        par[P_DAMPED] = bool(m.material_damping)
        par[P_CH] = spec.integrator == "chung_hulbert"
        par[P_COROT] = spec.newton == "modified" and spec.held_tangent == "corotated" and bool(m.shells)
        # accept_flagged keeps a failed attempt's last iterate
        par[P_KEEP] = spec.on_unconverged == "accept_flagged"
        self.packs = ModelPacks(m, ws, sky, guard, integ._inv_scale, integ._mass, integ._mass_blocks, par)
        self._lay = self.packs.lay
        self._packs = self.packs.packs
        self._follower_scale, self._cons_scale = self.packs.follower_scale, self.packs.cons_scale
        self._io = np.zeros(N_IO)
        na = m.actuators.l0.size
        self._ch = spec.integrator == "chung_hulbert"
        self._no_rate = np.zeros(na)        # the rates argument when the caller gives none
        self._shared = (integ.data.buf, integ.data.lay, ws.f_ext, ws.r, sky._env, sky._inv_diag, sky._stats)
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
        self._tally = np.zeros(4)
        # steps that need nothing from Python between them may run in one call (attempts): none
        # with driven supports (their values move with t) or keeping failed iterates (the
        # integrator's policy starts from the step's start); while the loads change, only
        # without moment loads (their scales are items of the packs, set per step by loads())
        self._batchable = self.packs._q_drive is None and not par[P_KEEP]
        self._tabulable = self._batchable and not (mo.follower_signals or mo.cons_signals)
        self._no_table = np.zeros((0, m.ndof))
        self._no_lams = np.zeros((0, na))
        self._table: np.ndarray | None = None        # (TABLE_STEPS, ndof), on first use

    def invalidate(self) -> None:
        """Someone else (``initialize``, a sub-step) formed ``f_ext``: recompute it next time."""
        self._scales[:] = math.nan
        self._g_scale = math.nan
        self._still = False

    def loads(self, t: float) -> None:
        """``f_ext`` and the moment scales at ``t`` as
        :func:`~flexmb_core.model.assembly.update_load_scales` forms them (the same operations:
        bit-identical), ``f_ext`` recomputed only when a signal changed."""
        if self._still and t >= self._still_after:     # (a rolled-back run may come back before it)
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

    def steady(self, t: float) -> bool:
        """Whether every step from ``t`` (s) on sees the same loads and driven supports (the
        loads were formed at a time after the signals' last change)."""
        return self._batchable and self._still and t >= self._still_after

    def batches(self, t: float) -> bool:
        """Whether :meth:`attempts` may run several steps from ``t`` (s): steady ones, or ones
        whose loads it can tabulate beforehand."""
        return self._tabulable or self.steady(t)

    def attempts(self, t: float, dt: float, lam_new: np.ndarray, count: int) -> tuple[int, StepResult, np.ndarray]:
        """Attempts of steps ``dt`` from ``t`` (the time of the integrator's step data, s) in one
        numba call (:func:`model_steps`) where :meth:`batches`: up to ``count``, and up to
        :data:`TABLE_STEPS` while the loads change, whose ``f_ext`` of each step is formed first,
        as :meth:`attempt` would form it. ``lam_new``: the stretches of every step ``(na,)``, or of
        each step ``(k, na)`` (then at most k steps). The same arithmetic as as many calls of
        :meth:`attempt`. Returns the steps accepted, the last attempt's result (a failure leaves the
        state at that step's start) and the tally ``[steps, iterations, most iterations in a step,
        largest relative residual]`` of the accepted ones."""
        lams = self._no_lams
        if lam_new.ndim == 2:
            lams, lam_new = lam_new, lam_new[0]
            count = min(count, lams.shape[0])
        table = self._no_table
        if not self.steady(t):
            count = min(count, TABLE_STEPS)
            if self._table is None:
                self._table = np.zeros((TABLE_STEPS, self.model.ndof))
            table = self._table[:count]
            af = self.integ.af
            for k in range(count):      # t advances as the kernel advances it: t_n + dt
                t_new = t + dt
                self.loads(t_new - af * dt if self._ch else t_new)
                table[k] = self.integ.ws.f_ext
                t = t_new
        d, dlay, f_ext, r, env, inv_diag, stats = self._shared
        cf, ci, wf, wi = self._packs
        code = model_steps(count, table, lams, d, dlay, lam_new, self._no_rate, False, f_ext, r, env, inv_diag, stats,
                           cf, ci, wf, wi, self._lay, self._io, dt, self.integ.guard.enabled, self._tally)
        done = int(self._tally[0])
        if table.shape[0] and done < count:
            self.invalidate()           # the loads were formed for steps that did not run
        return done, self._result(code), self._tally

    def attempt(self, state, dt: float, lam_new: np.ndarray, lam_rate: np.ndarray | None = None) -> StepResult:
        """The Newton attempt of the step ``state.t → state.t + dt`` to the actuator stretches
        ``lam_new`` (rates ``lam_rate`` or, for damped models, the integrator's backward
        difference): the result, with the state advanced when converged and otherwise at the
        step's start (under ``accept_flagged``: at the last iterate). ``state``: the state of the
        integrator's step data, the only one a step advances (:meth:`DynamicIntegrator.step`
        checks it)."""
        integ = self.integ
        rate_given = lam_rate is not None
        t_n = state.t
        t_new = t_n + dt
        self.loads(t_new - integ.af * dt if self._ch else t_new)
        self.packs.drives(state.q, t_new)
        d, dlay, f_ext, r, env, inv_diag, stats = self._shared
        cf, ci, wf, wi = self._packs
        code = model_step(d, dlay, lam_new, lam_rate if rate_given else self._no_rate, rate_given, f_ext, r, env,
                          inv_diag, stats, cf, ci, wf, wi, self._lay, self._io, dt, integ.guard.enabled)
        return self._result(code)

    def _result(self, code: int) -> StepResult:
        """The result of the attempt that left ``code`` and its outputs in ``io``."""
        it, rel, inc, strain, kin, grav = self._io[:IO_X].tolist()
        self.integ.ws.dissipation = self._io[IO_DISS]
        if code == OK:
            return StepResult(True, int(it), rel, inc, 1, kin, strain, grav)
        return self._failure(code, int(it), rel, inc, strain, kin, grav)

    def _failure(self, code: int, it: int, rel: float, inc: float, strain: float, kin: float,
                 grav: float) -> StepResult:
        """The failed attempt: its message, and its flag when the step guard refused the root."""
        integ, m, spec, io = self.integ, self.model, self.integ.spec, self._io
        guard = integ.guard
        flag, message = "", ""
        if code == SINGULAR:
            message = f"singular tangent at Newton iteration {it} (a non-finite pivot, or a zero matrix)"
        elif code == NO_CONVERGENCE:
            message = (f"no convergence in {spec.max_iterations} iterations (increment {inc:.2e}, "
                       f"tolerance {spec.tolerance:.1e}){singular_note(io[IO_OMEGA])}")
        elif code == NON_FINITE_RESIDUAL:
            message = f"non-finite residual at Newton iteration {it}{singular_note(io[IO_OMEGA])}"
        elif code == NON_FINITE_INCREMENT:
            message = f"non-finite increment at Newton iteration {it}{singular_note(io[IO_OMEGA])}"
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


from ..solvers.guard import SVK_LIMIT_STRETCH  # noqa: E402  (after the kernel: no import cycle at compile)
