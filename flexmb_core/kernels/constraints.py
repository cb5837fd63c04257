"""Rigid connection of non-collinear frame members by Lagrange multipliers (SPEC §5.4, §1.8).

Member b's section vectors at the corner are held to constant combinations of member a's frame
W = (V1a, V2a, V1a × V2a):  c_k = V_kb − Σ_j α_kj W_j = 0  (k = 1, 2; 6 equations). The positions
are shared through the node. Each corner is assembled like an element over 18 local unknowns
[V1b, V2b, V1a, V2a, λ1, λ2] (λ_k ∈ ℝ³, N·m per unit vector): residual rows Gᵀλ and c(q), tangent
[[Σλ∇²c, Gᵀ], [G, 0]] — exact, the cross product giving the only second derivatives.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True)
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
            n = 0
            for i in range(18):
                for j in range(18):
                    s = smap[c, n]
                    if s >= 0:
                        kdata[s] += ke[i, j]
                    n += 1


@njit(cache=True)
def _levi(i, j, m):
    """Levi-Civita symbol ε_ijm."""
    if i == j or j == m or i == m:
        return 0.0
    if (i, j, m) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        return 1.0
    return -1.0
