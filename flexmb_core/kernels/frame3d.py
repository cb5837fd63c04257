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

from ..jit import KERNEL
from .scatter import scatter_matrix

# Columns of the per-element material table ``mat[e]``.
MAT_E, MAT_ET, MAT_G, MAT_GT, MAT_KT, MAT_KS, MAT_TAU = 0, 1, 2, 3, 4, 5, 6
N_MAT = 7


@njit(**KERNEL)
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


# Block recipes of the straight element's tangent (see straight_frame_element): for row and
# column vector types (Y, V1, V2) of a node pair, the station accumulators that enter, with the
# factor kind (0: u_l·u_m, 1: u_l·φ_m, 2: φ_l·u_m, 3: φ_l·φ_m) and whether the 3×3 accumulator
# enters transposed. Rows 0–8, the symmetric part (material + geometric), accumulators
# 0 M0, 1 M1, 2 M2, 3 M11, 4 M12, 5 M22 (H00 times 1, s1, s2, s1², s1 s2, s2²), 6–8 H01 × (1, s1,
# s2), 9–11 H02 × (1, s1, s2), 12 H11, 13 H12, 14 H22. Rows 9–17, the non-symmetric viscous part
# τ Bᵀ C B̃ of damped elements (no transposes: N_jl ≠ N_ljᵀ), accumulators 15–20 N00 × (1, s1, s2,
# s1², s1 s2, s2²), 21–23 N01 × (1, s1, s2), 24–26 N02 × …, 27–29 N10 × …, 30–32 N20 × …, 33 N11,
# 34 N12, 35 N21, 36 N22.
_BLOCK = np.array([
    [[0, 0, 0], [-1, 0, 0], [-1, 0, 0], [-1, 0, 0]],          # Y,  Y
    [[1, 0, 0], [6, 1, 0], [-1, 0, 0], [-1, 0, 0]],           # Y,  V1
    [[2, 0, 0], [9, 1, 0], [-1, 0, 0], [-1, 0, 0]],           # Y,  V2
    [[1, 0, 0], [6, 2, 1], [-1, 0, 0], [-1, 0, 0]],           # V1, Y
    [[3, 0, 0], [7, 1, 0], [7, 2, 1], [12, 3, 0]],            # V1, V1
    [[4, 0, 0], [10, 1, 0], [8, 2, 1], [13, 3, 0]],           # V1, V2
    [[2, 0, 0], [9, 2, 1], [-1, 0, 0], [-1, 0, 0]],           # V2, Y
    [[4, 0, 0], [8, 1, 0], [10, 2, 1], [13, 3, 1]],           # V2, V1
    [[5, 0, 0], [11, 1, 0], [11, 2, 1], [14, 3, 0]],          # V2, V2
    [[15, 0, 0], [-1, 0, 0], [-1, 0, 0], [-1, 0, 0]],         # Y,  Y   (viscous, non-symmetric)
    [[16, 0, 0], [21, 1, 0], [-1, 0, 0], [-1, 0, 0]],         # Y,  V1
    [[17, 0, 0], [24, 1, 0], [-1, 0, 0], [-1, 0, 0]],         # Y,  V2
    [[16, 0, 0], [27, 2, 0], [-1, 0, 0], [-1, 0, 0]],         # V1, Y
    [[18, 0, 0], [22, 1, 0], [28, 2, 0], [33, 3, 0]],         # V1, V1
    [[19, 0, 0], [25, 1, 0], [29, 2, 0], [34, 3, 0]],         # V1, V2
    [[17, 0, 0], [30, 2, 0], [-1, 0, 0], [-1, 0, 0]],         # V2, Y
    [[19, 0, 0], [23, 1, 0], [31, 2, 0], [35, 3, 0]],         # V2, V1
    [[20, 0, 0], [26, 1, 0], [32, 2, 0], [36, 3, 0]],         # V2, V2
], dtype=np.int64)

# Section monomials, in the order of the station Gram matrix and of the accumulators: 1, s1, s2,
# s1², s1 s2, s2². _PROD[k, m] is the index of the product of the linear monomials k, m ∈ (1, s1, s2).
_PROD = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]], dtype=np.int64)

# Scratch layout of the straight kernel. gacc (N_GACC,): 0–14 the geometric (stress) accumulators,
# then the 6×6 Gram matrix Σ w·mono_i·mono_j of the station at _GR (row-major). hacc (N_HACC, 3, 3):
# 0–36 the tangent accumulators of _BLOCK, then per-station vectors (rows of 3×3 slots) from _SV on.
_GR = 15
N_GACC = _GR + 36
_SV = 37
_SV_F, _SV_B, _SV_H, _SV_BD, _SV_HH, _SV_BH, _SV_R, _SV_T, _SV_H3 = (_SV + k for k in range(9))
_SV_U = _SV + 9            # 6 slots: U[mm][k] = Σ_m G[mm, k·m] c_m  (c_m the coefficients of F̃[:, 0])
_SV_UH = _SV_U + 6         # 6 slots: the same with the coefficients of ĥ0 (viscous tangent)
_SV_X = _SV_UH + 6         # 18 slots: the block kinds combined with a row node's factors, per block type
N_HACC = _SV_X + 18


