"""Rigid connection of non-collinear frame members by Lagrange multipliers (SPEC §5.4, §1.8).

Member b's section vectors at the corner are held to constant combinations of member a's frame
W = (V1a, V2a, V1a × V2a):  c_k = V_kb − Σ_j α_kj W_j = 0  (k = 1, 2; 6 equations). The positions
are shared through the node. Each corner is assembled like an element over 18 local unknowns
[V1b, V2b, V1a, V2a, λ1, λ2] (λ_k ∈ ℝ³, N·m per unit vector): residual rows Gᵀλ and c(q), tangent
[[Σλ∇²c, Gᵀ], [G, 0]] — exact, the cross product giving the only second derivatives.
"""

from __future__ import annotations

from numba import njit

from ..jit import KERNEL
from .scatter import scatter_matrix


@njit(**KERNEL)
def rigid_corner_group(q, mult, dofs, alpha, smap, want_k, r, rc, kdata, ke):
    """Constraint forces into ``r`` (ndof), violations into ``rc`` (6·nc), tangent into ``kdata``.

    Parameters
    ----------
    q : (ndof,) — unknowns.  mult : (6·nc,) — multipliers [λ1, λ2] per corner.
    dofs : (nc, 12) int64 — global ids of [V1b, V2b, V1a, V2a].
    alpha : (nc, 2, 3) — α_kj from the reference frames.
    smap : (nc, 324) int64 — CSR position of each entry of the 18 × 18 local matrix (−1: none).
    ke : (18, 18) scratch.
    """
    for c in range(dofs.shape[0]):
        v1a = (q[dofs[c, 6]], q[dofs[c, 7]], q[dofs[c, 8]])
        v2a = (q[dofs[c, 9]], q[dofs[c, 10]], q[dofs[c, 11]])
        w3 = (v1a[1] * v2a[2] - v1a[2] * v2a[1], v1a[2] * v2a[0] - v1a[0] * v2a[2],
              v1a[0] * v2a[1] - v1a[1] * v2a[0])
        if want_k:
            ke[:, :] = 0.0
        for k in range(2):
            a1 = alpha[c, k, 0]
            a2 = alpha[c, k, 1]
            a3 = alpha[c, k, 2]
            for i in range(3):
                lam = mult[6 * c + 3 * k + i]
                rc[6 * c + 3 * k + i] = q[dofs[c, 3 * k + i]] - a1 * v1a[i] - a2 * v2a[i] - a3 * w3[i]
                # Gradient row of c_ki: +e_i on V_kb; −a1 e_i − a3 ∂(W3_i)/∂V1a on V1a; likewise V2a.
                # ∂(V1×V2)_i/∂V1_j = ε_ijm V2_m... written out: W3_i = ε_ijm V1_j V2_m.
                r[dofs[c, 3 * k + i]] += lam
                for j in range(3):
                    g1 = -a1 * (1.0 if i == j else 0.0)
                    g2 = -a2 * (1.0 if i == j else 0.0)
                    for m in range(3):
                        eps = _levi(i, j, m)
                        if eps != 0.0:
                            g1 -= a3 * eps * v2a[m]   # ∂W3_i/∂V1a_j
                            g2 -= a3 * _levi(i, m, j) * v1a[m]   # ∂W3_i/∂V2a_j
                    r[dofs[c, 6 + j]] += lam * g1
                    r[dofs[c, 9 + j]] += lam * g2
                    if want_k:
                        row = 12 + 3 * k + i
                        ke[row, 6 + j] += g1
                        ke[6 + j, row] += g1
                        ke[row, 9 + j] += g2
                        ke[9 + j, row] += g2
                if want_k:
                    row = 12 + 3 * k + i
                    ke[row, 3 * k + i] += 1.0
                    ke[3 * k + i, row] += 1.0
                    # λ·∇²c: −a3 λ_ki ε_ijm on (V1a_j, V2a_m) and its transpose
                    for j in range(3):
                        for m in range(3):
                            eps = _levi(i, j, m)
                            if eps != 0.0:
                                h = -a3 * lam * eps
                                ke[6 + j, 9 + m] += h
                                ke[9 + m, 6 + j] += h
        if want_k:
            scatter_matrix(smap[c], ke, kdata)


