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


# Block recipes of the straight element's tangent (see straight_frame_element): for row and
# column vector types (Y, V1, V2) of a node pair, the station accumulators that enter, with the
# factor kind (0: u_l·u_m, 1: u_l·φ_m, 2: φ_l·u_m, 3: φ_l·φ_m) and whether the 3×3 accumulator
# enters transposed. Accumulators: 0 M0, 1 M1, 2 M2, 3 M11, 4 M12, 5 M22 (H00 times 1, s1, s2,
# s1², s1 s2, s2²), 6–8 H01 × (1, s1, s2), 9–11 H02 × (1, s1, s2), 12 H11, 13 H12, 14 H22.
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
], dtype=np.int64)


@njit(cache=True)
def straight_frame_element(qe, phi_st, dphi_st, s_pt, w, nsec, mat, lam, want_k, blocks, fp, ep, gbar, hacc,
                           gacc, tk, tg, re, ke):
    """Residual, tangent and energy of one straight, undamped frame element, from the structure
    of its kinematics (the same integrals as :func:`frame_element`, in fewer operations).

    For a straight element with constant section vectors, ``A⁰ = R₀ diag(|X'|, 1, 1)``, so ``D̃``
    has two non-zeros per row and the deformation gradient is affine in the section coordinates:
    ``F̃(s) = [(Y' + s₁V₁' + s₂V₂')/λ, V̄₁, V̄₂]`` from five vectors per axial station
    (``Y' = Σφ'Y/|X'|`` etc., ``V̄ = ΣφV``). Each section point then costs O(10²) flops instead of
    O(10³); the section sums go into station accumulators (``H_jl = Σ_k C_k G_kj G_klᵀ`` times the
    monomials 1, s₁, s₂, s₁², s₁s₂, s₂²; ``S_jl`` likewise for the geometric part), from which
    the 3×3 node blocks of the tangent follow (``_BLOCK``). The station shear split is the
    general kernel's. Same parameters as :func:`frame_element` except:

    phi_st, dphi_st : (nst, n) — φ_ℓ and φ'_ℓ/|X'| (1/m) at the axial stations.
    s_pt : (nip, 2) — section coordinates (s₁, s₂) of the points (m).
    blocks : (9, 4, 3) int64 — ``_BLOCK``.
    fp : (nip, 3, 3), ep : (nip, 6), gbar : (2, 9n) — scratch (F̃ and E at the points, the
        shear-split gradients).
    hacc : (15, 3, 3), gacc : (15,) — scratch (station accumulators).
    tk : (9, 4, 3, 3), tg : (9, 4) — scratch (the accumulators combined per block kind).

    Returns the strain energy (J).
    """
    nip = w.shape[0]
    nn = phi_st.shape[1]
    nloc = 9 * nn
    e_ax = mat[0]
    e_t = mat[1]
    g_pt = mat[2] * mat[4]
    g_t = mat[3]
    c_st = mat[2] * (mat[5] - mat[4])
    inv = 1.0 / lam
    re[:] = 0.0
    if want_k:
        ke[:, :] = 0.0
    energy = 0.0
    nst = nip // nsec
    for st in range(nst):
        p0 = st * nsec
        # five station vectors: Y', V1', V2' (per |X'|) and V̄1, V̄2
        yp0 = 0.0; yp1 = 0.0; yp2 = 0.0
        a10 = 0.0; a11 = 0.0; a12 = 0.0
        a20 = 0.0; a21 = 0.0; a22 = 0.0
        b10 = 0.0; b11 = 0.0; b12 = 0.0
        b20 = 0.0; b21 = 0.0; b22 = 0.0
        for l in range(nn):
            dp = dphi_st[st, l]
            ph = phi_st[st, l]
            k = 9 * l
            yp0 += dp * qe[k]; yp1 += dp * qe[k + 1]; yp2 += dp * qe[k + 2]
            a10 += dp * qe[k + 3]; a11 += dp * qe[k + 4]; a12 += dp * qe[k + 5]
            a20 += dp * qe[k + 6]; a21 += dp * qe[k + 7]; a22 += dp * qe[k + 8]
            b10 += ph * qe[k + 3]; b11 += ph * qe[k + 4]; b12 += ph * qe[k + 5]
            b20 += ph * qe[k + 6]; b21 += ph * qe[k + 7]; b22 += ph * qe[k + 8]
        wsum = 0.0
        g01 = 0.0
        g02 = 0.0
        for p in range(p0, p0 + nsec):
            s1 = s_pt[p, 0]
            s2 = s_pt[p, 1]
            f00 = (yp0 + s1 * a10 + s2 * a20) * inv
            f10 = (yp1 + s1 * a11 + s2 * a21) * inv
            f20 = (yp2 + s1 * a12 + s2 * a22) * inv
            fp[p, 0, 0] = f00; fp[p, 1, 0] = f10; fp[p, 2, 0] = f20
            fp[p, 0, 1] = b10; fp[p, 1, 1] = b11; fp[p, 2, 1] = b12
            fp[p, 0, 2] = b20; fp[p, 1, 2] = b21; fp[p, 2, 2] = b22
            ep[p, 0] = 0.5 * (f00 * f00 + f10 * f10 + f20 * f20 - 1.0)
            ep[p, 1] = 0.5 * (b10 * b10 + b11 * b11 + b12 * b12 - 1.0)
            ep[p, 2] = 0.5 * (b20 * b20 + b21 * b21 + b22 * b22 - 1.0)
            ep[p, 3] = 0.5 * (f00 * b10 + f10 * b11 + f20 * b12)
            ep[p, 4] = 0.5 * (f00 * b20 + f10 * b21 + f20 * b22)
            ep[p, 5] = 0.5 * (b10 * b20 + b11 * b21 + b12 * b22)
            wl = w[p] * lam
            wsum += wl
            g01 += wl * 2.0 * ep[p, 3]
            g02 += wl * 2.0 * ep[p, 4]
        g01 /= wsum
        g02 /= wsum
        energy += 0.5 * c_st * wsum * (g01 * g01 + g02 * g02)
        tau01 = c_st * g01
        tau02 = c_st * g02
        r00 = 0.0; r01 = 0.0; r02 = 0.0          # Σ w P[:,0], Σ w s1 P[:,0], Σ w s2 P[:,0], Σ w P[:,1], Σ w P[:,2]
        r10 = 0.0; r11 = 0.0; r12 = 0.0
        r20 = 0.0; r21 = 0.0; r22 = 0.0
        t10 = 0.0; t11 = 0.0; t12 = 0.0
        t20 = 0.0; t21 = 0.0; t22 = 0.0
        fw0 = 0.0; fw1 = 0.0; fw2 = 0.0           # Σ w f0, Σ w s1, Σ w s2 (shear split)
        sw1 = 0.0
        sw2 = 0.0
        if want_k:
            hacc[:, :, :] = 0.0
            gacc[:] = 0.0
        for p in range(p0, p0 + nsec):
            s1 = s_pt[p, 0]
            s2 = s_pt[p, 1]
            wl = w[p] * lam
            e00 = ep[p, 0]
            e11 = ep[p, 1]
            e22 = ep[p, 2]
            y01 = 2.0 * ep[p, 3]
            y02 = 2.0 * ep[p, 4]
            y12 = 2.0 * ep[p, 5]
            energy += wl * 0.5 * (e_ax * e00 * e00 + e_t * (e11 * e11 + e22 * e22)
                                  + g_pt * (y01 * y01 + y02 * y02) + g_t * y12 * y12)
            s00 = e_ax * e00
            s11 = e_t * e11
            s22 = e_t * e22
            s01 = g_pt * y01 + tau01
            s02 = g_pt * y02 + tau02
            s12 = g_t * y12
            f00 = fp[p, 0, 0]; f10 = fp[p, 1, 0]; f20 = fp[p, 2, 0]
            # P = F̃ S by columns: P[:, j] = Σ_k f_k S_kj
            q00 = f00 * s00 + b10 * s01 + b20 * s02
            q10 = f10 * s00 + b11 * s01 + b21 * s02
            q20 = f20 * s00 + b12 * s01 + b22 * s02
            q01 = f00 * s01 + b10 * s11 + b20 * s12
            q11 = f10 * s01 + b11 * s11 + b21 * s12
            q21 = f20 * s01 + b12 * s11 + b22 * s12
            q02 = f00 * s02 + b10 * s12 + b20 * s22
            q12 = f10 * s02 + b11 * s12 + b21 * s22
            q22 = f20 * s02 + b12 * s12 + b22 * s22
            r00 += wl * q00; r01 += wl * q10; r02 += wl * q20
            r10 += wl * s1 * q00; r11 += wl * s1 * q10; r12 += wl * s1 * q20
            r20 += wl * s2 * q00; r21 += wl * s2 * q10; r22 += wl * s2 * q20
            t10 += wl * q01; t11 += wl * q11; t12 += wl * q21
            t20 += wl * q02; t21 += wl * q12; t22 += wl * q22
            if want_k:
                fw0 += wl * f00; fw1 += wl * f10; fw2 += wl * f20
                sw1 += wl * s1
                sw2 += wl * s2
                c0 = wl * e_ax
                c1 = wl * e_t
                c3 = wl * g_pt
                c5 = wl * g_t
                mono = (1.0, s1, s2, s1 * s1, s1 * s2, s2 * s2)
                fv = (f00, f10, f20)
                b1 = (b10, b11, b12)
                b2 = (b20, b21, b22)
                for i in range(3):
                    for j in range(3):
                        ff = fv[i] * fv[j]
                        g11 = b1[i] * b1[j]
                        g22 = b2[i] * b2[j]
                        h00 = c0 * ff + c3 * (g11 + g22)
                        for mm in range(6):
                            hacc[mm, i, j] += mono[mm] * h00
                        h01 = c3 * b1[i] * fv[j]
                        h02 = c3 * b2[i] * fv[j]
                        hacc[6, i, j] += h01
                        hacc[7, i, j] += s1 * h01
                        hacc[8, i, j] += s2 * h01
                        hacc[9, i, j] += h02
                        hacc[10, i, j] += s1 * h02
                        hacc[11, i, j] += s2 * h02
                        hacc[12, i, j] += c1 * g11 + c3 * ff + c5 * g22
                        hacc[13, i, j] += c5 * b2[i] * b1[j]
                        hacc[14, i, j] += c1 * g22 + c3 * ff + c5 * g11
                for mm in range(6):
                    gacc[mm] += wl * mono[mm] * s00
                gacc[6] += wl * s01
                gacc[7] += wl * s1 * s01
                gacc[8] += wl * s2 * s01
                gacc[9] += wl * s02
                gacc[10] += wl * s1 * s02
                gacc[11] += wl * s2 * s02
                gacc[12] += wl * s11
                gacc[13] += wl * s12
                gacc[14] += wl * s22
        # residual: Y rows take P[:,0]·φ'/|X'|λ, V rows add s·P[:,0] and P[:,1|2]·φ
        for l in range(nn):
            u = dphi_st[st, l] * inv
            ph = phi_st[st, l]
            k = 9 * l
            re[k] += u * r00; re[k + 1] += u * r01; re[k + 2] += u * r02
            re[k + 3] += u * r10 + ph * t10; re[k + 4] += u * r11 + ph * t11; re[k + 5] += u * r12 + ph * t12
            re[k + 6] += u * r20 + ph * t20; re[k + 7] += u * r21 + ph * t21; re[k + 8] += u * r22 + ph * t22
        if want_k:
            # per vector-type pair (ta, tb) and factor kind (u_l u_m, u_l φ_m, φ_l u_m, φ_l φ_m): the
            # 3×3 matrix that the factor multiplies, geometric part (scalar × I₃) included
            tk[:, :, :, :] = 0.0
            tg[:, :] = 0.0
            for bt in range(9):
                for z in range(4):
                    idx = blocks[bt, z, 0]
                    if idx < 0:
                        break
                    kind = blocks[bt, z, 1]
                    tg[bt, kind] += gacc[idx]
                    if blocks[bt, z, 2] == 0:
                        for i in range(3):
                            for j in range(3):
                                tk[bt, kind, i, j] += hacc[idx, i, j]
                    else:
                        for i in range(3):
                            for j in range(3):
                                tk[bt, kind, i, j] += hacc[idx, j, i]
                for kind in range(4):
                    for i in range(3):
                        tk[bt, kind, i, i] += tg[bt, kind]
            for l in range(nn):
                ul = dphi_st[st, l] * inv
                pl = phi_st[st, l]
                for m in range(l, nn):
                    um = dphi_st[st, m] * inv
                    pm = phi_st[st, m]
                    f0 = ul * um
                    f1 = ul * pm
                    f2 = pl * um
                    f3 = pl * pm
                    for ta in range(3):
                        ra = 9 * l + 3 * ta
                        tb0 = ta if m == l else 0         # lower blocks: mirrored at the end
                        for tb in range(tb0, 3):
                            cb = 9 * m + 3 * tb
                            bt = 3 * ta + tb
                            for i in range(3):
                                for j in range(3):
                                    ke[ra + i, cb + j] += (f0 * tk[bt, 0, i, j] + f1 * tk[bt, 1, i, j]
                                                           + f2 * tk[bt, 2, i, j] + f3 * tk[bt, 3, i, j])
            if c_st != 0.0:
                # station shear split: rank two, with ∂(Σ w γ01)/∂q and ∂(Σ w γ02)/∂q from the
                # station sums (the general kernel's gbar)
                for l in range(nn):
                    ul = dphi_st[st, l] * inv
                    pl = phi_st[st, l]
                    k = 9 * l
                    gbar[0, k] = ul * wsum * b10; gbar[0, k + 1] = ul * wsum * b11; gbar[0, k + 2] = ul * wsum * b12
                    gbar[0, k + 3] = pl * fw0 + ul * sw1 * b10
                    gbar[0, k + 4] = pl * fw1 + ul * sw1 * b11
                    gbar[0, k + 5] = pl * fw2 + ul * sw1 * b12
                    gbar[0, k + 6] = ul * sw2 * b10; gbar[0, k + 7] = ul * sw2 * b11; gbar[0, k + 8] = ul * sw2 * b12
                    gbar[1, k] = ul * wsum * b20; gbar[1, k + 1] = ul * wsum * b21; gbar[1, k + 2] = ul * wsum * b22
                    gbar[1, k + 3] = ul * sw1 * b20; gbar[1, k + 4] = ul * sw1 * b21; gbar[1, k + 5] = ul * sw1 * b22
                    gbar[1, k + 6] = pl * fw0 + ul * sw2 * b20
                    gbar[1, k + 7] = pl * fw1 + ul * sw2 * b21
                    gbar[1, k + 8] = pl * fw2 + ul * sw2 * b22
                cw = c_st / wsum
                for r in range(nloc):
                    g0 = cw * gbar[0, r]
                    g1 = cw * gbar[1, r]
                    for c in range(r, nloc):
                        ke[r, c] += g0 * gbar[0, c] + g1 * gbar[1, c]
    if want_k:
        for r in range(nloc):
            for c in range(r + 1, nloc):
                ke[c, r] = ke[r, c]
    return energy