@njit(**KERNEL)
def _station_gram(s_pt, w, p0, nsec, lam, gacc):
    """Gram matrix Σ w·λ·mono_i·mono_j of the section monomials (1, s₁, s₂, s₁², s₁s₂, s₂²) over the
    station's points ``p0 … p0 + nsec − 1`` into ``gacc[_GR:_GR + 36]`` (row-major, symmetric)."""
    for i in range(36):
        gacc[_GR + i] = 0.0
    for p in range(p0, p0 + nsec):
        s1 = s_pt[p, 0]
        s2 = s_pt[p, 1]
        wl = w[p] * lam
        mo = (1.0, s1, s2, s1 * s1, s1 * s2, s2 * s2)
        for i in range(6):
            wi = wl * mo[i]
            for j in range(i, 6):
                gacc[_GR + 6 * i + j] += wi * mo[j]
    for i in range(6):
        for j in range(i):
            gacc[_GR + 6 * i + j] = gacc[_GR + 6 * j + i]


@njit(**KERNEL)
def station_grams(s_pt, w, nsec, gacc, out):
    """``out (ne, nst, 36)``: every straight element's station Gram matrices at λ = 1, once per
    model — what :func:`straight_frame_element` computes at every call of an element at λ = 1
    (passive elements, actuators at rest), by the same function: the same numbers."""
    for e in range(out.shape[0]):
        for st in range(out.shape[1]):
            _station_gram(s_pt[e], w[e], st * nsec, nsec, 1.0, gacc)
            for i in range(36):
                out[e, st, i] = gacc[_GR + i]


