"""The corrector of path following in one numba call: Newton on ``R(x, λ) = 0`` bordered by the
arc-length or the displacement constraint.

:func:`path_correct` runs every iteration of :class:`~flexmb_core.integrators.path_following.PathFollower`'s
corrector — the loads at the load factor λ (``f_ext = λ f_ref``, moment scales λ·s⁰), the residual
and tangent of every element group, bar, shell, multiplier constraint and moment load
(:func:`~.packs.assemble_packed`), the skyline LU (:func:`~.packs.factor_packed`; static pivoting,
augmentation and refinement where the factors are suspect), the two solves ``δx_R = −K⁻¹R`` and
``δx_t = K⁻¹p`` (``p = −∂R/∂λ``, the moment loads' share evaluated at their scale s⁰: they are linear
in it), the constraint's δλ and the convergence test — on the packs of the static Newton
(:class:`~.static_step.NumbaStatic`). Python calls it once per attempted increment, and for the
plain Newton at a fixed load factor that starts the path (``control = FIXED``).

The arc-length root is the one whose increment turns least from the increment so far (Crisfield's
choice); weights, tolerances and messages are those the Python corrector had (its dot products
over the position mask were numpy's pairwise sums, these are loop sums: the last bits of a path may
differ).
"""

from __future__ import annotations

import math

from numba import njit

from ..jit import KERNEL
from ..kernels.moments import conservative_moments, follower_moments
from .fast import NO_CONVERGENCE, NON_FINITE_INCREMENT, NON_FINITE_RESIDUAL, OK, SINGULAR
from .packs import (L_CAXES, L_CMAG, L_DQ, L_FMBODY, L_FREE, L_FSCALE, L_FSMAP, L_FVDOFS, L_INVS, L_KDATA, L_KDUMMY,
                    L_MSCALE, L_MSMAP, L_MVDOFS, L_PAR, L_RC, L_RF, L_VEVAL, L_ZLAM, P_MAXIT, P_NMULT, P_TOL,
                    assemble_packed, factor_packed, solve_packed, view1, view2, view3)

# Return codes beyond fast.py's: no real root of the arc-length constraint; the controlled
# displacement does not respond to the load.
NO_ROOT, NO_RESPONSE = 8, 9
# ``control`` values: arc length; a fixed load factor (the start); ≥ 0: the system row whose
# displacement is controlled.
ARC, FIXED = -1, -2
# Output slots of io.
PO_IT, PO_INC, PO_LAM, PO_DISC, PO_OMEGA, N_PO = range(6)


