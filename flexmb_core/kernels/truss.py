"""Positional 2-node truss / bar actuator (SPEC §3, §4.2): Green–Lagrange strain, SVK.

The bar actuator replaces the reference length ``ℓ₀`` by the commanded ``L_a = λ ℓ₀``.
"""

from __future__ import annotations

from numba import njit

from .scatter import scatter_matrix


@njit(cache=True)
def truss_element(xe, l0, ea, lam, want_k, re, ke):
    """Residual, tangent and energy of one bar.

    Parameters
    ----------
    xe : (6,) float64 — end positions [Y¹, Y²] (m).
    l0 : float — reference length at λ = 1 (m).
    ea : float — axial stiffness E·A (N).
    lam : float — actuator stretch (1 for a passive bar).
    re : (6,) out — internal force (N).  ke : (6, 6) out — tangent (N/m).

    Returns
    -------
    (U, dU/dλ) in J.
    """
    la = lam * l0
    dx = xe[3] - xe[0]
    dy = xe[4] - xe[1]
    dz = xe[5] - xe[2]
    l2 = dx * dx + dy * dy + dz * dz
    eg = 0.5 * (l2 / (la * la) - 1.0)
    energy = 0.5 * ea * la * eg * eg
    c = ea * eg / la
    re[0] = -c * dx
    re[1] = -c * dy
    re[2] = -c * dz
    re[3] = c * dx
    re[4] = c * dy
    re[5] = c * dz
    if want_k:
        a = ea / (la * la * la)
        dd = (dx, dy, dz)
        for i in range(3):
            for j in range(3):
                kij = a * dd[i] * dd[j]
                if i == j:
                    kij += c
                ke[i, j] = kij
                ke[i + 3, j + 3] = kij
                ke[i, j + 3] = -kij
                ke[i + 3, j] = -kij
    dudla = ea * eg * (0.5 * eg - l2 / (la * la))
    return energy, dudla * l0


@njit(cache=True)
def truss_group(q, edofs, l0, ea, act, lam_act, smap, want_k, r, kdata, qe, re, ke):
    """Loop over a truss group; scatter into ``r`` and CSR ``kdata``. Returns strain energy (J)."""
    ne = edofs.shape[0]
    energy = 0.0
    for e in range(ne):
        for i in range(6):
            qe[i] = q[edofs[e, i]]
        lam = 1.0
        if act[e] >= 0:
            lam = lam_act[act[e]]
        u, _ = truss_element(qe, l0[e], ea[e], lam, want_k, re, ke)
        energy += u
        for i in range(6):
            r[edofs[e, i]] += re[i]
        if want_k:
            scatter_matrix(smap[e], ke, kdata)
    return energy


@njit(cache=True)
def truss_group_actuator_dudlam(q, edofs, l0, ea, act, lam_act, want_k, out, qe, re, ke):
    """Accumulate dU/dλ of every actuated bar into ``out[actuator]`` (J); ``want_k`` = False is
    an argument, not a literal (a literal compiles a second signature of the element kernel)."""
    for e in range(edofs.shape[0]):
        if act[e] < 0:
            continue
        for i in range(6):
            qe[i] = q[edofs[e, i]]
        _, dl = truss_element(qe, l0[e], ea[e], lam_act[act[e]], want_k, re, ke)
        out[act[e]] += dl