@njit(**KERNEL)
def straight_frame_element(qe, ve, phi_st, dphi_st, s_pt, w, nsec, mat, lam, lam_rate, c_v, want_k, want_dlam,
                           blocks, hacc, gacc, tk, tg, gram, re, ke):
    """Residual, tangent, energy and dissipation of one straight frame element, undamped or
    Kelvin–Voigt damped, passive or actuated, from the structure of its kinematics: the same
    integrals as :func:`frame_element` (equal to round-off), in fewer operations.

    For a straight element with constant section vectors, ``A⁰ = R₀ diag(|X'|, 1, 1)``, so ``D̃``
    has two non-zeros per row and the deformation gradient is affine in the section coordinates,
    ``F̃(s) = [c + s₁a + s₂b, B₁, B₂]`` with ``c, a, b = (Y', V₁', V₂')/λ`` (per |X'|) and
    ``B = ΣφV`` at each axial station; its rate ``Ḟ`` likewise (``Ḟ[:, 0] = h_c + s₁h_a + s₂h_b``
    including the ``−λ̇/λ`` term of a moving reference, ``Ḃ = ΣφV̇``). Strains and stresses are
    then polynomials in ``(s₁, s₂)``: ``E₀₀, Ė₀₀, S₀₀`` of degree 2, the axial–section shears of
    degree 1, the rest constant. Every through-section integral the element needs (energy,
    dissipation, residual, tangent) is a polynomial of degree ≤ 4 integrated with the element's
    own section rule, so it is evaluated *exactly as that rule would*, from the rule's moments
    ``Σ w s₁ᵖ s₂ʳ`` (p + r ≤ 4, the 6×6 Gram matrix of the monomials 1, s₁, s₂, s₁², s₁s₂, s₂²)
    and the polynomial coefficients: algebraically identical to the point-by-point sum, with a
    cost independent of the number of section points. (The shipped rules are also exact for
    degree 4, sections.py, so these are the exact section integrals.)

    Tangent ``∂r/∂q + c_v ∂r/∂v``: the symmetric part ``(1 + τc_v) Bᵀ C B`` + geometric (elastic +
    viscous stress) from the station accumulators of ``_BLOCK`` rows 0–8; for damped elements the
    non-symmetric ``τ Bᵀ C B̃`` (``B̃ = ∂Ė/∂q`` at fixed ``v``) from rows 9–17. The station shear
    split is the general kernel's, its rank-two tangent folded into the same block kinds. Same
    parameters as :func:`frame_element`, except:

    phi_st, dphi_st : (nst, n) — φ_ℓ and φ'_ℓ/|X'| (1/m) at the axial stations.
    s_pt : (nip, 2) — section coordinates (s₁, s₂) of the points (m).
    blocks : (18, 4, 3) int64 — ``_BLOCK``.
    hacc : (N_HACC, 3, 3), gacc : (N_GACC,) — scratch (station accumulators, Gram matrix,
        station vectors; layout at ``_GR``, ``_SV``).
    tk : (9, 4, 3, 3), tg : (9, 4) — scratch (the accumulators combined per block kind).
    gram : (nst, 36) — the element's station Gram matrices at λ = 1 (:func:`station_grams`), read
        instead of summed over the section points when ``lam == 1``.

    Returns
    -------
    (U, dU/dλ + ∂D/∂λ̇, 2D) as :func:`frame_element` (the second only if ``want_dlam``).
    """
    nip = w.shape[0]
    nn = phi_st.shape[1]
    nloc = 9 * nn
    e_ax = mat[0]
    e_t = mat[1]
    g_pt = mat[2] * mat[4]
    g_t = mat[3]
    c_st = mat[2] * (mat[5] - mat[4])
    tau = mat[6]
    visc = tau > 0.0
    inv = 1.0 / lam
    mdl = -lam_rate * inv * inv     # dD̃/dt = mdl · Dax, as in frame_element
    rho = lam_rate * inv            # ∂Ḟ[:, 0]/∂q = −ρ ∂F̃[:, 0]/∂q (the moving reference)
    kfac = 1.0 + tau * c_v
    re[:] = 0.0
    if want_k:
        ke[:, :] = 0.0
    energy = 0.0
    dudlam = 0.0
    diss = 0.0
    fv = hacc[_SV_F]     # rows c, a, b: F̃[:, 0] = c + s1 a + s2 b
    bv = hacc[_SV_B]     # rows B1, B2 (F̃[:, 1], F̃[:, 2])
    hv = hacc[_SV_H]     # rows h_c, h_a, h_b: Ḟ[:, 0]
    bd = hacc[_SV_BD]    # rows Ḃ1, Ḃ2
    hh = hacc[_SV_HH]    # rows of ĥ0 = Ḟ[:, 0] − ρ F̃[:, 0] (∂Ė/∂F̃[:, 0] at fixed v)
    bh = hacc[_SV_BH]    # rows ĥ1, ĥ2 = Ḃ − ρ B
    rs = hacc[_SV_R]     # rows Σ w s^m P[:, 0], m = 1, s1, s2
    ts = hacc[_SV_T]     # rows Σ w P[:, 1], Σ w P[:, 2]
    h3 = hacc[_SV_H3]    # rows Σ w s^m Ḟ[:, 0]
    nst = nip // nsec
    for st in range(nst):
        p0 = st * nsec
        # Gram matrix of the monomials over the station's section points (weights w·λ)
        if lam == 1.0:
            for i in range(36):
                gacc[_GR + i] = gram[st, i]
        else:
            _station_gram(s_pt, w, p0, nsec, lam, gacc)
        wsum = gacc[_GR]
        # station vectors (and rates)
        for i in range(3):
            y = 0.0
            x1 = 0.0
            x2 = 0.0
            z1 = 0.0
            z2 = 0.0
            for l in range(nn):
                dp = dphi_st[st, l]
                ph = phi_st[st, l]
                k = 9 * l + i
                y += dp * qe[k]
                x1 += dp * qe[k + 3]
                x2 += dp * qe[k + 6]
                z1 += ph * qe[k + 3]
                z2 += ph * qe[k + 6]
            fv[0, i] = y * inv
            fv[1, i] = x1 * inv
            fv[2, i] = x2 * inv
            bv[0, i] = z1
            bv[1, i] = z2
            if visc:
                yd = 0.0
                x1d = 0.0
                x2d = 0.0
                z1d = 0.0
                z2d = 0.0
                for l in range(nn):
                    dp = dphi_st[st, l]
                    ph = phi_st[st, l]
                    k = 9 * l + i
                    yd += dp * ve[k]
                    x1d += dp * ve[k + 3]
                    x2d += dp * ve[k + 6]
                    z1d += ph * ve[k + 3]
                    z2d += ph * ve[k + 6]
                hv[0, i] = yd * inv + mdl * y
                hv[1, i] = x1d * inv + mdl * x1
                hv[2, i] = x2d * inv + mdl * x2
                bd[0, i] = z1d
                bd[1, i] = z2d
                for k in range(3):
                    hh[k, i] = hv[k, i] - rho * fv[k, i]
                bh[0, i] = z1d - rho * z1
                bh[1, i] = z2d - rho * z2
        # strains as polynomials: E00 (coefficients of the 6 monomials), γ01, γ02 (of 1, s1, s2)
        cc = 0.0; ca = 0.0; cb = 0.0; aa = 0.0; ab = 0.0; bb = 0.0
        c1 = 0.0; a1 = 0.0; b1 = 0.0; c2 = 0.0; a2 = 0.0; b2 = 0.0
        n11 = 0.0; n22 = 0.0; n12 = 0.0
        for i in range(3):
            fc = fv[0, i]; fa = fv[1, i]; fb = fv[2, i]; v1 = bv[0, i]; v2 = bv[1, i]
            cc += fc * fc; ca += fc * fa; cb += fc * fb; aa += fa * fa; ab += fa * fb; bb += fb * fb
            c1 += fc * v1; a1 += fa * v1; b1 += fb * v1
            c2 += fc * v2; a2 += fa * v2; b2 += fb * v2
            n11 += v1 * v1; n22 += v2 * v2; n12 += v1 * v2
        e00 = (0.5 * (cc - 1.0), ca, cb, 0.5 * aa, ab, 0.5 * bb)
        e11 = 0.5 * (n11 - 1.0)
        e22 = 0.5 * (n22 - 1.0)
        y12 = n12
        y01 = (c1, a1, b1)
        y02 = (c2, a2, b2)
        r00 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        r11 = 0.0
        r22 = 0.0
        r12 = 0.0
        r01 = (0.0, 0.0, 0.0)
        r02 = (0.0, 0.0, 0.0)
        if visc:
            # Ė = sym(F̃ᵀ Ḟ): Ė00 = F̃0·Ḟ0 (degree 2), γ̇0α = Ḟ0·Bα + F̃0·Ḃα (degree 1), the rest constant
            d00 = 0.0; d01 = 0.0; d02 = 0.0; d03 = 0.0; d04 = 0.0; d05 = 0.0
            u1c = 0.0; u1a = 0.0; u1b = 0.0; u2c = 0.0; u2a = 0.0; u2b = 0.0
            m11 = 0.0; m22 = 0.0; m12 = 0.0
            for i in range(3):
                fc = fv[0, i]; fa = fv[1, i]; fb = fv[2, i]; v1 = bv[0, i]; v2 = bv[1, i]
                gc = hv[0, i]; ga = hv[1, i]; gb = hv[2, i]; w1 = bd[0, i]; w2 = bd[1, i]
                d00 += fc * gc
                d01 += fc * ga + fa * gc
                d02 += fc * gb + fb * gc
                d03 += fa * ga
                d04 += fa * gb + fb * ga
                d05 += fb * gb
                u1c += gc * v1 + fc * w1; u1a += ga * v1 + fa * w1; u1b += gb * v1 + fb * w1
                u2c += gc * v2 + fc * w2; u2a += ga * v2 + fa * w2; u2b += gb * v2 + fb * w2
                m11 += v1 * w1; m22 += v2 * w2; m12 += v1 * w2 + w1 * v2
            r00 = (d00, d01, d02, d03, d04, d05)
            r11 = m11
            r22 = m22
            r12 = m12
            r01 = (u1c, u1a, u1b)
            r02 = (u2c, u2a, u2b)
        # station shear split (averages of γ01, γ02 and their rates), and the integrals of the
        # quadratic forms: Σ w p(s)² = pᵀ G p for a polynomial p with coefficients in the monomials
        sg1 = 0.0; sg2 = 0.0; sh1 = 0.0; sh2 = 0.0
        q_e = 0.0; q_r = 0.0; q_y = 0.0; q_d = 0.0
        for i in range(3):
            gi = gacc[_GR + i]
            sg1 += gi * y01[i]
            sg2 += gi * y02[i]
            sh1 += gi * r01[i]
            sh2 += gi * r02[i]
            for j in range(3):
                gij = gacc[_GR + 6 * i + j]
                q_y += gij * (y01[i] * y01[j] + y02[i] * y02[j])
                q_d += gij * (r01[i] * r01[j] + r02[i] * r02[j])
        for i in range(6):
            for j in range(6):
                gij = gacc[_GR + 6 * i + j]
                q_e += gij * e00[i] * e00[j]
                q_r += gij * r00[i] * r00[j]
        g01 = sg1 / wsum
        g02 = sg2 / wsum
        h01 = sh1 / wsum
        h02 = sh2 / wsum
        energy += 0.5 * c_st * wsum * (g01 * g01 + g02 * g02)
        energy += 0.5 * (e_ax * q_e + g_pt * q_y + wsum * (e_t * (e11 * e11 + e22 * e22) + g_t * y12 * y12))
        if visc:
            diss += tau * c_st * wsum * (h01 * h01 + h02 * h02)
            diss += tau * (e_ax * q_r + g_pt * q_d + wsum * (e_t * (r11 * r11 + r22 * r22) + g_t * r12 * r12))
        tau01 = c_st * (g01 + tau * h01)
        tau02 = c_st * (g02 + tau * h02)
        # stress polynomials (elastic + viscous, local frame) and their section integrals against
        # the monomials: gacc[0:6] = Σ w mono S00, [6:9] = Σ w s^m S01, [9:12] = … S02, [12:15] =
        # W·(S11, S12, S22) — the geometric accumulators of _BLOCK, also what the residual needs
        s11 = e_t * (e11 + tau * r11)
        s22 = e_t * (e22 + tau * r22)
        s12 = g_t * (y12 + tau * r12)
        for i in range(6):
            z = 0.0
            for j in range(6):
                z += gacc[_GR + 6 * i + j] * e_ax * (e00[j] + tau * r00[j])
            gacc[i] = z
        for i in range(3):
            z1 = gacc[_GR + 6 * i] * tau01
            z2 = gacc[_GR + 6 * i] * tau02
            for j in range(3):
                gij = gacc[_GR + 6 * i + j]
                z1 += gij * g_pt * (y01[j] + tau * r01[j])
                z2 += gij * g_pt * (y02[j] + tau * r02[j])
            gacc[6 + i] = z1
            gacc[9 + i] = z2
        gacc[12] = wsum * s11
        gacc[13] = wsum * s12
        gacc[14] = wsum * s22
        # P = F̃ S by columns: Σ w s^m P[:,0] = Σ_k c_k Σ w s^m s^k S00 + B1 Σ w s^m S01 + B2 Σ w s^m S02,
        # Σ w P[:,1] = Σ_k c_k Σ w s^k S01 + W (B1 S11 + B2 S12), Σ w P[:,2] likewise
        for i in range(3):
            v1 = bv[0, i]
            v2 = bv[1, i]
            for m in range(3):
                z = v1 * gacc[6 + m] + v2 * gacc[9 + m]
                for k in range(3):
                    z += fv[k, i] * gacc[_PROD[m, k]]
                rs[m, i] = z
            t1 = v1 * gacc[12] + v2 * gacc[13]
            t2 = v1 * gacc[13] + v2 * gacc[14]
            for k in range(3):
                t1 += fv[k, i] * gacc[6 + k]
                t2 += fv[k, i] * gacc[9 + k]
            ts[0, i] = t1
            ts[1, i] = t2
        # residual: Y rows take P[:,0]·φ'/|X'|λ, V rows add s·P[:,0] and P[:,1|2]·φ
        for l in range(nn):
            u = dphi_st[st, l] * inv
            ph = phi_st[st, l]
            k = 9 * l
            for i in range(3):
                re[k + i] += u * rs[0, i]
                re[k + 3 + i] += u * rs[1, i] + ph * ts[0, i]
                re[k + 6 + i] += u * rs[2, i] + ph * ts[1, i]
        if want_dlam:
            # dF̃/dλ = −F̃[:, 0] e₀ᵀ/λ, so ∂U/∂λ|_q (+ ∂D/∂λ̇) = −Σ w P[:, 0]·F̃[:, 0]/λ (+ U/λ, below)
            pf = 0.0
            for m in range(3):
                for i in range(3):
                    pf += fv[m, i] * rs[m, i]
            dudlam -= pf * inv
        if not want_k:
            continue
        # symmetric accumulators 0–14 (material part × (1 + τ c_v)): U[mm][k] = Σ_m G[mm, k·m] c_m
        # gives Σ w mono_mm F̃0 F̃0ᵀ = Σ_k c_k U[mm][k]ᵀ, and Σ w s^m F̃0 = U[m][0]
        for mm in range(6):
            um = hacc[_SV_U + mm]
            for k in range(3):
                for j in range(3):
                    z = 0.0
                    for m in range(3):
                        z += gacc[_GR + 6 * mm + _PROD[k, m]] * fv[m, j]
                    um[k, j] = z
        for mm in range(6):
            um = hacc[_SV_U + mm]
            gm = gacc[_GR + mm]
            for i in range(3):
                for j in range(3):
                    ff = fv[0, i] * um[0, j] + fv[1, i] * um[1, j] + fv[2, i] * um[2, j]
                    hacc[mm, i, j] = kfac * (e_ax * ff + g_pt * gm * (bv[0, i] * bv[0, j] + bv[1, i] * bv[1, j]))
                    if mm == 0:
                        b11 = bv[0, i] * bv[0, j]
                        b22 = bv[1, i] * bv[1, j]
                        hacc[12, i, j] = kfac * (wsum * (e_t * b11 + g_t * b22) + g_pt * ff)
                        hacc[13, i, j] = kfac * wsum * g_t * bv[1, i] * bv[0, j]
                        hacc[14, i, j] = kfac * (wsum * (e_t * b22 + g_t * b11) + g_pt * ff)
        for m in range(3):
            u3 = hacc[_SV_U + m]          # row 0: Σ w s^m F̃0
            for i in range(3):
                for j in range(3):
                    hacc[6 + m, i, j] = kfac * g_pt * bv[0, i] * u3[0, j]
                    hacc[9 + m, i, j] = kfac * g_pt * bv[1, i] * u3[0, j]
        if visc:
            # non-symmetric accumulators 15–36: N_jl = Σ_k C_k ∂ε_k/∂F̃[:, j] ⊗ ∂ε̇_k/∂F̃[:, l] (fixed v)
            for mm in range(6):
                um = hacc[_SV_UH + mm]
                for k in range(3):
                    for j in range(3):
                        z = 0.0
                        for m in range(3):
                            z += gacc[_GR + 6 * mm + _PROD[k, m]] * hh[m, j]
                        um[k, j] = z
            for m in range(3):
                for j in range(3):
                    z = 0.0
                    for k in range(3):
                        z += gacc[_GR + 6 * m + k] * hv[k, j]
                    h3[m, j] = z
            for mm in range(6):
                um = hacc[_SV_UH + mm]
                gm = gacc[_GR + mm]
                for i in range(3):
                    for j in range(3):
                        fh = fv[0, i] * um[0, j] + fv[1, i] * um[1, j] + fv[2, i] * um[2, j]
                        hacc[15 + mm, i, j] = tau * (e_ax * fh + g_pt * gm * (bv[0, i] * bh[0, j]
                                                                              + bv[1, i] * bh[1, j]))
            for i in range(3):
                for j in range(3):
                    fh0 = fv[0, i] * h3[0, j] + fv[1, i] * h3[1, j] + fv[2, i] * h3[2, j]   # Σ w F̃0 Ḟ0ᵀ
                    hacc[33, i, j] = tau * (wsum * (e_t * bv[0, i] * bd[0, j] + g_t * bv[1, i] * bd[1, j])
                                            + g_pt * fh0)
                    hacc[34, i, j] = tau * wsum * g_t * bv[1, i] * bd[0, j]
                    hacc[35, i, j] = tau * wsum * g_t * bv[0, i] * bd[1, j]
                    hacc[36, i, j] = tau * (wsum * (e_t * bv[1, i] * bd[1, j] + g_t * bv[0, i] * bd[0, j])
                                            + g_pt * fh0)
                    for m in range(3):
                        fs = hacc[_SV_U + m, 0, i]
                        hacc[21 + m, i, j] = tau * g_pt * bv[0, i] * h3[m, j]
                        hacc[24 + m, i, j] = tau * g_pt * bv[1, i] * h3[m, j]
                        hacc[27 + m, i, j] = tau * g_pt * fs * bh[0, j]
                        hacc[30 + m, i, j] = tau * g_pt * fs * bh[1, j]
        # per vector-type pair (ta, tb) and factor kind (u_l u_m, u_l φ_m, φ_l u_m, φ_l φ_m): the
        # 3×3 matrix that the factor multiplies, geometric part (scalar × I₃) included
        tk[:, :, :, :] = 0.0
        tg[:, :] = 0.0
        for bt in range(9):
            for zz in range(4):
                idx = blocks[bt, zz, 0]
                if idx < 0:
                    break
                kind = blocks[bt, zz, 1]
                tg[bt, kind] += gacc[idx]
                if blocks[bt, zz, 2] == 0:
                    for i in range(3):
                        for j in range(3):
                            tk[bt, kind, i, j] += hacc[idx, i, j]
                else:
                    for i in range(3):
                        for j in range(3):
                            tk[bt, kind, i, j] += hacc[idx, j, i]
            if visc:
                for zz in range(4):
                    idx = blocks[9 + bt, zz, 0]
                    if idx < 0:
                        break
                    kind = blocks[9 + bt, zz, 1]
                    for i in range(3):
                        for j in range(3):
                            tk[bt, kind, i, j] += hacc[idx, i, j]
            for kind in range(4):
                for i in range(3):
                    tk[bt, kind, i, i] += tg[bt, kind]
        if c_st != 0.0:
            # Station shear split: the general kernel's rank-two (c_st/W)(ḡ01 ḡ01ᵀ + ḡ02 ḡ02ᵀ) with
            # ḡ0α = ∂(Σ w γ0α)/∂q, and for damped elements (τ c_st/W)(ḡ0α ġ0αᵀ), ġ0α = ∂(Σ w γ̇0α)/∂q
            # at fixed v. Both gradients have the node structure u_l α_t + φ_l β_t (α_t = m_t Bα with
            # m = (W, Σws1, Σws2), β = Σ w F̃0 on the Vα rows only; ġ: ĥα and Σ w Ḟ0 instead), so
            # the term joins the block kinds (O(1) per station) instead of a dense (9n)² update.
            ck = c_st / wsum * kfac
            cn = c_st / wsum * tau
            fw = hacc[_SV_U]      # row 0: Σ w F̃0
            for ta in range(3):
                ma = gacc[_GR + ta]
                for tb in range(3):
                    mb = gacc[_GR + tb]
                    bt = 3 * ta + tb
                    for i in range(3):
                        for j in range(3):
                            x = ck * ma * mb * (bv[0, i] * bv[0, j] + bv[1, i] * bv[1, j])
                            if visc:
                                x += cn * ma * mb * (bv[0, i] * bh[0, j] + bv[1, i] * bh[1, j])
                            tk[bt, 0, i, j] += x
                            if tb > 0:
                                x = ck * ma * bv[tb - 1, i] * fw[0, j]
                                if visc:
                                    x += cn * ma * bv[tb - 1, i] * h3[0, j]
                                tk[bt, 1, i, j] += x
                            if ta > 0:
                                x = ck * fw[0, i] * mb * bv[ta - 1, j]
                                if visc:
                                    x += cn * fw[0, i] * mb * bh[ta - 1, j]
                                tk[bt, 2, i, j] += x
                            if ta > 0 and ta == tb:
                                x = ck * fw[0, i] * fw[0, j]
                                if visc:
                                    x += cn * fw[0, i] * h3[0, j]
                                tk[bt, 3, i, j] += x
        for l in range(nn):
            ul = dphi_st[st, l] * inv
            pl = phi_st[st, l]
            # row node's factors first (X_u = u_l T0 + φ_l T2, X_φ = u_l T1 + φ_l T3), then per column
            # node u_m X_u + φ_m X_φ: 2 + 2/n instead of 4 multiply-adds per entry
            for bt in range(9):
                for i in range(3):
                    for j in range(3):
                        hacc[_SV_X + 2 * bt, i, j] = ul * tk[bt, 0, i, j] + pl * tk[bt, 2, i, j]
                        hacc[_SV_X + 2 * bt + 1, i, j] = ul * tk[bt, 1, i, j] + pl * tk[bt, 3, i, j]
            # undamped: upper blocks only, mirrored at the end; damped: every block (non-symmetric)
            for m in range(0 if visc else l, nn):
                um_ = dphi_st[st, m] * inv
                pm = phi_st[st, m]
                for ta in range(3):
                    ra = 9 * l + 3 * ta
                    tb0 = ta if (m == l and not visc) else 0
                    for tb in range(tb0, 3):
                        cb = 9 * m + 3 * tb
                        x = _SV_X + 2 * (3 * ta + tb)
                        for i in range(3):
                            for j in range(3):
                                ke[ra + i, cb + j] += um_ * hacc[x, i, j] + pm * hacc[x + 1, i, j]
    if want_k and not visc:
        for r in range(nloc):
            for c in range(r + 1, nloc):
                ke[c, r] = ke[r, c]
    if want_dlam:
        dudlam += energy * inv
    return energy, dudlam, diss


