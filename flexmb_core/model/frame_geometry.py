"""Per-integration-point data of positional frame elements (SPEC §1.1, §1.2, §4.2, §9).

For each point of an element (axial Gauss point × section point) this computes, once:
``Dax, Dsec`` (3n × 3) with ``D̃ = Dax/λ + Dsec = C diag(1/λ, 1, 1) (A⁰)⁻¹ R₀``, the volume
weight ``w = W_ξ W_s det A⁰`` and the mass contributions. Curved reference axes are handled by
evaluating ``A⁰`` at every point.
"""

from __future__ import annotations

import functools

import numpy as np

from .shape import gauss_legendre, lagrange_1d


@functools.lru_cache(maxsize=64)
def frame_points(order: int, n_axial: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Shape functions at the axial Gauss points: ``(xi, W, phi (m, n), dphi (m, n))`` (cached per
    (order, n_axial): compiling 10⁴ elements computed them 2·10⁴ times; read-only)."""
    xi, wx = gauss_legendre(n_axial)
    phi, dphi = lagrange_1d(order, xi)
    for a in (xi, wx, phi, dphi):
        a.setflags(write=False)
    return xi, wx, phi, dphi


def frame_element_geometry(x_nodes: np.ndarray, v1_nodes: np.ndarray, v2_nodes: np.ndarray,
                           order: int, n_axial: int, sec_pts: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Integration data of one frame element.

    Parameters
    ----------
    x_nodes, v1_nodes, v2_nodes : (n, 3) — reference node positions (m) and unit section
        vectors (principal axes) at the element's ``n = order + 1`` nodes.
    order : int — Lagrange order.
    n_axial : int — Gauss points along ξ.
    sec_pts : (ns, 3) — section points (s1, s2, weight) in m, m, m².

    Returns
    -------
    dax, dsec : (nip, 3n, 3) with nip = n_axial · ns, station-major.
    w : (nip,) reference volume weights (m³).
    psi : (nip, 3n) — ``φ_ℓ ψ_t`` per point, the kinetic-energy interpolation (mass matrix).
    """
    n = order + 1
    _, wx, phi, dphi = frame_points(order, n_axial)
    ns = sec_pts.shape[0]
    nip = n_axial * ns
    dax = np.zeros((nip, 3 * n, 3))
    dsec = np.zeros((nip, 3 * n, 3))
    w = np.zeros(nip)
    psi = np.zeros((nip, 3 * n))
    s1, s2, ws = sec_pts[:, 0], sec_pts[:, 1], sec_pts[:, 2]                # (ns,)
    for g in range(n_axial):
        ph = phi[g]
        dph = dphi[g]
        x_xi = dph @ x_nodes          # (3,) axis tangent (unnormalised)
        v1c = ph @ v1_nodes
        t0 = x_xi / np.linalg.norm(x_xi)
        e1 = v1c - (v1c @ t0) * t0
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(t0, e1)
        r0 = np.column_stack((t0, e1, e2))
        # all section points of this station at once (the same operations, point by point)
        pts = x_nodes + s1[:, None, None] * v1_nodes + s2[:, None, None] * v2_nodes   # (ns, n, 3)
        a0 = np.empty((ns, 3, 3))
        a0[:, :, 0] = dph @ pts
        a0[:, :, 1] = ph @ v1_nodes
        a0[:, :, 2] = ph @ v2_nodes
        det = np.linalg.det(a0)                                                      # (ns,)
        if np.any(det <= 0.0):
            raise ValueError("frame element with non-positive reference Jacobian "
                             f"(det A0 = {det[np.argmax(det <= 0.0)]:.3e}); check node order and section vectors")
        a0inv_r0 = np.linalg.inv(a0) @ r0                                            # (ns, 3, 3)
        rows = slice(g * ns, g * ns + ns)
        for l in range(n):
            c_ax = np.zeros((ns, 3, 3))
            c_ax[:, 0, 0] = dph[l]
            c_ax[:, 1, 0] = s1 * dph[l]
            c_ax[:, 2, 0] = s2 * dph[l]
            c_sec = np.array([[0, 0, 0], [0, ph[l], 0], [0, 0, ph[l]]], dtype=float)
            dax[rows, 3 * l:3 * l + 3] = c_ax @ a0inv_r0
            dsec[rows, 3 * l:3 * l + 3] = c_sec @ a0inv_r0
            psi[rows, 3 * l] = ph[l]
            psi[rows, 3 * l + 1] = ph[l] * s1
            psi[rows, 3 * l + 2] = ph[l] * s2
        w[rows] = wx[g] * ws * det
    return dax, dsec, w, psi


def frame_element_mass(psi: np.ndarray, w: np.ndarray, rho: float,
                       inertia_scale: np.ndarray | None = None) -> np.ndarray:
    """Consistent mass matrix ``(9n, 9n)`` of one element: ``∫ρ φψ_a φψ_b dV · I₃`` (kg, kg·m…).

    ``inertia_scale`` (3n,) optionally rescales rows/columns per node-vector (benchmark data that
    give ρA and ρI independently of the stiffness section).
    """
    m_v = (psi * (rho * w)[:, None]).T @ psi  # (3n, 3n)
    if inertia_scale is not None:
        m_v = m_v * np.sqrt(np.outer(inertia_scale, inertia_scale))
    return np.kron(m_v, np.eye(3))
