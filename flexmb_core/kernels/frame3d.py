"""Positional 3D frame element (SPEC §1): residual, tangent, strain energy, actuator stretch.

Nodal unknowns per node: position Y and two generalized section vectors V1, V2, ordered
``q_e = [Y¹, V1¹, V2¹, Y², …]`` (``9 n`` values). The deformation gradient in the local
reference frame is ``F = Qᵀ D̃`` with ``Q`` the ``(3n, 3)`` matrix of nodal vectors and
``D̃ = Dax/λ + Dsec`` precomputed per integration point (``λ`` is the actuator stretch, 1 for a
passive member; it scales the axial reference coordinate, SPEC §4.2, and the weight by ``λ``).

Constitutive law: the local "frame" Saint-Venant–Kirchhoff law of SPEC §1.2 (no Poisson coupling,
so no Poisson locking), with the station shear split that gives torsion ``GJ`` and uniform shear
``k_s G A`` at the same time.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .scatter import scatter_matrix

# Columns of the per-element material table ``mat[e]``.
MAT_E, MAT_ET, MAT_G, MAT_GT, MAT_KT, MAT_KS = 0, 1, 2, 3, 4, 5
N_MAT = 6


@njit(cache=True)
def frame_element(qe, dax, dsec, w, nsec, mat, lam, want_k, want_dlam,
                  d, fp, ep, bmat, gbar, re, ke):
    """Residual, tangent and energy of one positional frame element.

    Parameters
    ----------
    qe : (9n,) float64 — element unknowns [Y, V1, V2] per node (m, –, –).
    dax, dsec : (nip, 3n, 3) float64 — axial / section parts of D̃ per integration point.
    w : (nip,) float64 — reference volume weights (m³) at λ = 1.
    nsec : int — section points per axial station (points are station-major).
    mat : (6,) float64 — E, E_t, G, G_t (Pa), κ_t = J/I_p, k_s.
    lam : float — actuator stretch λ = L_cmd / L_0 (1 for passive elements).
    want_k, want_dlam : bool — compute the tangent / dU/dλ.
    d, fp, ep, bmat, gbar : scratch (nip,3n,3), (nip,3,3), (nip,6), (6,9n), (2,9n).
    re : (9n,) float64 — out: internal force ∂U/∂q_e (N, N·m).
    ke : (9n, 9n) float64 — out: tangent ∂²U/∂q_e² (written only if ``want_k``).

    Returns
    -------
    (U, dU/dλ) : strain energy (J) and its derivative with respect to λ at fixed q (J).
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
    g_pt = g_mod * kap_t           # point shear modulus: gives G·J in torsion
    c_st = g_mod * (k_s - kap_t)   # station-average shear modulus: tops uniform shear up to k_s·G·A
    inv = 1.0 / lam
    re[:] = 0.0
    if want_k:
        ke[:, :] = 0.0
    energy = 0.0
    dudlam = 0.0

    # Pass 1: F and E at every point (the station averages need all points of a station).
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

    nst = nip // nsec
    for st in range(nst):
        p0 = st * nsec
        wsum = 0.0
        g01 = 0.0
        g02 = 0.0
        for p in range(p0, p0 + nsec):
            wl = w[p] * lam
            wsum += wl
            g01 += wl * 2.0 * ep[p, 3]
            g02 += wl * 2.0 * ep[p, 4]
        g01 /= wsum
        g02 /= wsum
        energy += 0.5 * c_st * wsum * (g01 * g01 + g02 * g02)
        tau01 = c_st * g01
        tau02 = c_st * g02
        if want_k:
            gbar[:, :] = 0.0

        for p in range(p0, p0 + nsec):
            wl = w[p] * lam
            e00 = ep[p, 0]
            e11 = ep[p, 1]
            e22 = ep[p, 2]
            y01 = 2.0 * ep[p, 3]
            y02 = 2.0 * ep[p, 4]
            y12 = 2.0 * ep[p, 5]
            s00 = e_ax * e00
            s11 = e_t * e11
            s22 = e_t * e22
            s01 = g_pt * y01 + tau01
            s02 = g_pt * y02 + tau02
            s12 = g_t * y12
            energy += wl * 0.5 * (e_ax * e00 * e00 + e_t * (e11 * e11 + e22 * e22)
                                  + g_pt * (y01 * y01 + y02 * y02) + g_t * y12 * y12)
            f00 = fp[p, 0, 0]; f01 = fp[p, 0, 1]; f02 = fp[p, 0, 2]
            f10 = fp[p, 1, 0]; f11 = fp[p, 1, 1]; f12 = fp[p, 1, 2]
            f20 = fp[p, 2, 0]; f21 = fp[p, 2, 1]; f22 = fp[p, 2, 2]
            # First Piola–Kirchhoff P = F S (S symmetric, local frame).
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
                # dF/dλ = −Qᵀ Dax / λ², and S : sym(Fᵀ dF) = P : dF with P = F S.
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
                    for r in range(nloc):
                        br = ck * bmat[k, r]
                        if br != 0.0:
                            for c in range(r, nloc):
                                ke[r, c] += br * bmat[k, c]
                for r in range(nloc):
                    gbar[0, r] += wl * bmat[3, r]
                    gbar[1, r] += wl * bmat[4, r]
                # Geometric part: δ_ij · w d_a S d_bᵀ
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
                g0 = cw * gbar[0, r]
                g1 = cw * gbar[1, r]
                for c in range(r, nloc):
                    ke[r, c] += g0 * gbar[0, c] + g1 * gbar[1, c]
    if want_k:
        for r in range(nloc):
            for c in range(r + 1, nloc):
                ke[c, r] = ke[r, c]
    if want_dlam:
        dudlam += energy * inv
    return energy, dudlam


