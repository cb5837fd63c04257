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
    dv : (20, 3) scratch — rows ∂F/∂(Y or G) of each node (F = Σ e_i ⊗ row).
    dfa : (10, 3, 3) scratch — ∂F/∂aℓ.
    f : (3, 3) scratch — deformation gradient.
    bmat, cb : (6, 70) scratch — Voigt ∂E/∂q and C : ∂E/∂q.
    re : (70,) out — internal force ∂U/∂q_e (N for Y, N·m for G and a).
    ke : (70, 70) out — tangent ∂²U/∂q_e² (symmetric; written only if ``want_k``).

    Returns
    -------
    float — strain energy U (J).
    """
    npt = w.shape[0]
    lam_l = mat[0]
    mu = mat[1]
    hh = mat[2]
    re[:] = 0.0
    if want_k:
        ke[:, :] = 0.0
    energy = 0.0
    for p in range(npt):
        z = zeta[p]
        z2 = z * z
        # Interpolated fields: y,1 y,2; g g,1 g,2; a a,1 a,2.
        y1x = 0.0; y1y = 0.0; y1z = 0.0
        y2x = 0.0; y2y = 0.0; y2z = 0.0
        gx = 0.0; gy = 0.0; gz = 0.0
        g1x = 0.0; g1y = 0.0; g1z = 0.0
        g2x = 0.0; g2y = 0.0; g2z = 0.0
        aa = 0.0; a1 = 0.0; a2 = 0.0
        for n in range(NODES):
            b = NDOF_NODE * n
            ph = phi[p, n]
            p1 = dphi[p, n, 0]
            p2 = dphi[p, n, 1]
            y1x += p1 * qe[b]; y1y += p1 * qe[b + 1]; y1z += p1 * qe[b + 2]
            y2x += p2 * qe[b]; y2y += p2 * qe[b + 1]; y2z += p2 * qe[b + 2]
            gx += ph * qe[b + 3]; gy += ph * qe[b + 4]; gz += ph * qe[b + 5]
            g1x += p1 * qe[b + 3]; g1y += p1 * qe[b + 4]; g1z += p1 * qe[b + 5]
            g2x += p2 * qe[b + 3]; g2y += p2 * qe[b + 4]; g2z += p2 * qe[b + 5]
            aa += ph * qe[b + 6]
            a1 += p1 * qe[b + 6]
            a2 += p2 * qe[b + 6]
        # Columns of A¹ = [∂y/∂ξ1, ∂y/∂ξ2, ∂y/∂ζ].
        c0x = y1x + hh * (z * g1x + z2 * (a1 * gx + aa * g1x))
        c0y = y1y + hh * (z * g1y + z2 * (a1 * gy + aa * g1y))
        c0z = y1z + hh * (z * g1z + z2 * (a1 * gz + aa * g1z))
        c1x = y2x + hh * (z * g2x + z2 * (a2 * gx + aa * g2x))
        c1y = y2y + hh * (z * g2y + z2 * (a2 * gy + aa * g2y))
        c1z = y2z + hh * (z * g2z + z2 * (a2 * gz + aa * g2z))
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
        wp = w[p]
        energy += 0.5 * wp * (s00 * e00 + s11 * e11 + s22 * e22 + 2.0 * (s01 * e01 + s02 * e02 + s12 * e12))
        # First Piola–Kirchhoff P = F S.
        p00 = f[0, 0] * s00 + f[0, 1] * s01 + f[0, 2] * s02
        p01 = f[0, 0] * s01 + f[0, 1] * s11 + f[0, 2] * s12
        p02 = f[0, 0] * s02 + f[0, 1] * s12 + f[0, 2] * s22
        p10 = f[1, 0] * s00 + f[1, 1] * s01 + f[1, 2] * s02
        p11 = f[1, 0] * s01 + f[1, 1] * s11 + f[1, 2] * s12
        p12 = f[1, 0] * s02 + f[1, 1] * s12 + f[1, 2] * s22
        p20 = f[2, 0] * s00 + f[2, 1] * s01 + f[2, 2] * s02
        p21 = f[2, 0] * s01 + f[2, 1] * s11 + f[2, 2] * s12
        p22 = f[2, 0] * s02 + f[2, 1] * s12 + f[2, 2] * s22

        for n in range(NODES):
            ph = phi[p, n]
            p1 = dphi[p, n, 0]
            p2 = dphi[p, n, 1]
            # ∂A¹/∂Y: [φ,1, φ,2, 0]; ∂A¹/∂G: [h(ζφ,1 + ζ²(a,1φ + aφ,1)), h(ζφ,2 + ζ²(a,2φ + aφ,2)), h(1+2aζ)φ].
            u0 = hh * (z * p1 + z2 * (a1 * ph + aa * p1))
            u1 = hh * (z * p2 + z2 * (a2 * ph + aa * p2))
            u2 = s3 * ph
            for j in range(3):
                dv[2 * n, j] = p1 * a0inv[p, 0, j] + p2 * a0inv[p, 1, j]
                dv[2 * n + 1, j] = u0 * a0inv[p, 0, j] + u1 * a0inv[p, 1, j] + u2 * a0inv[p, 2, j]
            # ∂A¹/∂aℓ = h [ζ²(φ,1 g + φ g,1), ζ²(φ,2 g + φ g,2), 2ζφ g] (columns); ∂F/∂aℓ = that · (A⁰)⁻¹.
            w0 = hh * z2
            k0x = w0 * (p1 * gx + ph * g1x); k0y = w0 * (p1 * gy + ph * g1y); k0z = w0 * (p1 * gz + ph * g1z)
            k1x = w0 * (p2 * gx + ph * g2x); k1y = w0 * (p2 * gy + ph * g2y); k1z = w0 * (p2 * gz + ph * g2z)
            w2 = 2.0 * hh * z * ph
            k2x = w2 * gx; k2y = w2 * gy; k2z = w2 * gz
            for j in range(3):
                i0 = a0inv[p, 0, j]
                i1 = a0inv[p, 1, j]
                i2 = a0inv[p, 2, j]
                dfa[n, 0, j] = k0x * i0 + k1x * i1 + k2x * i2
                dfa[n, 1, j] = k0y * i0 + k1y * i1 + k2y * i2
                dfa[n, 2, j] = k0z * i0 + k1z * i1 + k2z * i2
            for t in range(2):
                d0 = dv[2 * n + t, 0]
                d1 = dv[2 * n + t, 1]
                d2 = dv[2 * n + t, 2]
                b = NDOF_NODE * n + 3 * t
                re[b] += wp * (p00 * d0 + p01 * d1 + p02 * d2)
                re[b + 1] += wp * (p10 * d0 + p11 * d1 + p12 * d2)
                re[b + 2] += wp * (p20 * d0 + p21 * d1 + p22 * d2)
            re[NDOF_NODE * n + 6] += wp * (p00 * dfa[n, 0, 0] + p01 * dfa[n, 0, 1] + p02 * dfa[n, 0, 2]
                                           + p10 * dfa[n, 1, 0] + p11 * dfa[n, 1, 1] + p12 * dfa[n, 1, 2]
                                           + p20 * dfa[n, 2, 0] + p21 * dfa[n, 2, 1] + p22 * dfa[n, 2, 2])
        if not want_k:
            continue

        # Material part: Bᵀ C B with B the Voigt ∂E/∂q (engineering shears).
        for n in range(NODES):
            for t in range(2):
                d0 = dv[2 * n + t, 0]
                d1 = dv[2 * n + t, 1]
                d2 = dv[2 * n + t, 2]
                for i in range(3):
                    col = NDOF_NODE * n + 3 * t + i
                    fi0 = f[i, 0]
                    fi1 = f[i, 1]
                    fi2 = f[i, 2]
                    bmat[0, col] = fi0 * d0
                    bmat[1, col] = fi1 * d1
                    bmat[2, col] = fi2 * d2
                    bmat[3, col] = fi0 * d1 + fi1 * d0
                    bmat[4, col] = fi0 * d2 + fi2 * d0
                    bmat[5, col] = fi1 * d2 + fi2 * d1
            # ∂E/∂a = sym(Fᵀ ∂F/∂a): m_jk = Σ_i F_ij dfa_ik.
            col = NDOF_NODE * n + 6
            for (k, j, l) in ((0, 0, 0), (1, 1, 1), (2, 2, 2)):
                s = 0.0
                for i in range(3):
                    s += f[i, j] * dfa[n, i, l]
                bmat[k, col] = s
            for (k, j, l) in ((3, 0, 1), (4, 0, 2), (5, 1, 2)):
                s = 0.0
                for i in range(3):
                    s += f[i, j] * dfa[n, i, l] + f[i, l] * dfa[n, i, j]
                bmat[k, col] = s
        for c in range(NLOC):
            tr_b = bmat[0, c] + bmat[1, c] + bmat[2, c]
            cb[0, c] = wp * (lam_l * tr_b + 2.0 * mu * bmat[0, c])
            cb[1, c] = wp * (lam_l * tr_b + 2.0 * mu * bmat[1, c])
            cb[2, c] = wp * (lam_l * tr_b + 2.0 * mu * bmat[2, c])
            cb[3, c] = wp * mu * bmat[3, c]
            cb[4, c] = wp * mu * bmat[4, c]
            cb[5, c] = wp * mu * bmat[5, c]
        for r in range(NLOC):
            b0 = bmat[0, r]; b1 = bmat[1, r]; b2 = bmat[2, r]
            b3 = bmat[3, r]; b4 = bmat[4, r]; b5 = bmat[5, r]
            for c in range(r, NLOC):
                ke[r, c] += (b0 * cb[0, c] + b1 * cb[1, c] + b2 * cb[2, c]
                             + b3 * cb[3, c] + b4 * cb[4, c] + b5 * cb[5, c])

        # Geometric part S : sym(∂Fᵀ_α ∂F_β): δ_ij d_α S d_βᵀ among the Y/G rows.
        for va in range(2 * NODES):
            d0 = dv[va, 0]
            d1 = dv[va, 1]
            d2 = dv[va, 2]
            sa0 = wp * (s00 * d0 + s01 * d1 + s02 * d2)
            sa1 = wp * (s01 * d0 + s11 * d1 + s12 * d2)
            sa2 = wp * (s02 * d0 + s12 * d1 + s22 * d2)
            ra = NDOF_NODE * (va // 2) + 3 * (va % 2)
            for vb in range(va, 2 * NODES):
                gab = sa0 * dv[vb, 0] + sa1 * dv[vb, 1] + sa2 * dv[vb, 2]
                rb = NDOF_NODE * (vb // 2) + 3 * (vb % 2)
                for i in range(3):
                    ke[ra + i, rb + i] += gab
        # (aℓ, Y/G): (∂F/∂aℓ S d_βᵀ)_i; (aℓ, am): Σ_i ∂F/∂aℓ S ∂F/∂amᵀ; plus the (aℓ, Gm) second
        # derivative of F: P_i · (h [ζ²(φℓ,1 φm + φℓ φm,1), ζ²(φℓ,2 φm + φℓ φm,2), 2ζ φℓ φm] (A⁰)⁻¹).
        for n in range(NODES):
            ra = NDOF_NODE * n + 6
            # T = ∂F/∂aℓ S (3×3)
            t00 = dfa[n, 0, 0] * s00 + dfa[n, 0, 1] * s01 + dfa[n, 0, 2] * s02
            t01 = dfa[n, 0, 0] * s01 + dfa[n, 0, 1] * s11 + dfa[n, 0, 2] * s12
            t02 = dfa[n, 0, 0] * s02 + dfa[n, 0, 1] * s12 + dfa[n, 0, 2] * s22
            t10 = dfa[n, 1, 0] * s00 + dfa[n, 1, 1] * s01 + dfa[n, 1, 2] * s02
            t11 = dfa[n, 1, 0] * s01 + dfa[n, 1, 1] * s11 + dfa[n, 1, 2] * s12
            t12 = dfa[n, 1, 0] * s02 + dfa[n, 1, 1] * s12 + dfa[n, 1, 2] * s22
            t20 = dfa[n, 2, 0] * s00 + dfa[n, 2, 1] * s01 + dfa[n, 2, 2] * s02
            t21 = dfa[n, 2, 0] * s01 + dfa[n, 2, 1] * s11 + dfa[n, 2, 2] * s12
            t22 = dfa[n, 2, 0] * s02 + dfa[n, 2, 1] * s12 + dfa[n, 2, 2] * s22
            phn = phi[p, n]
            pn1 = dphi[p, n, 0]
            pn2 = dphi[p, n, 1]
            for vb in range(2 * NODES):
                d0 = dv[vb, 0]
                d1 = dv[vb, 1]
                d2 = dv[vb, 2]
                m = vb // 2
                rb = NDOF_NODE * m + 3 * (vb % 2)
                x0 = wp * (t00 * d0 + t01 * d1 + t02 * d2)
                x1 = wp * (t10 * d0 + t11 * d1 + t12 * d2)
                x2 = wp * (t20 * d0 + t21 * d1 + t22 * d2)
                if vb % 2 == 1:
                    phm = phi[p, m]
                    u0 = hh * z2 * (pn1 * phm + phn * dphi[p, m, 0])
                    u1 = hh * z2 * (pn2 * phm + phn * dphi[p, m, 1])
                    u2 = 2.0 * hh * z * phn * phm
                    e0 = u0 * a0inv[p, 0, 0] + u1 * a0inv[p, 1, 0] + u2 * a0inv[p, 2, 0]
                    e1 = u0 * a0inv[p, 0, 1] + u1 * a0inv[p, 1, 1] + u2 * a0inv[p, 2, 1]
                    e2 = u0 * a0inv[p, 0, 2] + u1 * a0inv[p, 1, 2] + u2 * a0inv[p, 2, 2]
                    x0 += wp * (p00 * e0 + p01 * e1 + p02 * e2)
                    x1 += wp * (p10 * e0 + p11 * e1 + p12 * e2)
                    x2 += wp * (p20 * e0 + p21 * e1 + p22 * e2)
                # Only the upper triangle is accumulated: the a row of node n sits after the Y/G
                # rows of node n and before those of later nodes.
                if rb < ra:
                    ke[rb, ra] += x0
                    ke[rb + 1, ra] += x1
                    ke[rb + 2, ra] += x2
                else:
                    ke[ra, rb] += x0
                    ke[ra, rb + 1] += x1
                    ke[ra, rb + 2] += x2
            for m in range(n, NODES):
                rb = NDOF_NODE * m + 6
                s = 0.0
                for i in range(3):
                    s += (t00 if i == 0 else (t10 if i == 1 else t20)) * dfa[m, i, 0]
                    s += (t01 if i == 0 else (t11 if i == 1 else t21)) * dfa[m, i, 1]
                    s += (t02 if i == 0 else (t12 if i == 1 else t22)) * dfa[m, i, 2]
                ke[ra, rb] += wp * s
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
    """Scratch buffers for :func:`shell_group` (allocated once per model): dv, dfa, f, bmat, cb, qe, re, ke."""
    return (np.zeros((2 * NODES, 3)), np.zeros((NODES, 3, 3)), np.zeros((3, 3)), np.zeros((6, NLOC)),
            np.zeros((6, NLOC)), np.zeros(NLOC), np.zeros(NLOC), np.zeros((NLOC, NLOC)))