@njit(nogil=True, **KERNEL)
def path_correct(q, lam_act, mult, f_ext, r, env, inv_diag, lu_stats, wmask, dx_acc, f_ref, s_fol0, s_cons0, rm, pt,
                 d_t, lam, dl, c2, lam_point, lam_scale, control, cf, ci, wf, wi, lay, io):
    """Corrector iterations of one increment, from the predicted ``q``, ``mult``, ``lam``.

    ``q (ndof,)``, ``mult (nmult,)`` in/out (the new point on success, the last iterate
    otherwise: the caller restores the increment's start); ``lam_act (na,)`` the actuators'
    stretches; ``f_ext, r (ndof,)`` the workspace's loads and internal forces; ``env, inv_diag,
    lu_stats`` the static solver's skyline factors; ``wmask (nfree,)`` 1.0 on the free nodal
    positions (the arc length's metric); ``dx_acc (nsys,)`` in/out the increment so far of the
    free DOFs and multipliers; ``f_ref (ndof,)`` the dead loads per unit λ; ``s_fol0, s_cons0``
    the moment loads' scales per unit λ; ``rm (ndof,)``, ``pt, d_t (nsys,)`` scratch (``p`` of :func:`load_direction` in ``rm``); ``lam`` the
    load factor of the prediction; ``dl`` the increment's length (m); ``c2 = ψ² ‖u₁‖²`` the
    spherical arc length's load weight; ``lam_point`` the load factor of the last converged point;
    ``lam_scale`` the first increment's |Δλ| (the convergence test's scale for δλ); ``control``
    :data:`ARC`, :data:`FIXED` or the controlled system row. ``io`` out (``PO_*``): iterations,
    last scaled increment, load factor, the discriminant of a rootless constraint, the largest
    backward error of the solves.

    Returns ``OK``, ``NO_CONVERGENCE``, ``NON_FINITE_RESIDUAL``, ``NON_FINITE_INCREMENT``,
    ``SINGULAR``, :data:`NO_ROOT` or :data:`NO_RESPONSE`.
    """
    par = view1(cf, lay[L_PAR])
    free = view1(ci, lay[L_FREE])
    kdata = view1(wf, lay[L_KDATA])
    rf = view1(wf, lay[L_RF])
    d_r = view1(wf, lay[L_DQ])
    rc = view1(wf, lay[L_RC])
    inv_scale = view1(wf, lay[L_INVS])
    zero_v = view1(wf, lay[L_VEVAL])
    zero_lam = view1(wf, lay[L_ZLAM])
    fscale = view1(wf, lay[L_FSCALE])
    mscale = view1(wf, lay[L_MSCALE])
    f_vdofs = view2(ci, lay[L_FVDOFS])
    m_vdofs = view2(ci, lay[L_MVDOFS])
    kdummy = view1(wf, lay[L_KDUMMY])
    tol = par[P_TOL]
    max_it = int(par[P_MAXIT])
    nmult = int(par[P_NMULT])
    nf = free.size
    # bools from data, not literals (one signature per kernel: tests/unit/test_signatures.py)
    no_k = tol < 0.0
    want_k = not no_k
    inc = math.inf
    code = NO_CONVERGENCE
    it = 0
    io[PO_OMEGA] = 0.0
    for it in range(1, max_it + 1):
        for i in range(fscale.size):
            fscale[i] = lam * s_fol0[i]
        for i in range(mscale.size):
            mscale[i] = lam * s_cons0[i]
        for i in range(f_ext.size):
            f_ext[i] = lam * f_ref[i]
        assemble_packed(q, zero_v, lam_act, zero_lam, 0.0, want_k, no_k, mult, r, kdata, cf, ci, wf, wi, lay, par)
        finite = True
        for k in range(nf):
            i = free[k]
            rf[k] = -(r[i] - f_ext[i])
            if not math.isfinite(rf[k]):
                finite = False
        viol = 0.0
        for i in range(nmult):
            rf[nf + i] = -rc[i]
            if not math.isfinite(rc[i]):
                finite = False
            viol = max(viol, abs(rc[i]))
        if not finite:
            code = NON_FINITE_RESIDUAL
            break
        if not factor_packed(kdata, kdata, 0.0, env, inv_diag, lu_stats, nmult, wf, wi, lay, par):
            code = SINGULAR
            break
        io[PO_OMEGA] = max(io[PO_OMEGA], solve_packed(rf, d_r, env, inv_diag, lu_stats, wf, wi, lay, par))
        dlam = 0.0
        if control != FIXED:
            load_direction(q, f_ref, s_fol0, s_cons0, f_vdofs, view2(cf, lay[L_FMBODY]), view2(ci, lay[L_FSMAP]),
                           m_vdofs, view3(cf, lay[L_CAXES]), view1(cf, lay[L_CMAG]), view2(ci, lay[L_MSMAP]), no_k,
                           rm, kdummy)
            for k in range(nf):
                pt[k] = rm[free[k]]
            for i in range(nmult):
                pt[nf + i] = 0.0
            io[PO_OMEGA] = max(io[PO_OMEGA], solve_packed(pt, d_t, env, inv_diag, lu_stats, wf, wi, lay, par))
            if control >= 0:
                if abs(d_t[control]) < 1e-300:
                    code = NO_RESPONSE
                    break
                dlam = -d_r[control] / d_t[control]
            else:
                dlam, disc = _arc_root(d_r, d_t, dx_acc, wmask, lam - lam_point, c2, dl)
                if not math.isfinite(dlam):
                    io[PO_DISC] = disc
                    code = NO_ROOT
                    break
        finite = True
        inc = 0.0
        for k in range(nf + nmult):
            x = d_r[k] + dlam * d_t[k] if control != FIXED else d_r[k]
            if not math.isfinite(x):
                finite = False
            d_r[k] = x
        if not finite:
            code = NON_FINITE_INCREMENT
            break
        for k in range(nf):
            q[free[k]] += d_r[k]
            inc = max(inc, abs(d_r[k]) * inv_scale[k])
        for i in range(nmult):
            mult[i] += d_r[nf + i]
        for k in range(nf + nmult):
            dx_acc[k] += d_r[k]
        lam += dlam
        lam_ref = max(abs(lam), lam_scale, 1e-300)
        if inc <= tol and viol <= tol and abs(dlam) <= tol * lam_ref:
            code = OK
            break
    io[PO_IT] = it
    io[PO_INC] = inc
    io[PO_LAM] = lam
    return code