@njit(cache=True)
def frame_group(q, edofs, dax, dsec, w, nsec, mat, act, lam_act, smap, want_k, want_dlam,
                r, kdata, d, fp, ep, bmat, gbar, qe, re, ke):
    """Loop over one frame group: gather, element kernel, scatter into ``r`` and CSR ``kdata``.

    ``edofs (ne, 9n)`` global DOF ids; ``act (ne,)`` actuator id or −1; ``lam_act`` stretch per
    actuator; ``smap (ne, (9n)²)`` position of each local entry in ``kdata`` (−1: prescribed).
    ``want_dlam`` must be passed in (False) rather than written as a literal: a literal constant
    in a call between njit functions is typed ``Literal[bool]`` and compiles a second signature.
    Returns the group's strain energy (J).
    """
    ne = edofs.shape[0]
    nloc = edofs.shape[1]
    energy = 0.0
    for e in range(ne):
        for i in range(nloc):
            qe[i] = q[edofs[e, i]]
        lam = 1.0
        if act[e] >= 0:
            lam = lam_act[act[e]]
        u, _ = frame_element(qe, dax[e], dsec[e], w[e], nsec, mat[e], lam, want_k, want_dlam,
                             d, fp, ep, bmat, gbar, re, ke)
        energy += u
        for i in range(nloc):
            r[edofs[e, i]] += re[i]
        if want_k:
            scatter_matrix(smap[e], ke, kdata)
    return energy


@njit(cache=True)
def frame_group_actuator_dudlam(q, edofs, dax, dsec, w, nsec, mat, act, lam_act, want_k, want_dlam, out,
                                d, fp, ep, bmat, gbar, qe, re, ke):
    """Accumulate dU/dλ of every actuated element into ``out[actuator]`` (J).

    Callers pass ``want_k = False, want_dlam = True`` (as arguments, see :func:`frame_group`)."""
    ne = edofs.shape[0]
    nloc = edofs.shape[1]
    for e in range(ne):
        if act[e] < 0:
            continue
        for i in range(nloc):
            qe[i] = q[edofs[e, i]]
        _, dl = frame_element(qe, dax[e], dsec[e], w[e], nsec, mat[e], lam_act[act[e]], want_k,
                              want_dlam, d, fp, ep, bmat, gbar, re, ke)
        out[act[e]] += dl


def frame_scratch(nip: int, nv: int) -> tuple[np.ndarray, ...]:
    """Scratch buffers for :func:`frame_group` (allocated once per model, never in the loop)."""
    nloc = 3 * nv
    return (np.zeros((nip, nv, 3)), np.zeros((nip, 3, 3)), np.zeros((nip, 6)),
            np.zeros((6, nloc)), np.zeros((2, nloc)), np.zeros(nloc), np.zeros(nloc),
            np.zeros((nloc, nloc)))
