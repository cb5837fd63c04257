"""Solid-like positional shell element (SPEC §2): curved cubic triangle, 10 nodes, 7 unknowns per node.

Nodal unknowns ``[Y (3), G (3), a (1)]``: mid-surface position, one unconstrained generalized
vector (director and thickness stretch in one) and the thickness strain rate, ordered node by
node (``q_e`` has 70 values). With ``h = h0/2`` and ζ ∈ [−1, 1] through the thickness,

    x(ξ1, ξ2, ζ) = Σ φℓ Xℓ + h ζ Σ φℓ V⁰ℓ                   (reference; V⁰ the unit nodal normals)
    y(ξ1, ξ2, ζ) = Σ φℓ Yℓ + h (ζ + a ζ²) Σ φℓ Gℓ,  a = Σ φℓ aℓ

so the thickness stretch |G|(1 + 2aζ) varies linearly through the thickness: the section can
contract the way bending with ν ≠ 0 requires, and the full 3D Saint-Venant–Kirchhoff law
``S = λ tr(E) I + 2μ E`` is used as it is (no plane-stress condensation, no Poisson locking).
``F = A¹ (A⁰)⁻¹`` with ``A = [∂/∂ξ1, ∂/∂ξ2, ∂/∂ζ]`` is linear in Y and G for fixed a and bilinear
in (a, G): the only second derivatives of F are the (a, G) cross terms, which enter the geometric
part of the tangent. The strain energy ``∫ ½ S : E dV₀`` is integrated by a triangle rule times
Gauss points through the thickness; the tangent is exact (``tests/unit/test_shell_kernel.py``).
The kernel sums the points through the thickness in 21 node-independent "virtual" unknowns and
spreads them over the 70 once per in-plane point (:func:`shell_element`, Notes).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .scatter import scatter_matrix

NODES = 10          # cubic triangle
NDOF_NODE = 7       # Y, G, a
NLOC = NODES * NDOF_NODE

# Columns of the per-element material table ``mat[e]``.
SMAT_LAMBDA, SMAT_MU, SMAT_H = 0, 1, 2
N_SMAT = 3


# Virtual unknowns v = 7b + ν (b: φ, φ,1, φ,2; ν: Y0 Y1 Y2 G0 G1 G2 a) and the scratch rows.
NV = 3 * NDOF_NODE
D_SD, D_G, D_N = 6, 12, 15          # dv rows: d_k (0–5), w S d_k (6–11), g g,1 g,2 (12–14), N (15–17)
F_NY, F_NZ, F_NZ2, F_RV = 3, 6, 9, 12   # f rows: F (0–2), Σ N, Σ ζN, Σ ζ²N (3 each), r_v (12–14, by b)
N_F = F_RV + 3
B_H = 6             # bmat rows: Voigt B (0–5), H (6–26)
NB = 4              # in-plane points whose Sᵀ T is added to K_e in one pass
C_T = 6             # cb rows: w C B (0–5), T = H S of the NB batch slots (21 rows each), their s_ℓ (3 rows each)
C_S = C_T + NB * NV


@njit(cache=True)
def _fields(qe, phi, dphi, p):
    """y,1 y,2; g g,1 g,2; a a,1 a,2 at point ``p`` (an 18-tuple). Plain IEEE rounding here, in
    :func:`_strain_stress` and in :func:`shell_element` (which inlines both; fastmath there fuses
    their products too): E of a small strain is a small difference of F's products, and this keeps
    F, E, S and U bit-identical to the per-node form of the kernel (a contracted F moved r_e of a
    nearly unstrained panel by 1e-7 of its size)."""
    y1x = 0.0; y1y = 0.0; y1z = 0.0
    y2x = 0.0; y2y = 0.0; y2z = 0.0
    gx = 0.0; gy = 0.0; gz = 0.0
    g1x = 0.0; g1y = 0.0; g1z = 0.0
    g2x = 0.0; g2y = 0.0; g2z = 0.0
    aa = 0.0; a1 = 0.0; a2 = 0.0
    for n in range(NODES):
        b = NDOF_NODE * n
        ph = phi[p, n]
        s1 = dphi[p, n, 0]
        s2 = dphi[p, n, 1]
        y1x += s1 * qe[b]; y1y += s1 * qe[b + 1]; y1z += s1 * qe[b + 2]
        y2x += s2 * qe[b]; y2y += s2 * qe[b + 1]; y2z += s2 * qe[b + 2]
        gx += ph * qe[b + 3]; gy += ph * qe[b + 4]; gz += ph * qe[b + 5]
        g1x += s1 * qe[b + 3]; g1y += s1 * qe[b + 4]; g1z += s1 * qe[b + 5]
        g2x += s2 * qe[b + 3]; g2y += s2 * qe[b + 4]; g2z += s2 * qe[b + 5]
        aa += ph * qe[b + 6]
        a1 += s1 * qe[b + 6]
        a2 += s2 * qe[b + 6]
    return (y1x, y1y, y1z, y2x, y2y, y2z, gx, gy, gz, g1x, g1y, g1z, g2x, g2y, g2z, aa, a1, a2)


@njit(cache=True)
def _strain_stress(fl, z, hh, a0inv, p, lam_l, mu, f):
    """F (into ``f[0:3]``), the SVK stress S and S : E at thickness coordinate ``z`` of point ``p``
    from the fields ``fl`` of :func:`_fields`. Returns (S00, S11, S22, S01, S02, S12, S : E)."""
    y1x, y1y, y1z, y2x, y2y, y2z, gx, gy, gz, g1x, g1y, g1z, g2x, g2y, g2z, aa, a1, a2 = fl
    q1x = a1 * gx + aa * g1x; q1y = a1 * gy + aa * g1y; q1z = a1 * gz + aa * g1z
    q2x = a2 * gx + aa * g2x; q2y = a2 * gy + aa * g2y; q2z = a2 * gz + aa * g2z
    z2 = z * z
    # Columns of A¹ = [∂y/∂ξ1, ∂y/∂ξ2, ∂y/∂ζ].
    c0x = y1x + hh * (z * g1x + z2 * q1x)
    c0y = y1y + hh * (z * g1y + z2 * q1y)
    c0z = y1z + hh * (z * g1z + z2 * q1z)
    c1x = y2x + hh * (z * g2x + z2 * q2x)
    c1y = y2y + hh * (z * g2y + z2 * q2y)
    c1z = y2z + hh * (z * g2z + z2 * q2z)
    s3 = hh * (1.0 + 2.0 * aa * z)
    c2x = s3 * gx
    c2y = s3 * gy
    c2z = s3 * gz
    for j in range(3):
        i0 = a0inv[p, 0, j]
        i1 = a0inv[p, 1, j]
        i2 = a0inv[p, 2, j]
        f[0, j] = c0x * i0 + c1x * i1 + c2x * i2
        f[1, j] = c0y * i0 + c1y * i1 + c2y * i2
        f[2, j] = c0z * i0 + c1z * i1 + c2z * i2
    # Green–Lagrange strain and the SVK stress.
    e00 = 0.5 * (f[0, 0] * f[0, 0] + f[1, 0] * f[1, 0] + f[2, 0] * f[2, 0] - 1.0)
    e11 = 0.5 * (f[0, 1] * f[0, 1] + f[1, 1] * f[1, 1] + f[2, 1] * f[2, 1] - 1.0)
    e22 = 0.5 * (f[0, 2] * f[0, 2] + f[1, 2] * f[1, 2] + f[2, 2] * f[2, 2] - 1.0)
    e01 = 0.5 * (f[0, 0] * f[0, 1] + f[1, 0] * f[1, 1] + f[2, 0] * f[2, 1])
    e02 = 0.5 * (f[0, 0] * f[0, 2] + f[1, 0] * f[1, 2] + f[2, 0] * f[2, 2])
    e12 = 0.5 * (f[0, 1] * f[0, 2] + f[1, 1] * f[1, 2] + f[2, 1] * f[2, 2])
    tr = e00 + e11 + e22
    s00 = lam_l * tr + 2.0 * mu * e00
    s11 = lam_l * tr + 2.0 * mu * e11
    s22 = lam_l * tr + 2.0 * mu * e22
    s01 = 2.0 * mu * e01
    s02 = 2.0 * mu * e02
    s12 = 2.0 * mu * e12
    return s00, s11, s22, s01, s02, s12, s00 * e00 + s11 * e11 + s22 * e22 + 2.0 * (s01 * e01 + s02 * e02 + s12 * e12)


@njit(cache=True, fastmath={"reassoc", "contract"})
def _spread_slot(cb, ke, slot):
    """Upper triangle of K_e += Sᵀ T for one batch slot (T rows ``C_T + 21·slot + v``, s_ℓ rows
    ``C_S + 3·slot``); the 70-long inner loops run over contiguous columns of ``ke`` and ``cb``."""
    tb = C_T + NV * slot
    sb = C_S + 3 * slot
    for n in range(NODES):
        ph = cb[sb, n]
        s1 = cb[sb + 1, n]
        s2 = cb[sb + 2, n]
        for nu in range(3):
            row = NDOF_NODE * n + nu
            t = tb + NDOF_NODE + nu
            for c in range(row, NLOC):
                ke[row, c] += s1 * cb[t, c] + s2 * cb[t + NDOF_NODE, c]
        for nu in range(3, NDOF_NODE):
            row = NDOF_NODE * n + nu
            t = tb + nu
            for c in range(row, NLOC):
                ke[row, c] += ph * cb[t, c] + s1 * cb[t + NDOF_NODE, c] + s2 * cb[t + 2 * NDOF_NODE, c]


@njit(cache=True, fastmath={"reassoc", "contract"})
def _spread_batch(cb, ke):
    """Upper triangle of K_e += Σ_slots Sᵀ T for a full batch (NB = 4 slots): one pass over K_e."""
    u = NDOF_NODE
    t1 = C_T + NV
    t2 = C_T + 2 * NV
    t3 = C_T + 3 * NV
    for n in range(NODES):
        a00 = cb[C_S, n]; a01 = cb[C_S + 1, n]; a02 = cb[C_S + 2, n]
        a10 = cb[C_S + 3, n]; a11 = cb[C_S + 4, n]; a12 = cb[C_S + 5, n]
        a20 = cb[C_S + 6, n]; a21 = cb[C_S + 7, n]; a22 = cb[C_S + 8, n]
        a30 = cb[C_S + 9, n]; a31 = cb[C_S + 10, n]; a32 = cb[C_S + 11, n]
        for nu in range(3):
            row = NDOF_NODE * n + nu
            r0 = C_T + nu
            r1 = t1 + nu
            r2 = t2 + nu
            r3 = t3 + nu
            for c in range(row, NLOC):
                ke[row, c] += (a01 * cb[r0 + u, c] + a02 * cb[r0 + 2 * u, c] + a11 * cb[r1 + u, c]
                               + a12 * cb[r1 + 2 * u, c] + a21 * cb[r2 + u, c] + a22 * cb[r2 + 2 * u, c]
                               + a31 * cb[r3 + u, c] + a32 * cb[r3 + 2 * u, c])
        for nu in range(3, NDOF_NODE):
            row = NDOF_NODE * n + nu
            r0 = C_T + nu
            r1 = t1 + nu
            r2 = t2 + nu
            r3 = t3 + nu
            for c in range(row, NLOC):
                ke[row, c] += (a00 * cb[r0, c] + a01 * cb[r0 + u, c] + a02 * cb[r0 + 2 * u, c]
                               + a10 * cb[r1, c] + a11 * cb[r1 + u, c] + a12 * cb[r1 + 2 * u, c]
                               + a20 * cb[r2, c] + a21 * cb[r2 + u, c] + a22 * cb[r2 + 2 * u, c]
                               + a30 * cb[r3, c] + a31 * cb[r3 + u, c] + a32 * cb[r3 + 2 * u, c])


@njit(cache=True)
def shell_element(qe, phi, dphi, zeta, a0inv, w, mat, want_k, dv, dfa, f, bmat, cb, re, ke):
    """Residual, tangent and strain energy of one positional shell element.

    Parameters
    ----------
    qe : (70,) float64 — element unknowns [Y (m), G (–), a (–)] per node.
    phi : (npt, 10) float64 — shape functions at the integration points.
    dphi : (npt, 10, 2) float64 — their derivatives ∂φ/∂ξ1, ∂φ/∂ξ2.
    zeta : (npt,) float64 — thickness coordinate ζ ∈ [−1, 1] of each point.
    a0inv : (npt, 3, 3) float64 — (A⁰)⁻¹ of the reference map per point (1/m, 1/m, 1/m rows).
    w : (npt,) float64 — reference volume weights W·det A⁰ (m³).
    mat : (3,) float64 — Lamé λ, μ (Pa) and the half thickness h = h0/2 (m).
    want_k : bool — also compute the tangent.
    dv, dfa, f, bmat, cb : scratch of :func:`shell_scratch` (row roles: ``D_*``, ``F_*``, ``B_H``, ``C_*``).
    re : (70,) out — internal force ∂U/∂q_e (N for Y, N·m for G and a).
    ke : (70, 70) out — tangent ∂²U/∂q_e² (symmetric; written only if ``want_k``).

    Returns
    -------
    float — strain energy U (J).

    Notes
    -----
    Every derivative of F with respect to a nodal unknown (ℓ, ν) is Σ_b s_ℓ[b] ∂F/∂v, with
    s_ℓ = (φℓ, φℓ,1, φℓ,2) and 21 "virtual" unknowns v = 7b + ν whose ∂F depend on the point but not
    on the node (Y_i: e_i ⊗ d_k with d = a⁰₀, a⁰₁ for b = 1, 2; G_i: e_i ⊗ d_k with the G columns of
    ∂A¹; a: the g, g,1, g,2 terms; a⁰_c the rows of (A⁰)⁻¹). The points through the thickness at one
    in-plane point (consecutive rows of ``phi``/``dphi`` equal) share s_ℓ, so their contributions are
    summed over the 21 virtual unknowns first and spread over the 70 once: r_e += Sᵀ r_v and
    K_e += Sᵀ H S (21 × 21 H; T = H S, then Sᵀ T for NB in-plane points in one pass over K_e). r_v
    only needs the thickness moments Σ N, Σ ζN, Σ ζ²N of N = w P (A⁰)⁻ᵀ. Same integrand, same rule
    and F, E, S rounded as in the per-node sum; r_e and K_e differ from it by summation order only
    (≤ 1e-14 relative, ``docs/benchmarks/shell_kernel.md``).
    """
    npt = w.shape[0]
    lam_l = mat[SMAT_LAMBDA]
    mu = mat[SMAT_MU]
    hh = mat[SMAT_H]
    re[:] = 0.0
    if want_k:
        ke[:, :] = 0.0
    energy = 0.0
    ns = 0              # filled slots of the tangent batch
    p0 = npt * 0         # an int64 from data: a literal 0 would compile a second signature of _fields
    while p0 < npt:
        # The run p0 … p1−1 of points through the thickness at one in-plane point.
        p1 = p0 + 1
        while p1 < npt:
            same = True
            for n in range(NODES):
                if (phi[p1, n] != phi[p0, n] or dphi[p1, n, 0] != dphi[p0, n, 0]
                        or dphi[p1, n, 1] != dphi[p0, n, 1]):
                    same = False
                    break
            if not same:
                break
            p1 += 1
        # Interpolated fields (independent of ζ): y,1 y,2; g g,1 g,2; a a,1 a,2.
        fl = _fields(qe, phi, dphi, p0)
        y1x, y1y, y1z, y2x, y2y, y2z, gx, gy, gz, g1x, g1y, g1z, g2x, g2y, g2z, aa, a1, a2 = fl
        for i in range(F_NY, F_RV):
            f[i, 0] = 0.0
            f[i, 1] = 0.0
            f[i, 2] = 0.0
        if want_k:
            dv[D_G, 0] = gx; dv[D_G, 1] = gy; dv[D_G, 2] = gz
            dv[D_G + 1, 0] = g1x; dv[D_G + 1, 1] = g1y; dv[D_G + 1, 2] = g1z
            dv[D_G + 2, 0] = g2x; dv[D_G + 2, 1] = g2y; dv[D_G + 2, 2] = g2z
            for v in range(3, NV):
                for v2 in range(NV):
                    bmat[B_H + v, v2] = 0.0
        for p in range(p0, p1):
            z = zeta[p]
            z2 = z * z
            hz = hh * z
            hz2 = hh * z2
            s3 = hh * (1.0 + 2.0 * aa * z)
            s00, s11, s22, s01, s02, s12, se = _strain_stress(fl, z, hh, a0inv, p, lam_l, mu, f)
            wp = w[p]
            energy += 0.5 * wp * se
            # w P = w F S, then N = w P (A⁰)⁻ᵀ and its thickness moments.
            for i in range(3):
                fi0 = f[i, 0]
                fi1 = f[i, 1]
                fi2 = f[i, 2]
                pi0 = wp * (fi0 * s00 + fi1 * s01 + fi2 * s02)
                pi1 = wp * (fi0 * s01 + fi1 * s11 + fi2 * s12)
                pi2 = wp * (fi0 * s02 + fi1 * s12 + fi2 * s22)
                for c in range(3):
                    nic = pi0 * a0inv[p, c, 0] + pi1 * a0inv[p, c, 1] + pi2 * a0inv[p, c, 2]
                    dv[D_N + i, c] = nic
                    f[F_NY + i, c] += nic
                    f[F_NZ + i, c] += z * nic
                    f[F_NZ2 + i, c] += z2 * nic
            if not want_k:
                continue

            # Virtual ∂F: Y, G (e_i ⊗ d_k, k = 3t + b) and a (dfa[b]).
            cg = hh * (z + z2 * aa)
            for j in range(3):
                i0 = a0inv[p, 0, j]
                i1 = a0inv[p, 1, j]
                i2 = a0inv[p, 2, j]
                dv[0, j] = 0.0
                dv[1, j] = i0
                dv[2, j] = i1
                dv[3, j] = hz2 * (a1 * i0 + a2 * i1) + s3 * i2
                dv[4, j] = cg * i0
                dv[5, j] = cg * i1
                for i in range(3):
                    dfa[0, i, j] = hz2 * (dv[D_G + 1, i] * i0 + dv[D_G + 2, i] * i1) + 2.0 * hz * dv[D_G, i] * i2
                    dfa[1, i, j] = hz2 * dv[D_G, i] * i0
                    dfa[2, i, j] = hz2 * dv[D_G, i] * i1
            # Voigt B = ∂E/∂v (engineering shears) and w C B.
            for nu in range(6):
                i = nu % 3
                fi0 = f[i, 0]
                fi1 = f[i, 1]
                fi2 = f[i, 2]
                for bb in range(3):
                    k = 3 * (nu // 3) + bb
                    d0 = dv[k, 0]
                    d1 = dv[k, 1]
                    d2 = dv[k, 2]
                    col = NDOF_NODE * bb + nu
                    bmat[0, col] = fi0 * d0
                    bmat[1, col] = fi1 * d1
                    bmat[2, col] = fi2 * d2
                    bmat[3, col] = fi0 * d1 + fi1 * d0
                    bmat[4, col] = fi0 * d2 + fi2 * d0
                    bmat[5, col] = fi1 * d2 + fi2 * d1
            for bb in range(3):
                col = NDOF_NODE * bb + 6
                m00 = 0.0; m11 = 0.0; m22 = 0.0; m01 = 0.0; m02 = 0.0; m12 = 0.0
                for i in range(3):
                    fi0 = f[i, 0]
                    fi1 = f[i, 1]
                    fi2 = f[i, 2]
                    h0 = dfa[bb, i, 0]
                    h1 = dfa[bb, i, 1]
                    h2 = dfa[bb, i, 2]
                    m00 += fi0 * h0
                    m11 += fi1 * h1
                    m22 += fi2 * h2
                    m01 += fi0 * h1 + fi1 * h0
                    m02 += fi0 * h2 + fi2 * h0
                    m12 += fi1 * h2 + fi2 * h1
                bmat[0, col] = m00
                bmat[1, col] = m11
                bmat[2, col] = m22
                bmat[3, col] = m01
                bmat[4, col] = m02
                bmat[5, col] = m12
            for c in range(3, NV):
                tr_b = bmat[0, c] + bmat[1, c] + bmat[2, c]
                cb[0, c] = wp * (lam_l * tr_b + 2.0 * mu * bmat[0, c])
                cb[1, c] = wp * (lam_l * tr_b + 2.0 * mu * bmat[1, c])
                cb[2, c] = wp * (lam_l * tr_b + 2.0 * mu * bmat[2, c])
                cb[3, c] = wp * mu * bmat[3, c]
                cb[4, c] = wp * mu * bmat[4, c]
                cb[5, c] = wp * mu * bmat[5, c]
            # Material part Bᵀ C B (upper triangle).
            for v in range(3, NV):
                b0 = bmat[0, v]; b1 = bmat[1, v]; b2 = bmat[2, v]
                b3 = bmat[3, v]; b4 = bmat[4, v]; b5 = bmat[5, v]
                for v2 in range(v, NV):
                    bmat[B_H + v, v2] += (b0 * cb[0, v2] + b1 * cb[1, v2] + b2 * cb[2, v2]
                                          + b3 * cb[3, v2] + b4 * cb[4, v2] + b5 * cb[5, v2])
            # Geometric part among Y/G: δ_ij w d_k S d_k2 (k = 3t + b ↔ v = 7b + 3t + i).
            for k in range(1, 6):
                d0 = dv[k, 0]
                d1 = dv[k, 1]
                d2 = dv[k, 2]
                dv[D_SD + k, 0] = wp * (s00 * d0 + s01 * d1 + s02 * d2)
                dv[D_SD + k, 1] = wp * (s01 * d0 + s11 * d1 + s12 * d2)
                dv[D_SD + k, 2] = wp * (s02 * d0 + s12 * d1 + s22 * d2)
            for k in range(1, 6):
                vk = NDOF_NODE * (k % 3) + 3 * (k // 3)
                for k2 in range(1, 6):
                    vk2 = NDOF_NODE * (k2 % 3) + 3 * (k2 // 3)
                    if vk2 < vk:
                        continue
                    gkk = dv[k, 0] * dv[D_SD + k2, 0] + dv[k, 1] * dv[D_SD + k2, 1] + dv[k, 2] * dv[D_SD + k2, 2]
                    for i in range(3):
                        bmat[B_H + vk + i, vk2 + i] += gkk
            # (Y/G, a): (w ∂F/∂a S d_k)_i; (a, a): w ∂F/∂a S : ∂F/∂a.
            for bb in range(3):
                va = NDOF_NODE * bb + 6
                for i in range(3):
                    h0 = dfa[bb, i, 0]
                    h1 = dfa[bb, i, 1]
                    h2 = dfa[bb, i, 2]
                    dfa[3 + bb, i, 0] = wp * (h0 * s00 + h1 * s01 + h2 * s02)
                    dfa[3 + bb, i, 1] = wp * (h0 * s01 + h1 * s11 + h2 * s12)
                    dfa[3 + bb, i, 2] = wp * (h0 * s02 + h1 * s12 + h2 * s22)
                for k in range(1, 6):
                    vk = NDOF_NODE * (k % 3) + 3 * (k // 3)
                    for i in range(3):
                        x = dfa[3 + bb, i, 0] * dv[k, 0] + dfa[3 + bb, i, 1] * dv[k, 1] + dfa[3 + bb, i, 2] * dv[k, 2]
                        if vk + i < va:
                            bmat[B_H + vk + i, va] += x
                        else:
                            bmat[B_H + va, vk + i] += x
                for b2 in range(bb, 3):
                    s = 0.0
                    for i in range(3):
                        for j in range(3):
                            s += dfa[3 + bb, i, j] * dfa[b2, i, j]
                    bmat[B_H + va, NDOF_NODE * b2 + 6] += s
            # Second derivative ∂²F/∂a ∂G_i: P_i · (h [ζ² (s_a,1 s_b + s_a s_b,1), ζ² (…,2), 2ζ s_a s_b] (A⁰)⁻¹),
            # at (v_G, v_a) = (7b + 3 + i, 7b' + 6) for (b, b') = (φ, φ), (φ,1, φ), (φ, φ,1), (φ,2, φ), (φ, φ,2).
            for i in range(3):
                x0 = hz2 * dv[D_N + i, 0]
                x1 = hz2 * dv[D_N + i, 1]
                bmat[B_H + 3 + i, 6] += 2.0 * hz * dv[D_N + i, 2]
                bmat[B_H + 3 + i, NDOF_NODE + 6] += x0
                bmat[B_H + 3 + i, 2 * NDOF_NODE + 6] += x1
                bmat[B_H + 6, NDOF_NODE + 3 + i] += x0
                bmat[B_H + 6, 2 * NDOF_NODE + 3 + i] += x1

        # Virtual residual from the thickness moments, then r_e += Sᵀ r_v.
        for i in range(3):
            f[F_RV, i] = 0.0
            f[F_RV + 1, i] = f[F_NY + i, 0]
            f[F_RV + 2, i] = f[F_NY + i, 1]
            f[F_RV, 3 + i] = hh * (a1 * f[F_NZ2 + i, 0] + a2 * f[F_NZ2 + i, 1] + f[F_NY + i, 2]
                                   + 2.0 * aa * f[F_NZ + i, 2])
            f[F_RV + 1, 3 + i] = hh * (f[F_NZ + i, 0] + aa * f[F_NZ2 + i, 0])
            f[F_RV + 2, 3 + i] = hh * (f[F_NZ + i, 1] + aa * f[F_NZ2 + i, 1])
        f[F_RV, 6] = hh * (f[F_NZ2, 0] * g1x + f[F_NZ2 + 1, 0] * g1y + f[F_NZ2 + 2, 0] * g1z
                           + f[F_NZ2, 1] * g2x + f[F_NZ2 + 1, 1] * g2y + f[F_NZ2 + 2, 1] * g2z
                           + 2.0 * (f[F_NZ, 2] * gx + f[F_NZ + 1, 2] * gy + f[F_NZ + 2, 2] * gz))
        f[F_RV + 1, 6] = hh * (f[F_NZ2, 0] * gx + f[F_NZ2 + 1, 0] * gy + f[F_NZ2 + 2, 0] * gz)
        f[F_RV + 2, 6] = hh * (f[F_NZ2, 1] * gx + f[F_NZ2 + 1, 1] * gy + f[F_NZ2 + 2, 1] * gz)
        for n in range(NODES):
            ph = phi[p0, n]
            s1 = dphi[p0, n, 0]
            s2 = dphi[p0, n, 1]
            b = NDOF_NODE * n
            for nu in range(NDOF_NODE):
                re[b + nu] += ph * f[F_RV, nu] + s1 * f[F_RV + 1, nu] + s2 * f[F_RV + 2, nu]
        if want_k:
            # K_e += Sᵀ H S: T = H S (21 × 70) into the batch slot, then (per NB slots) the upper triangle
            # of Sᵀ T. Rows v < 3 (Y·φ) are zero.
            for v in range(3, NV):
                for v2 in range(3, v):
                    bmat[B_H + v, v2] = bmat[B_H + v2, v]
            tb = C_T + NV * ns
            for v in range(3, NV):
                for m in range(NODES):
                    ph = phi[p0, m]
                    s1 = dphi[p0, m, 0]
                    s2 = dphi[p0, m, 1]
                    c0 = NDOF_NODE * m
                    for nu in range(NDOF_NODE):
                        cb[tb + v, c0 + nu] = (ph * bmat[B_H + v, nu] + s1 * bmat[B_H + v, NDOF_NODE + nu]
                                               + s2 * bmat[B_H + v, 2 * NDOF_NODE + nu])
            for n in range(NODES):
                cb[C_S + 3 * ns, n] = phi[p0, n]
                cb[C_S + 3 * ns + 1, n] = dphi[p0, n, 0]
                cb[C_S + 3 * ns + 2, n] = dphi[p0, n, 1]
            ns += 1
            if ns == NB:
                _spread_batch(cb, ke)
                ns = 0
        p0 = p1
    if want_k:
        for slot in range(ns):
            _spread_slot(cb, ke, slot)
    if want_k:
        for r in range(NLOC):
            for c in range(r + 1, NLOC):
                ke[c, r] = ke[r, c]
    return energy


@njit(cache=True)
def shell_group(q, edofs, phi, dphi, zeta, a0inv, w, mat, smap, want_k, r, kdata, dv, dfa, f, bmat, cb,
                qe, re, ke):
    """Loop over one shell group: gather, element kernel, scatter into ``r`` and CSR ``kdata``.

    ``edofs (ne, 70)`` global DOF ids; ``a0inv (ne, npt, 3, 3)``, ``w (ne, npt)``, ``mat (ne, 3)``;
    ``smap (ne, 4900)`` CSR position of each local entry (−1: prescribed). Returns the strain energy (J).
    """
    energy = 0.0
    for e in range(edofs.shape[0]):
        for i in range(NLOC):
            qe[i] = q[edofs[e, i]]
        energy += shell_element(qe, phi, dphi, zeta, a0inv[e], w[e], mat[e], want_k, dv, dfa, f, bmat, cb,
                                re, ke)
        for i in range(NLOC):
            r[edofs[e, i]] += re[i]
        if want_k:
            scatter_matrix(smap[e], ke, kdata)
    return energy


def shell_scratch() -> tuple[np.ndarray, ...]:
    """Scratch buffers for :func:`shell_group` (allocated once per model): dv, dfa, f, bmat, cb, qe, re, ke.

    ``dv (20, 3)`` virtual d_k, w S d_k, g g,1 g,2 and N; ``dfa (10, 3, 3)`` virtual ∂F/∂a and
    w ∂F/∂a S; ``f (15, 7)`` F, the thickness moments of N and r_v; ``bmat (27, 21)`` Voigt B and H;
    ``cb (102, 70)`` w C B, the batch's T and s_ℓ; ``qe, re (70,)``; ``ke (70, 70)``.
    """
    return (np.zeros((2 * NODES, 3)), np.zeros((NODES, 3, 3)), np.zeros((N_F, NDOF_NODE)), np.zeros((B_H + NV, NV)),
            np.zeros((C_S + 3 * NB, NLOC)), np.zeros(NLOC), np.zeros(NLOC), np.zeros((NLOC, NLOC)))