@njit(cache=True)
def frame_group(q, v, edofs, dax, dsec, w, nsec, mat, act, lam_act, lam_rate, c_v, smap, want_k,
                want_dlam, r, kdata, d, fp, fd, ep, ed, bmat, bdot, gbar, gdot, qe, ve, re, ke, kn,
                straight, phi_st, dphi_st, s_pt, blocks, hacc, gacc, tk, tg):
    """Loop over one frame group: gather, element kernel, scatter into ``r`` and CSR ``kdata``.

    ``v (ndof,)`` rates of the unknowns (read only for damped elements); ``edofs (ne, 9n)`` global
    DOF ids; ``act (ne,)`` actuator id or −1; ``lam_act, lam_rate`` stretch and stretch rate per
    actuator; ``smap (ne, (9n)²)`` position of each local entry in ``kdata`` (−1: prescribed).
    ``straight … gacc`` (:func:`frame_structure`): elements flagged straight (and undamped) go
    through :func:`straight_frame_element`, the others through :func:`frame_element`.
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
            u = straight_frame_element(qe, phi_st[e], dphi_st[e], s_pt[e], w[e], nsec, mat[e], lam, want_k,
                                       blocks, fp, ep, gbar, hacc, gacc, tk, tg, re, ke)
            de = 0.0
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


def frame_structure(g, *, structured: bool = True) -> tuple[np.ndarray, ...]:
    """Per-group data of :func:`straight_frame_element` (computed once per model, from the
    group's own integration data): ``(straight (ne,) int64, phi_st (ne, nst, n), dphi_st (ne, nst,
    n), s_pt (ne, nip, 2), _BLOCK, hacc (15, 3, 3), gacc (15,), tk (9, 4, 3, 3), tg (9, 4))``.

    An element is flagged straight when its ``D̃`` has the structure of a straight element with
    constant section vectors (``d_Y = [φ'/|X'|, 0, 0]``, ``d_V1 = [s₁φ'/|X'|, φ, 0]``, ``d_V2 =
    [s₂φ'/|X'|, 0, φ]`` at every point, to 1e-12 of its largest entry) and it is undamped;
    curved and damped elements keep :func:`frame_element`. ``structured=False`` flags none.
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
        ok = g.mat[e, 6] == 0.0 and np.abs(dax[:, :, 1:]).max() <= tol and np.abs(dsec[:, :, 0]).max() <= tol
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
    return (straight, phi_st, dphi_st, s_pt, _BLOCK, np.zeros((15, 3, 3)), np.zeros(15), np.zeros((9, 4, 3, 3)),
            np.zeros((9, 4)))
