"""Cheap physical checks of a converged Newton root (the step guard, :mod:`flexmb_core.solvers.guard`).

All a small fraction of one residual assembly (no mat-vec over the whole model):

* :func:`frame_orientation` — at the section centroid of every axial station of every frame
  element, the volume ratio ``det F = Y'·(V1×V2) / (λ det A⁰)`` and the three fibre stretches
  ``|Y'|/(λ|X'|)``, ``|V1|``, ``|V2|``. Green–Lagrange strain is blind to reflections
  (``E(−F) = E(F)``), so a Saint-Venant–Kirchhoff model has zero-energy equilibria with the
  section turned inside out; and SVK's uniaxial stress ``E(λ³ − λ)/2`` peaks at the stretch
  ``1/√3`` — below it the material is unstable and the roots found there are artefacts of the
  model, not states of a steel or rubber member.
* :func:`dynamic_guard` — the incremental potential and the energy balance of a dynamic step
  from the residuals and energies the step computed anyway.
* :func:`step_work`, :func:`drive_reactions`, :func:`conservative_moment_work`,
  :func:`energy_resolution` — the pieces (work of loads and drives, exact work of conservative
  moments, the energy resolution of a converged state).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..jit import KERNEL


@njit(**KERNEL)
def frame_orientation(q, edofs, act, lam_act, phi, dphi, inv_det0, inv_len0):
    """Smallest volume ratio and fibre stretch over a frame group's stations.

    Parameters
    ----------
    q : (ndof,) float64 — unknowns (m, –).
    edofs : (ne, 9n) int64 — element DOFs [Y, V1, V2] per node.
    act : (ne,) int64 — actuator id or −1; ``lam_act (na,)`` the stretches in force.
    phi, dphi : (ns, n) float64 — shape functions and ξ-derivatives at the ``ns`` stations.
    inv_det0 : (ne, ns) float64 — 1 / det A⁰ at the station centroids (1/m).
    inv_len0 : (ne, ns) float64 — 1 / |X'| at the stations (1/m).

    Returns
    -------
    (min det F, min fibre stretch, element of the min det F) : float, float, int.
    """
    ne = edofs.shape[0]
    ns = phi.shape[0]
    nn = phi.shape[1]
    jmin = math.inf
    smin = math.inf
    emin = -1
    for e in range(ne):
        lam = 1.0
        if act[e] >= 0:
            lam = lam_act[act[e]]
        for s in range(ns):
            y0 = 0.0; y1 = 0.0; y2 = 0.0
            a0 = 0.0; a1 = 0.0; a2 = 0.0
            b0 = 0.0; b1 = 0.0; b2 = 0.0
            for a in range(nn):
                dp = dphi[s, a]
                p = phi[s, a]
                k = 9 * a
                y0 += dp * q[edofs[e, k]]
                y1 += dp * q[edofs[e, k + 1]]
                y2 += dp * q[edofs[e, k + 2]]
                a0 += p * q[edofs[e, k + 3]]
                a1 += p * q[edofs[e, k + 4]]
                a2 += p * q[edofs[e, k + 5]]
                b0 += p * q[edofs[e, k + 6]]
                b1 += p * q[edofs[e, k + 7]]
                b2 += p * q[edofs[e, k + 8]]
            det = (y0 * (a1 * b2 - a2 * b1) + y1 * (a2 * b0 - a0 * b2) + y2 * (a0 * b1 - a1 * b0)) \
                * inv_det0[e, s] / lam
            if det < jmin:
                jmin = det
                emin = e
            st = min(math.sqrt(y0 * y0 + y1 * y1 + y2 * y2) * inv_len0[e, s] / lam,
                     math.sqrt(a0 * a0 + a1 * a1 + a2 * a2), math.sqrt(b0 * b0 + b1 * b1 + b2 * b2))
            if st < smin:
                smin = st
    return jmin, smin, emin


@njit(**KERNEL)
def step_work(q, q_n, f_ext, f_prev, r_int, a, v, c_m, m_indptr, m_indices, m_data, drive_ids, react_prev,
              react):
    """Work done on the mechanism over a step by the loads and the driven supports (J).

    Loads: trapezoidal rule ``½(f_n + f_{n+1})·(q_{n+1} − q_n)`` over every DOF (gravity
    included). Driven DOFs ``drive_ids (nd,)``: their reactions ``R = f_int + M(a + c_m v) −
    f_ext`` at the end of the step go to ``react (nd,)`` (``r_int`` the internal force of the last
    residual evaluation, ``a, v`` the end rates), and their work is ``½(R_n + R_{n+1})·Δq``.

    Returns ``(W_loads, W_drives)``.
    """
    w_ext = 0.0
    for i in range(q.size):
        d = q[i] - q_n[i]
        if d != 0.0:
            w_ext += 0.5 * (f_ext[i] + f_prev[i]) * d
    drive_reactions(r_int, a, v, c_m, m_indptr, m_indices, m_data, f_ext, drive_ids, react)
    w_drv = 0.0
    for k in range(drive_ids.size):
        i = drive_ids[k]
        w_drv += 0.5 * (react_prev[k] + react[k]) * (q[i] - q_n[i])
    return w_ext, w_drv


@njit(**KERNEL)
def drive_reactions(r_int, a, v, c_m, m_indptr, m_indices, m_data, f_ext, drive_ids, react):
    """Reactions ``R = f_int + M(a + c_m v) − f_ext`` at the driven DOFs ``drive_ids`` into
    ``react`` (N, N·m): what the prescribed motion has to supply."""
    for k in range(drive_ids.size):
        i = drive_ids[k]
        s = 0.0
        for p in range(m_indptr[i], m_indptr[i + 1]):
            j = m_indices[p]
            s += m_data[p] * (a[j] + c_m * v[j])
        react[k] = r_int[i] + s - f_ext[i]


@njit(**KERNEL)
def conservative_moment_work(q, q_p, vdofs, axes, magnitude, scale):
    """Exact work ``Σ M Δθ`` of the fixed-axis conservative moments
    (:func:`flexmb_core.kernels.moments.conservative_moments`) from ``q_p`` to ``q`` (J): ``Δθ``
    is the angle turned by the projection of the section vector in the plane ⊥ n (|Δθ| < π)."""
    w = 0.0
    for m in range(vdofs.shape[0]):
        ax = axes[m, 0]
        bx = axes[m, 1]
        x0 = 0.0; y0 = 0.0; x1 = 0.0; y1 = 0.0
        for i in range(3):
            x0 += q_p[vdofs[m, i]] * ax[i]
            y0 += q_p[vdofs[m, i]] * bx[i]
            x1 += q[vdofs[m, i]] * ax[i]
            y1 += q[vdofs[m, i]] * bx[i]
        w += magnitude[m] * scale[m] * math.atan2(x0 * y1 - y0 * x1, x0 * x1 + y0 * y1)
    return w


@njit(**KERNEL)
def energy_resolution(free, dof_scale, tol, r_int, f_ext):
    """How well the potential energy of a converged state is known (J): Newton leaves each free
    DOF uncertain by ``tol·scale_i``, which moves the work of the internal and external forces by
    ``Σ tol·scale_i (|f_int,i| + |f_ext,i|)``. (The kinetic part, ``c_v·tol·√(c_M·2K)``, is added
    by the callers that have a velocity.)"""
    s = 0.0
    for k in range(free.size):
        i = free[k]
        s += dof_scale[i] * (abs(r_int[i]) + abs(f_ext[i]))
    return tol * s


@njit(**KERNEL)
def dynamic_guard(q, dq, free, dof_scale, ivec, gvec, il, react, ir, m_indptr, m_indices, m_data, f_ext, r_int, rf,
                  a, v, drive_ids, c_m, c_v, tol, c_mass, rise_tol, bal_tol, u_p, u_last, u_scale, extra_p,
                  extra_size, w_mom, kin, e_start, balance):
    """Checks 2 and 3 of the step guard (:mod:`flexmb_core.solvers.guard`) for one converged
    dynamic step, in one call and without a mat-vec: the guard must cost little next to an
    assembly (every array argument also costs dispatch time, hence the stacked vectors).

    The inertial and external forces ``g = M(a + c_m v) − f_ext`` are affine in ``q`` during a
    step, so their work from the Newton start ``q_p`` to the last iterate ``q_l`` is exactly
    ``½ (g_p + g_l)·(q_l − q_p)``, with ``g = r − f_int`` read off the residuals of the first and
    the last iteration.

    Parameters
    ----------
    q, a, v : (ndof,) — accepted state and rates.  dq : (nsys,) — the last Newton increment (the
        last evaluated iterate is ``q + dq`` on the free DOFs).
    free, dof_scale : the model's free DOFs and increment scales.
    ivec : (7, ndof) — the integrator's rows q_n, v_n, a_n, ã_n, q̂, the Newton start q_p and
        (first nfree entries) ``g_p = M(a + c_m v) − f_ext`` there.
    gvec : (6, ndof) — the energy ledger's two sets (f, q, v): the ledger's state at ``il``, the
        candidate end state at ``3 − il`` (written here).
    react : (2, nd) — drive reactions: ledger row ``ir``, candidate row ``1 − ir`` (written).
    m_indptr, m_indices, m_data : the mass matrix (CSR; only the driven rows are read).
    f_ext, r_int, rf : loads at the end of the step; internal force and residual (free rows
        first) of the last evaluation.
    drive_ids : (nd,) driven DOFs.  c_m, c_v : mass damping (1/s) and ∂v/∂q (1/s).
    tol, c_mass : Newton tolerance; ``Σ_ij |M_ij| s_i s_j`` over the free DOFs (the kinetic
        energy resolution is ``c_v tol √(c_mass 2K)``).
    rise_tol, bal_tol : the guard's tolerances.
    u_p, u_last, u_scale : strain energy at the Newton start and last iterate; the factor of U in
        Φ (1, or 1/(1−αf) for Chung–Hulbert).
    extra_p, extra_size : the other (signed) terms of Φ(q_l) − Φ(q_p) (moments, viscous,
        multipliers) and the sum of their magnitudes (J).
    w_mom, kin, e_start : moment work over the step (q_n → q), the kinetic energy of the accepted
        state, K + U of the ledger's state (J).
    balance : bool — run check 3 (no actuator moved; it also needs the ledger at the step's
        start, ``(q_n, v_n)`` equal to the ledger's ``(q, v)``, checked here).

    Returns
    -------
    code : int — 0 accepted, 1 the incremental potential rose (check 2), 2 energy gained beyond
        the work done (check 3).
    x, y : float — (rise, size) of Φ for code 1, (gain, scale) of the balance otherwise (J).
    e_end : float — K + U of the accepted state (J), U to first order from the last iterate.
    """
    q_n = ivec[0]
    v_n = ivec[1]
    q_p = ivec[5]
    g_p = ivec[6]
    f_prev = gvec[il]
    ledger_q = gvec[il + 1]
    ledger_v = gvec[il + 2]
    ic = 3 - il
    cand_f = gvec[ic]
    cand_q = gvec[ic + 1]
    cand_v = gvec[ic + 2]
    w_in = 0.0
    w_abs = 0.0
    du = 0.0
    res = 0.0
    for k in range(free.size):
        i = free[k]
        d = q[i] + dq[k] - q_p[i]
        w = 0.5 * d * (g_p[k] + rf[k] - r_int[i])
        w_in += w
        w_abs += abs(w)
        du += r_int[i] * dq[k]
        res += dof_scale[i] * (abs(r_int[i]) + abs(f_ext[i]))
    floor = tol * res + c_v * tol * np.sqrt(c_mass * 2.0 * kin)
    # check 2: Φ(q_l) − Φ(q_p)
    rise = (u_last - u_p) * u_scale + w_in + extra_p
    size = (abs(u_last) + abs(u_p)) * u_scale + w_abs + extra_size
    e_end = kin + u_last - du
    w_ext, w_drv = step_work(q, q_n, f_ext, f_prev, r_int, a, v, c_m, m_indptr, m_indices, m_data, drive_ids,
                             react[ir], react[1 - ir])
    match = True
    for i in range(q.size):
        if q_n[i] != ledger_q[i] or v_n[i] != ledger_v[i]:
            match = False
        cand_f[i] = f_ext[i]
        cand_q[i] = q[i]
        cand_v[i] = v[i]
    if rise > rise_tol * size and rise > floor:
        return 1, rise, size, e_end
    if not (balance and match):
        return 0, 0.0, 0.0, e_end
    # check 3: K + U gained at most the work of loads and drives
    gain = e_end - e_start - (w_ext + w_drv + w_mom)
    scale = abs(e_start) + abs(w_ext) + abs(w_drv) + abs(w_mom)
    if gain > bal_tol * scale and gain > floor:
        return 2, gain, scale, e_end
    return 0, gain, scale, e_end
