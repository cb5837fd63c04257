"""Positional 3D frame element (SPEC §1): residual, tangent, strain energy, actuator stretch,
Kelvin–Voigt material damping.

Nodal unknowns per node: position Y and two generalized section vectors V1, V2, ordered
``q_e = [Y¹, V1¹, V2¹, Y², …]`` (``9 n`` values). The deformation gradient in the local
reference frame is ``F = Qᵀ D̃`` with ``Q`` the ``(3n, 3)`` matrix of nodal vectors and
``D̃ = Dax/λ + Dsec`` precomputed per integration point (``λ`` is the actuator stretch, 1 for a
passive member; it scales the axial reference coordinate, SPEC §4.2, and the weight by ``λ``).

Constitutive law: the local "frame" Saint-Venant–Kirchhoff law of SPEC §1.2 (no Poisson coupling,
so no Poisson locking), with the station shear split that gives torsion ``GJ`` and uniform shear
``k_s G A`` at the same time.

Material damping (Kelvin–Voigt): the second Piola–Kirchhoff stress is ``S = C : (E + τ Ė)`` with
the retardation time ``τ = η / E`` (``mat[6]``, s) and the Green–Lagrange strain rate
``Ė = sym(Fᵀ Ḟ)``, ``Ḟ = Q̇ᵀ D̃ + Qᵀ dD̃/dλ λ̇`` (the commanded stretch rate ``λ̇`` of an actuator
moves its reference, so commanded extension is not damped). ``Ė`` vanishes under any rigid
velocity field (``Ḟ = W F``, ``W`` skew), so rigid-body motion is not damped. The viscous force is
the gradient of the dissipation potential ``D = ½ ∫ τ Ė : C : Ė dV``; its dissipation ``2D ≥ 0``
(the same quadratic form as the strain energy). In the linear limit every mode gets the damping
ratio ``ζ = ω τ / 2``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .scatter import scatter_matrix

# Columns of the per-element material table ``mat[e]``.
MAT_E, MAT_ET, MAT_G, MAT_GT, MAT_KT, MAT_KS, MAT_TAU = 0, 1, 2, 3, 4, 5, 6
N_MAT = 7


@njit(cache=True)
def frame_element(qe, ve, dax, dsec, w, nsec, mat, lam, lam_rate, c_v, want_k, want_dlam,
                  d, fp, fd, ep, ed, bmat, bdot, gbar, gdot, re, ke, kn):
    """Residual, tangent, energy and dissipation of one positional frame element.

    Parameters
    ----------
    qe, ve : (9n,) float64 — element unknowns [Y, V1, V2] per node (m, –, –) and their rates.
    dax, dsec : (nip, 3n, 3) float64 — axial / section parts of D̃ per integration point.
    w : (nip,) float64 — reference volume weights (m³) at λ = 1.
    nsec : int — section points per axial station (points are station-major).
    mat : (7,) float64 — E, E_t, G, G_t (Pa), κ_t = J/I_p, k_s, τ = η/E (s; 0: undamped).
    lam, lam_rate : float — actuator stretch λ = L_cmd / L_0 (1 for passive elements) and dλ/dt (1/s).
    c_v : float — ∂v/∂q of the integrator (γ/(βΔt); 0 in statics): the tangent is
        ∂r/∂q + c_v ∂r/∂v. Only damped elements depend on v.
    want_k, want_dlam : bool — compute the tangent / the force conjugate to λ.
    d, fp, fd, ep, ed, bmat, bdot, gbar, gdot : scratch (nip,3n,3), (nip,3,3) ×2, (nip,6) ×2,
        (6,9n) ×2, (2,9n) ×2.
    re : (9n,) float64 — out: internal force ∂U/∂q_e + ∂D/∂v_e (N, N·m).
    ke : (9n, 9n) float64 — out: tangent (written only if ``want_k``; symmetric unless damped).
    kn : (9n, 9n) float64 — scratch for the non-symmetric damping part of the tangent.

    Returns
    -------
    (U, dU/dλ + ∂D/∂λ̇, 2D) : strain energy (J), generalized force conjugate to λ at fixed q, v
    (J), and the dissipated power (W, ≥ 0).
    """
    nip = w.shape[0]
    nv = dax.shape[1]
    nloc = 3 * nv
    e_ax = mat[0]
    e_t = mat[1]
    g_mod = mat[2]
    g_t = mat[3]
    kap_t = mat[4]
    k_s = mat[5]
    tau = mat[6]
    visc = tau > 0.0
    g_pt = g_mod * kap_t           # point shear modulus: gives G·J in torsion
    c_st = g_mod * (k_s - kap_t)   # station-average shear modulus: tops uniform shear up to k_s·G·A
    inv = 1.0 / lam
    mdl = -lam_rate * inv * inv    # dD̃/dt = mdl · Dax
    kfac = 1.0 + tau * c_v         # symmetric material part: C (B + τ c_v B)
    re[:] = 0.0
    if want_k:
        ke[:, :] = 0.0
        if visc:
            kn[:, :] = 0.0
    energy = 0.0
    dudlam = 0.0
    diss = 0.0

    # Pass 1: F, E (and Ḟ, Ė) at every point (the station averages need all points of a station).
    for p in range(nip):
        for a in range(nv):
            for j in range(3):
                d[p, a, j] = dax[p, a, j] * inv + dsec[p, a, j]
        for i in range(3):
            for j in range(3):
                s = 0.0
                for a in range(nv):
                    s += qe[3 * a + i] * d[p, a, j]
                fp[p, i, j] = s
        for (k, i, j) in ((0, 0, 0), (1, 1, 1), (2, 2, 2), (3, 0, 1), (4, 0, 2), (5, 1, 2)):
            c = 0.0
            for m in range(3):
                c += fp[p, m, i] * fp[p, m, j]
            if i == j:
                c -= 1.0
            ep[p, k] = 0.5 * c
        if visc:
            for i in range(3):
                for j in range(3):
                    s = 0.0
                    for a in range(nv):
                        s += ve[3 * a + i] * d[p, a, j]
                    if mdl != 0.0:
                        for a in range(nv):
                            s += qe[3 * a + i] * dax[p, a, j] * mdl
                    fd[p, i, j] = s
            for (k, i, j) in ((0, 0, 0), (1, 1, 1), (2, 2, 2), (3, 0, 1), (4, 0, 2), (5, 1, 2)):
                c = 0.0
                for m in range(3):
                    c += fd[p, m, i] * fp[p, m, j] + fp[p, m, i] * fd[p, m, j]
                ed[p, k] = 0.5 * c

    nst = nip // nsec
    for st in range(nst):
        p0 = st * nsec
        wsum = 0.0
        g01 = 0.0
        g02 = 0.0
        h01 = 0.0
        h02 = 0.0
        for p in range(p0, p0 + nsec):
            wl = w[p] * lam
            wsum += wl
            g01 += wl * 2.0 * ep[p, 3]
            g02 += wl * 2.0 * ep[p, 4]
            if visc:
                h01 += wl * 2.0 * ed[p, 3]
                h02 += wl * 2.0 * ed[p, 4]
        g01 /= wsum
        g02 /= wsum
        h01 /= wsum
        h02 /= wsum
        energy += 0.5 * c_st * wsum * (g01 * g01 + g02 * g02)
        tau01 = c_st * (g01 + tau * h01)
        tau02 = c_st * (g02 + tau * h02)
        if visc:
            diss += tau * c_st * wsum * (h01 * h01 + h02 * h02)
        if want_k:
            gbar[:, :] = 0.0
            if visc:
                gdot[:, :] = 0.0

        for p in range(p0, p0 + nsec):
            wl = w[p] * lam
            e00 = ep[p, 0]
            e11 = ep[p, 1]
            e22 = ep[p, 2]
            y01 = 2.0 * ep[p, 3]
            y02 = 2.0 * ep[p, 4]
            y12 = 2.0 * ep[p, 5]
            energy += wl * 0.5 * (e_ax * e00 * e00 + e_t * (e11 * e11 + e22 * e22)
                                  + g_pt * (y01 * y01 + y02 * y02) + g_t * y12 * y12)
            if visc:
                r00 = ed[p, 0]
                r11 = ed[p, 1]
                r22 = ed[p, 2]
                r01 = 2.0 * ed[p, 3]
                r02 = 2.0 * ed[p, 4]
                r12 = 2.0 * ed[p, 5]
                diss += tau * wl * (e_ax * r00 * r00 + e_t * (r11 * r11 + r22 * r22)
                                    + g_pt * (r01 * r01 + r02 * r02) + g_t * r12 * r12)
                e00 += tau * r00
                e11 += tau * r11
                e22 += tau * r22
                y01 += tau * r01
                y02 += tau * r02
                y12 += tau * r12
            s00 = e_ax * e00
            s11 = e_t * e11
            s22 = e_t * e22
            s01 = g_pt * y01 + tau01
            s02 = g_pt * y02 + tau02
            s12 = g_t * y12
            f00 = fp[p, 0, 0]; f01 = fp[p, 0, 1]; f02 = fp[p, 0, 2]
            f10 = fp[p, 1, 0]; f11 = fp[p, 1, 1]; f12 = fp[p, 1, 2]
            f20 = fp[p, 2, 0]; f21 = fp[p, 2, 1]; f22 = fp[p, 2, 2]
            # First Piola–Kirchhoff P = F S (S symmetric, local frame, elastic + viscous).
            p00 = f00 * s00 + f01 * s01 + f02 * s02
            p01 = f00 * s01 + f01 * s11 + f02 * s12
            p02 = f00 * s02 + f01 * s12 + f02 * s22
            p10 = f10 * s00 + f11 * s01 + f12 * s02
            p11 = f10 * s01 + f11 * s11 + f12 * s12
            p12 = f10 * s02 + f11 * s12 + f12 * s22
            p20 = f20 * s00 + f21 * s01 + f22 * s02
            p21 = f20 * s01 + f21 * s11 + f22 * s12
            p22 = f20 * s02 + f21 * s12 + f22 * s22
            for a in range(nv):
                da0 = d[p, a, 0]
                da1 = d[p, a, 1]
                da2 = d[p, a, 2]
                re[3 * a] += wl * (p00 * da0 + p01 * da1 + p02 * da2)
                re[3 * a + 1] += wl * (p10 * da0 + p11 * da1 + p12 * da2)
                re[3 * a + 2] += wl * (p20 * da0 + p21 * da1 + p22 * da2)

            if want_dlam:
                # dF/dλ = −Qᵀ Dax / λ², and S : sym(Fᵀ dF) = P : dF with P = F S. With damping,
                # S includes τ C:Ė, which adds ∂D/∂λ̇ (∂Ė/∂λ̇ = ∂E/∂λ).
                sde = 0.0
                for i in range(3):
                    pi0 = p00 if i == 0 else (p10 if i == 1 else p20)
                    pi1 = p01 if i == 0 else (p11 if i == 1 else p21)
                    pi2 = p02 if i == 0 else (p12 if i == 1 else p22)
                    df0 = 0.0
                    df1 = 0.0
                    df2 = 0.0
                    for a in range(nv):
                        qa = qe[3 * a + i]
                        df0 += qa * dax[p, a, 0]
                        df1 += qa * dax[p, a, 1]
                        df2 += qa * dax[p, a, 2]
                    sde -= (pi0 * df0 + pi1 * df1 + pi2 * df2) * inv * inv
                dudlam += wl * sde

            if want_k:
                for a in range(nv):
                    da0 = d[p, a, 0]
                    da1 = d[p, a, 1]
                    da2 = d[p, a, 2]
                    for i in range(3):
                        fi0 = fp[p, i, 0]
                        fi1 = fp[p, i, 1]
                        fi2 = fp[p, i, 2]
                        col = 3 * a + i
                        bmat[0, col] = fi0 * da0
                        bmat[1, col] = fi1 * da1
                        bmat[2, col] = fi2 * da2
                        bmat[3, col] = fi0 * da1 + fi1 * da0
                        bmat[4, col] = fi0 * da2 + fi2 * da0
                        bmat[5, col] = fi1 * da2 + fi2 * da1
                for k in range(6):
                    if k == 0:
                        ck = wl * e_ax
                    elif k < 3:
                        ck = wl * e_t
                    elif k < 5:
                        ck = wl * g_pt
                    else:
                        ck = wl * g_t
                    ck *= kfac
                    for r in range(nloc):
                        br = ck * bmat[k, r]
                        if br != 0.0:
                            for c in range(r, nloc):
                                ke[r, c] += br * bmat[k, c]
                for r in range(nloc):
                    gbar[0, r] += wl * bmat[3, r]
                    gbar[1, r] += wl * bmat[4, r]
                if visc:
                    # B̃ = ∂Ė/∂q at fixed v: bmat(Ḟ, D̃) + bmat(F, dD̃/dt); non-symmetric part τ Bᵀ C B̃.
                    for a in range(nv):
                        da0 = d[p, a, 0]
                        da1 = d[p, a, 1]
                        da2 = d[p, a, 2]
                        xa0 = mdl * dax[p, a, 0]
                        xa1 = mdl * dax[p, a, 1]
                        xa2 = mdl * dax[p, a, 2]
                        for i in range(3):
                            fi0 = fp[p, i, 0]
                            fi1 = fp[p, i, 1]
                            fi2 = fp[p, i, 2]
                            hi0 = fd[p, i, 0]
                            hi1 = fd[p, i, 1]
                            hi2 = fd[p, i, 2]
                            col = 3 * a + i
                            bdot[0, col] = hi0 * da0 + fi0 * xa0
                            bdot[1, col] = hi1 * da1 + fi1 * xa1
                            bdot[2, col] = hi2 * da2 + fi2 * xa2
                            bdot[3, col] = hi0 * da1 + hi1 * da0 + fi0 * xa1 + fi1 * xa0
                            bdot[4, col] = hi0 * da2 + hi2 * da0 + fi0 * xa2 + fi2 * xa0
                            bdot[5, col] = hi1 * da2 + hi2 * da1 + fi1 * xa2 + fi2 * xa1
                    for k in range(6):
                        if k == 0:
                            ck = wl * e_ax * tau
                        elif k < 3:
                            ck = wl * e_t * tau
                        elif k < 5:
                            ck = wl * g_pt * tau
                        else:
                            ck = wl * g_t * tau
                        for r in range(nloc):
                            br = ck * bmat[k, r]
                            if br != 0.0:
                                for c in range(nloc):
                                    kn[r, c] += br * bdot[k, c]
                    for r in range(nloc):
                        gdot[0, r] += wl * bdot[3, r]
                        gdot[1, r] += wl * bdot[4, r]
                # Geometric part: δ_ij · w d_a S d_bᵀ (S elastic + viscous)
                for a in range(nv):
                    da0 = d[p, a, 0]
                    da1 = d[p, a, 1]
                    da2 = d[p, a, 2]
                    sa0 = s00 * da0 + s01 * da1 + s02 * da2
                    sa1 = s01 * da0 + s11 * da1 + s12 * da2
                    sa2 = s02 * da0 + s12 * da1 + s22 * da2
                    for b in range(a, nv):
                        gab = wl * (sa0 * d[p, b, 0] + sa1 * d[p, b, 1] + sa2 * d[p, b, 2])
                        for i in range(3):
                            ke[3 * a + i, 3 * b + i] += gab
        if want_k and c_st != 0.0:
            cw = c_st / wsum
            for r in range(nloc):
                g0 = cw * kfac * gbar[0, r]
                g1 = cw * kfac * gbar[1, r]
                for c in range(r, nloc):
                    ke[r, c] += g0 * gbar[0, c] + g1 * gbar[1, c]
            if visc:
                for r in range(nloc):
                    g0 = cw * tau * gbar[0, r]
                    g1 = cw * tau * gbar[1, r]
                    for c in range(nloc):
                        kn[r, c] += g0 * gdot[0, c] + g1 * gdot[1, c]
    if want_k:
        for r in range(nloc):
            for c in range(r + 1, nloc):
                ke[c, r] = ke[r, c]
        if visc:
            for r in range(nloc):
                for c in range(nloc):
                    ke[r, c] += kn[r, c]
    if want_dlam:
        dudlam += energy * inv
    return energy, dudlam, diss


@njit(cache=True)
def frame_group(q, v, edofs, dax, dsec, w, nsec, mat, act, lam_act, lam_rate, c_v, smap, want_k,
                want_dlam, r, kdata, d, fp, fd, ep, ed, bmat, bdot, gbar, gdot, qe, ve, re, ke, kn):
    """Loop over one frame group: gather, element kernel, scatter into ``r`` and CSR ``kdata``.

    ``v (ndof,)`` rates of the unknowns (read only for damped elements); ``edofs (ne, 9n)`` global
    DOF ids; ``act (ne,)`` actuator id or −1; ``lam_act, lam_rate`` stretch and stretch rate per
    actuator; ``smap (ne, (9n)²)`` position of each local entry in ``kdata`` (−1: prescribed).
    ``want_dlam`` must be passed in (False) rather than written as a literal: a literal constant
    in a call between njit functions is typed ``Literal[bool]`` and compiles a second signature.
    Returns the group's strain energy (J) and dissipated power (W).
    """
    ne = edofs.shape[0]
    nloc = edofs.shape[1]
    energy = 0.0
    diss = 0.0
    for e in range(ne):
        for i in range(nloc):
            qe[i] = q[edofs[e, i]]
        if mat[e, 6] > 0.0:
            for i in range(nloc):
                ve[i] = v[edofs[e, i]]
        lam = 1.0
        lrate = 0.0
        if act[e] >= 0:
            lam = lam_act[act[e]]
            lrate = lam_rate[act[e]]
        u, _, de = frame_element(qe, ve, dax[e], dsec[e], w[e], nsec, mat[e], lam, lrate, c_v, want_k,
                                 want_dlam, d, fp, fd, ep, ed, bmat, bdot, gbar, gdot, re, ke, kn)
        energy += u
        diss += de
        for i in range(nloc):
            r[edofs[e, i]] += re[i]
        if want_k:
            scatter_matrix(smap[e], ke, kdata)
    return energy, diss


@njit(cache=True)
def frame_group_actuator_dudlam(q, v, edofs, dax, dsec, w, nsec, mat, act, lam_act, lam_rate, c_v, want_k,
                                want_dlam, out, d, fp, fd, ep, ed, bmat, bdot, gbar, gdot, qe, ve, re, ke, kn):
    """Accumulate dU/dλ (+ ∂D/∂λ̇ for damped elements) of every actuated element into
    ``out[actuator]`` (J).

    Callers pass ``want_k = False, want_dlam = True`` (as arguments, see :func:`frame_group`)."""
    ne = edofs.shape[0]
    nloc = edofs.shape[1]
    for e in range(ne):
        if act[e] < 0:
            continue
        for i in range(nloc):
            qe[i] = q[edofs[e, i]]
        if mat[e, 6] > 0.0:
            for i in range(nloc):
                ve[i] = v[edofs[e, i]]
        _, dl, _ = frame_element(qe, ve, dax[e], dsec[e], w[e], nsec, mat[e], lam_act[act[e]],
                                 lam_rate[act[e]], c_v, want_k, want_dlam, d, fp, fd, ep, ed, bmat, bdot,
                                 gbar, gdot, re, ke, kn)
        out[act[e]] += dl


def frame_scratch(nip: int, nv: int) -> tuple[np.ndarray, ...]:
    """Scratch buffers for :func:`frame_group` (allocated once per model, never in the loop):
    d, fp, fd, ep, ed, bmat, bdot, gbar, gdot, qe, ve, re, ke, kn."""
    nloc = 3 * nv
    return (np.zeros((nip, nv, 3)), np.zeros((nip, 3, 3)), np.zeros((nip, 3, 3)), np.zeros((nip, 6)),
            np.zeros((nip, 6)), np.zeros((6, nloc)), np.zeros((6, nloc)), np.zeros((2, nloc)),
            np.zeros((2, nloc)), np.zeros(nloc), np.zeros(nloc), np.zeros(nloc), np.zeros((nloc, nloc)),
            np.zeros((nloc, nloc)))