@njit(**KERNEL)
def _levi(i, j, m):
    """Levi-Civita symbol ε_ijm."""
    if i == j or j == m or i == m:
        return 0.0
    if (i, j, m) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        return 1.0
    return -1.0


@njit(**KERNEL)
def _skew_mul(a, b):
    """a × b for 3-tuples/arrays."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(**KERNEL)
def _frame_fibre(c, v1, v2, w3):
    """Σ_j c_j W_j with W = (V1, V2, V1 × V2)."""
    return (c[0] * v1[0] + c[1] * v2[0] + c[2] * w3[0], c[0] * v1[1] + c[1] * v2[1] + c[2] * w3[1],
            c[0] * v1[2] + c[1] * v2[2] + c[2] * w3[2])


@njit(**KERNEL)
def _dfibre(c, v1, v2, which, i, j):
    """∂(Σ c W)_i / ∂V_which_j: c1 δ − c3 [V2]× (which = 0) or c2 δ + c3 [V1]× (which = 1)."""
    d = 1.0 if i == j else 0.0
    if which == 0:
        return c[0] * d - c[2] * _skew(v2, i, j)
    return c[1] * d + c[2] * _skew(v1, i, j)


@njit(**KERNEL)
def _skew(a, i, j):
    """[a]×_ij (so that [a]× b = a × b)."""
    if i == j:
        return 0.0
    if i == 0:
        return -a[2] if j == 1 else a[1]
    if i == 1:
        return a[2] if j == 0 else -a[0]
    return -a[1] if j == 0 else a[0]


@njit(**KERNEL)
def hinge_group(q, mult, offset, dofs, alpha, beta, smap, want_k, r, rc, kdata, ke):
    """Revolute joints whose axis lies in no section plane, by multipliers (SPEC §5.2):
    c_k = a·b_k = 0 (k = 1, 2) with a = Σ α_j W_j^A the axis fibre of body A and b_k = Σ β_kj W_j^B
    two fibres of body B orthogonal to the axis in the reference configuration.

    ``dofs (nh, 12)`` = [V1A, V2A, V1B, V2B]; ``alpha (nh, 3)``; ``beta (nh, 2, 3)``; multipliers at
    ``mult[offset + 2h + k]``; violations into ``rc`` at the same place; local unknowns
    [V1A, V2A, V1B, V2B, λ1, λ2] (14), ``smap (nh, 196)``, ``ke`` (14, 14) scratch.
    """
    for h in range(dofs.shape[0]):
        va1 = (q[dofs[h, 0]], q[dofs[h, 1]], q[dofs[h, 2]])
        va2 = (q[dofs[h, 3]], q[dofs[h, 4]], q[dofs[h, 5]])
        vb1 = (q[dofs[h, 6]], q[dofs[h, 7]], q[dofs[h, 8]])
        vb2 = (q[dofs[h, 9]], q[dofs[h, 10]], q[dofs[h, 11]])
        wa3 = _skew_mul(va1, va2)
        wb3 = _skew_mul(vb1, vb2)
        al = alpha[h]
        f = _frame_fibre(al, va1, va2, wa3)
        if want_k:
            ke[:, :] = 0.0
        for k in range(2):
            be = beta[h, k]
            g = _frame_fibre(be, vb1, vb2, wb3)
            lam = mult[offset + 2 * h + k]
            rc[offset + 2 * h + k] = f[0] * g[0] + f[1] * g[1] + f[2] * g[2]
            row = 12 + k
            # gradient: ∂c/∂V_A = (∂f/∂V_A)ᵀ g, ∂c/∂V_B = (∂g/∂V_B)ᵀ f
            for blk in range(4):
                for j in range(3):
                    s = 0.0
                    for i in range(3):
                        if blk < 2:
                            s += _dfibre(al, va1, va2, blk, i, j) * g[i]
                        else:
                            s += _dfibre(be, vb1, vb2, blk - 2, i, j) * f[i]
                    r[dofs[h, 3 * blk + j]] += lam * s
                    if want_k:
                        ke[row, 3 * blk + j] += s
                        ke[3 * blk + j, row] += s
            if want_k:
                # λ ∂²c: A–A and B–B from the cross products, A–B from the product of the two fibres
                for i in range(3):
                    for j in range(3):
                        haa = -al[2] * lam * _skew(g, i, j)           # (V1A_i, V2A_j)
                        ke[i, 3 + j] += haa
                        ke[3 + j, i] += haa
                        hbb = -be[2] * lam * _skew(f, i, j)           # (V1B_i, V2B_j)
                        ke[6 + i, 9 + j] += hbb
                        ke[9 + j, 6 + i] += hbb
                for ba in range(2):
                    for bb in range(2):
                        for i in range(3):
                            for j in range(3):
                                s = 0.0
                                for m in range(3):
                                    s += _dfibre(al, va1, va2, ba, m, i) * _dfibre(be, vb1, vb2, bb, m, j)
                                ke[3 * ba + i, 6 + 3 * bb + j] += lam * s
                                ke[6 + 3 * bb + j, 3 * ba + i] += lam * s
        if want_k:
            scatter_matrix(smap[h], ke, kdata)


@njit(**KERNEL)
def director_tie_group(q, mult, offset, dofs, alpha, smap, want_k, r, rc, kdata, ke):
    """Shell director tied to a frame section (``shell_rigid`` joints), by multipliers:
    c = G − Σ α_j W_j = 0 (3 equations) with W = (V1, V2, V1 × V2) of the frame node and α from the
    reference geometry (|G⁰| = 1 ⇒ the tie also holds the director's length at the node).

    ``dofs (nt, 9)`` = [G, V1, V2]; ``alpha (nt, 3)``; multipliers at ``mult[offset + 3t + i]``,
    violations into ``rc`` at the same place; local unknowns [G, V1, V2, λ] (12), ``smap (nt, 144)``,
    ``ke (12, 12)`` scratch.
    """
    for t in range(dofs.shape[0]):
        v1 = (q[dofs[t, 3]], q[dofs[t, 4]], q[dofs[t, 5]])
        v2 = (q[dofs[t, 6]], q[dofs[t, 7]], q[dofs[t, 8]])
        w3 = _skew_mul(v1, v2)
        al = alpha[t]
        f = _frame_fibre(al, v1, v2, w3)
        lam = (mult[offset + 3 * t], mult[offset + 3 * t + 1], mult[offset + 3 * t + 2])
        if want_k:
            ke[:, :] = 0.0
        for i in range(3):
            rc[offset + 3 * t + i] = q[dofs[t, i]] - f[i]
            r[dofs[t, i]] += lam[i]
            if want_k:
                ke[9 + i, i] += 1.0
                ke[i, 9 + i] += 1.0
            for blk in range(2):
                for j in range(3):
                    g = -_dfibre(al, v1, v2, blk, i, j)
                    r[dofs[t, 3 + 3 * blk + j]] += lam[i] * g
                    if want_k:
                        ke[9 + i, 3 + 3 * blk + j] += g
                        ke[3 + 3 * blk + j, 9 + i] += g
        if want_k:
            # Σ_i λ_i ∂²c_i/∂V1_j∂V2_m = −α3 Σ_i λ_i ε_ijm = α3 [λ]×_jm
            for j in range(3):
                for m in range(3):
                    h = al[2] * _skew(lam, j, m)
                    ke[3 + j, 6 + m] += h
                    ke[6 + m, 3 + j] += h
            scatter_matrix(smap[t], ke, kdata)