@njit(**KERNEL)
def frame_group(q, v, edofs, dax, dsec, w, nsec, mat, act, lam_act, lam_rate, c_v, smap, want_k,
                want_dlam, r, kdata, d, fp, fd, ep, ed, bmat, bdot, gbar, gdot, qe, ve, re, ke, kn,
                straight, phi_st, dphi_st, s_pt, blocks, hacc, gacc, tk, tg, gram):
    """Loop over one frame group: gather, element kernel, scatter into ``r`` and CSR ``kdata``.

    ``v (ndof,)`` rates of the unknowns (read only for damped elements); ``edofs (ne, 9n)`` global
    DOF ids; ``act (ne,)`` actuator id or −1; ``lam_act, lam_rate`` stretch and stretch rate per
    actuator; ``smap (ne, (9n)²)`` position of each local entry in ``kdata`` (−1: prescribed).
    ``straight … gram`` (:func:`frame_structure`): elements flagged straight (damped or not,
    actuated or not) go through :func:`straight_frame_element`, the others (curved) through
    :func:`frame_element`.
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
        if straight[e] == 1:
            u, _, de = straight_frame_element(qe, ve, phi_st[e], dphi_st[e], s_pt[e], w[e], nsec, mat[e], lam, lrate,
                                              c_v, want_k, want_dlam, blocks, hacc, gacc, tk, tg, gram[e], re, ke)
        else:
            u, _, de = frame_element(qe, ve, dax[e], dsec[e], w[e], nsec, mat[e], lam, lrate, c_v, want_k,
                                     want_dlam, d, fp, fd, ep, ed, bmat, bdot, gbar, gdot, re, ke, kn)
        energy += u
        diss += de
        for i in range(nloc):
            r[edofs[e, i]] += re[i]
        if want_k:
            scatter_matrix(smap[e], ke, kdata)
    return energy, diss


@njit(nogil=True, **KERNEL)
def frame_group_actuator_dudlam(q, v, edofs, dax, dsec, w, nsec, mat, act, lam_act, lam_rate, c_v, want_k,
                                want_dlam, out, d, fp, fd, ep, ed, bmat, bdot, gbar, gdot, qe, ve, re, ke, kn,
                                straight, phi_st, dphi_st, s_pt, blocks, hacc, gacc, tk, tg, gram):
    """Accumulate dU/dλ (+ ∂D/∂λ̇ for damped elements) of every actuated element into
    ``out[actuator]`` (J), straight elements by :func:`straight_frame_element` as in
    :func:`frame_group` (the general kernel made the node's actuator forces cost more than its
    step: 0.43 ms per published state for the 24 legs' elements of ``stewart_platform``).
    ``nogil``: the node's publisher thread calls it beside the stepping thread.

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
        if straight[e] == 1:
            _, dl, _ = straight_frame_element(qe, ve, phi_st[e], dphi_st[e], s_pt[e], w[e], nsec, mat[e],
                                              lam_act[act[e]], lam_rate[act[e]], c_v, want_k, want_dlam, blocks,
                                              hacc, gacc, tk, tg, gram[e], re, ke)
        else:
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


def frame_structure(g, *, structured: bool = True) -> tuple[np.ndarray, ...]:
    """Per-group data of :func:`straight_frame_element` (computed once per model, from the
    group's own integration data): ``(straight (ne,) int64, phi_st (ne, nst, n), dphi_st (ne, nst,
    n), s_pt (ne, nip, 2), _BLOCK (18, 4, 3), hacc (N_HACC, 3, 3), gacc (N_GACC,), tk (9, 4, 3, 3),
    tg (9, 4), gram (ne, nst, 36))`` (``gram``: :func:`station_grams`).

    An element is flagged straight when its ``D̃`` has the structure of a straight element with
    constant section vectors (``d_Y = [φ'/|X'|, 0, 0]``, ``d_V1 = [s₁φ'/|X'|, φ, 0]``, ``d_V2 =
    [s₂φ'/|X'|, 0, φ]`` at every point, to 1e-12 of its largest entry), damped or not; curved
    elements keep :func:`frame_element`. ``structured=False`` flags none.
    """
    ne, nip, nv, _ = g.dax.shape
    n = nv // 3
    nsec = g.nsec
    nst = nip // nsec
    straight = np.zeros(ne, dtype=np.int64)
    phi_st = np.zeros((ne, nst, n))
    dphi_st = np.zeros((ne, nst, n))
    s_pt = np.zeros((ne, nip, 2))
    for e in range(ne if structured else 0):
        dax, dsec = g.dax[e], g.dsec[e]
        tol = 1e-12 * max(np.abs(dax).max(), np.abs(dsec).max())
        ok = np.abs(dax[:, :, 1:]).max() <= tol and np.abs(dsec[:, :, 0]).max() <= tol
        ok = ok and np.abs(dsec[:, 0::3, :]).max() <= tol
        ok = ok and np.abs(dsec[:, 1::3, 2]).max() <= tol and np.abs(dsec[:, 2::3, 1]).max() <= tol
        for st in range(nst):
            if not ok:
                break
            pts = slice(st * nsec, (st + 1) * nsec)
            dp = dax[st * nsec, 0::3, 0]
            ph = dsec[st * nsec, 1::3, 1]
            ok = (np.abs(dax[pts, 0::3, 0] - dp).max() <= tol and np.abs(dsec[pts, 1::3, 1] - ph).max() <= tol
                  and np.abs(dsec[pts, 2::3, 2] - ph).max() <= tol)
            nrm = float(dp @ dp)
            for p in range(st * nsec, (st + 1) * nsec):
                s1 = float(dax[p, 1::3, 0] @ dp) / nrm
                s2 = float(dax[p, 2::3, 0] @ dp) / nrm
                ok = ok and (np.abs(dax[p, 1::3, 0] - s1 * dp).max() <= tol
                             and np.abs(dax[p, 2::3, 0] - s2 * dp).max() <= tol)
                s_pt[e, p] = (s1, s2)
            phi_st[e, st] = ph
            dphi_st[e, st] = dp
        straight[e] = 1 if ok else 0
    gacc = np.zeros(N_GACC)
    gram = np.zeros((ne, nst, 36))
    station_grams(s_pt, np.ascontiguousarray(g.w), nsec, gacc, gram)
    return (straight, phi_st, dphi_st, s_pt, _BLOCK, np.zeros((N_HACC, 3, 3)), gacc, np.zeros((9, 4, 3, 3)),
            np.zeros((9, 4)), gram)