@njit(nogil=True, **KERNEL)
def load_direction(q, f_ref, s_fol0, s_cons0, f_vdofs, f_mbody, f_smap, m_vdofs, m_axes, m_mag, m_smap, no_k, p,
                   kdummy):
    """``p = −∂R/∂λ (ndof,)`` at ``q``, into ``p``: the dead loads per unit λ ``f_ref`` minus the
    moment loads' internal-force share at their scales per unit λ ``s_fol0, s_cons0`` (the moment
    kernels are linear in the scale, so one evaluation is exact). The follower and conservative
    moments' arrays as in :mod:`flexmb_core.kernels.moments`; ``no_k`` False (no tangent),
    ``kdummy`` their unused tangent argument."""
    for i in range(p.size):
        p[i] = 0.0
    if f_vdofs.shape[0]:
        follower_moments(q, f_vdofs, f_mbody, s_fol0, f_smap, no_k, p, kdummy)
    if m_vdofs.shape[0]:
        conservative_moments(q, m_vdofs, m_axes, m_mag, s_cons0, m_smap, no_k, p, kdummy)
    for i in range(p.size):
        p[i] = f_ref[i] - p[i]


@njit(nogil=True, **KERNEL)
def _arc_root(d_r, d_t, dx, wmask, dlam_so_far, c2, dl):
    """δλ of the arc-length constraint ‖Δx + δx_R + δλ δx_t‖²_w + c2 (Δλ + δλ)² = dl²: of its two
    roots the one whose increment turns least from ``dx`` (the largest Δx·Δx_new + load term);
    ``(nan, discriminant)`` when it has no real root."""
    a = c2
    vt = 0.0
    vv = 0.0
    xv = 0.0
    xt = 0.0
    for k in range(wmask.size):
        if wmask[k] != 0.0:
            v = dx[k] + d_r[k]
            a += d_t[k] * d_t[k]
            vt += v * d_t[k]
            vv += v * v
            xv += dx[k] * v
            xt += dx[k] * d_t[k]
    b = 2.0 * (vt + c2 * dlam_so_far)
    c = vv + c2 * dlam_so_far * dlam_so_far - dl * dl
    disc = b * b - 4.0 * a * c
    if not disc >= 0.0 or not a > 0.0:
        return math.nan, disc
    qr = -0.5 * (b + math.copysign(math.sqrt(disc), b))
    root = qr / a
    if qr != 0.0:
        other = c / qr
        base = xv + c2 * dlam_so_far * dlam_so_far
        slope = xt + c2 * dlam_so_far
        if base + other * slope > base + root * slope:
            root = other
    return root, disc
