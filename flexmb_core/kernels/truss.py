"""Positional 2-node truss / bar actuator (SPEC §3, §4.2): Green–Lagrange strain, SVK, and
Kelvin–Voigt material damping.

The bar actuator replaces the reference length ``ℓ₀`` by the commanded ``L_a = λ ℓ₀``. With the
retardation time ``τ = η/E`` the axial stress is ``S = E (ε + τ ε̇)``, ε the Green–Lagrange strain
relative to ``L_a`` and ``ε̇ = (d·ḋ)/L_a² − (ℓ²/L_a²) λ̇/λ`` its rate (``d`` the end-to-end vector):
zero under any rigid velocity of the bar and under commanded extension at zero strain.
"""

from __future__ import annotations

from numba import njit

from ..jit import KERNEL
from .scatter import scatter_matrix


@njit(**KERNEL)
def truss_element(xe, ve, l0, ea, tau, lam, lam_rate, c_v, want_k, re, ke):
    """Residual, tangent, energy and dissipation of one bar.

    Parameters
    ----------
    xe, ve : (6,) float64 — end positions [Y¹, Y²] (m) and their velocities (m/s).
    l0 : float — reference length at λ = 1 (m).
    ea : float — axial stiffness E·A (N).
    tau : float — retardation time η/E (s); 0: undamped (``ve`` is not read).
    lam, lam_rate : float — actuator stretch (1 for a passive bar) and its rate (1/s).
    c_v : float — ∂v/∂q of the integrator (γ/(βΔt); 0 in statics).
    re : (6,) out — internal + viscous force (N).  ke : (6, 6) out — tangent ∂r/∂q + c_v ∂r/∂v (N/m).

    Returns
    -------
    (U, dU/dλ + ∂D/∂λ̇, dissipated power) in J, J, W.
    """
    la = lam * l0
    dx = xe[3] - xe[0]
    dy = xe[4] - xe[1]
    dz = xe[5] - xe[2]
    l2 = dx * dx + dy * dy + dz * dz
    inv2 = 1.0 / (la * la)
    eg = 0.5 * (l2 / (la * la) - 1.0)
    energy = 0.5 * ea * la * eg * eg
    rate = 0.0
    wx = 0.0
    wy = 0.0
    wz = 0.0
    lr = lam_rate / lam
    if tau > 0.0:
        wx = ve[3] - ve[0]
        wy = ve[4] - ve[1]
        wz = ve[5] - ve[2]
        rate = (dx * wx + dy * wy + dz * wz) * inv2 - l2 * inv2 * lr
    s = eg + tau * rate             # stress / E
    c = ea * s / la
    re[0] = -c * dx
    re[1] = -c * dy
    re[2] = -c * dz
    re[3] = c * dx
    re[4] = c * dy
    re[5] = c * dz
    if want_k:
        a = ea / (la * la * la) * (1.0 + tau * c_v)
        b = ea * tau / la * inv2    # viscous term at fixed v: (EAτ/L_a) d ⊗ ∂ε̇/∂d
        dd = (dx, dy, dz)
        ww = (wx - 2.0 * lr * dx, wy - 2.0 * lr * dy, wz - 2.0 * lr * dz)
        for i in range(3):
            for j in range(3):
                kij = a * dd[i] * dd[j] + b * dd[i] * ww[j]
                if i == j:
                    kij += c
                ke[i, j] = kij
                ke[i + 3, j + 3] = kij
                ke[i, j + 3] = -kij
                ke[i + 3, j] = -kij
    dudla = ea * eg * (0.5 * eg - l2 / (la * la)) - ea * tau * rate * l2 * inv2
    return energy, dudla * l0, ea * tau * la * rate * rate


@njit(**KERNEL)
def truss_group(q, v, edofs, l0, ea, tau, act, lam_act, lam_rate, c_v, smap, want_k, r, kdata, qe, ve, re, ke):
    """Loop over a truss group; scatter into ``r`` and CSR ``kdata``. Returns strain energy (J)
    and dissipated power (W)."""
    ne = edofs.shape[0]
    energy = 0.0
    diss = 0.0
    for e in range(ne):
        for i in range(6):
            qe[i] = q[edofs[e, i]]
        if tau[e] > 0.0:
            for i in range(6):
                ve[i] = v[edofs[e, i]]
        lam = 1.0
        lrate = 0.0
        if act[e] >= 0:
            lam = lam_act[act[e]]
            lrate = lam_rate[act[e]]
        u, _, de = truss_element(qe, ve, l0[e], ea[e], tau[e], lam, lrate, c_v, want_k, re, ke)
        energy += u
        diss += de
        for i in range(6):
            r[edofs[e, i]] += re[i]
        if want_k:
            scatter_matrix(smap[e], ke, kdata)
    return energy, diss


@njit(nogil=True, **KERNEL)
def truss_group_actuator_dudlam(q, v, edofs, l0, ea, tau, act, lam_act, lam_rate, c_v, want_k, out, qe, ve,
                                re, ke):
    """Accumulate dU/dλ (+ ∂D/∂λ̇) of every actuated bar into ``out[actuator]`` (J); ``want_k`` =
    False is an argument, not a literal (a literal compiles a second signature of the element kernel)."""
    for e in range(edofs.shape[0]):
        if act[e] < 0:
            continue
        for i in range(6):
            qe[i] = q[edofs[e, i]]
        if tau[e] > 0.0:
            for i in range(6):
                ve[i] = v[edofs[e, i]]
        _, dl, _ = truss_element(qe, ve, l0[e], ea[e], tau[e], lam_act[act[e]], lam_rate[act[e]], c_v, want_k,
                                 re, ke)
        out[act[e]] += dl
