"""Per-integration-point data of positional frame elements (SPEC §1.1, §1.2, §4.2, §9).

For each point of an element (axial Gauss point × section point) this computes, once:
``Dax, Dsec`` (3n × 3) with ``D̃ = Dax/λ + Dsec = C diag(1/λ, 1, 1) (A⁰)⁻¹ R₀``, the volume
weight ``w = W_ξ W_s det A⁰`` and the mass contributions. Curved reference axes are handled by
evaluating ``A⁰`` at every point.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

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


@njit(cache=True)
def _member_geometry_kernel(x, v1, v2, order, phi, dphi, wx, sec_pts, dax, dsec, w, psi, bad):
    """Every element of one member at once, element by element; inverse and determinant by
    cofactors. ``bad`` = [element, det] of the first element with a non-positive reference
    Jacobian, element −1 if none."""
    n = order + 1
    ne = w.shape[0]
    want_d = dax.shape[0] == ne            # the mass rule needs w and psi only
    n_axial = phi.shape[0]
    ns = sec_pts.shape[0]
    a0 = np.empty((3, 3))
    inv = np.empty((3, 3))
    r0 = np.empty((3, 3))
    m = np.empty((3, 3))
    for e in range(ne):
        base = e * order
        for g in range(n_axial):
            x_xi = np.zeros(3)
            v1c = np.zeros(3)
            for l in range(n):
                for c in range(3):
                    x_xi[c] += dphi[g, l] * x[base + l, c]
                    v1c[c] += phi[g, l] * v1[base + l, c]
            t0 = x_xi / np.sqrt(x_xi[0] ** 2 + x_xi[1] ** 2 + x_xi[2] ** 2)
            d = v1c[0] * t0[0] + v1c[1] * t0[1] + v1c[2] * t0[2]
            e1 = v1c - d * t0
            e1 /= np.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
            e2 = np.array([t0[1] * e1[2] - t0[2] * e1[1], t0[2] * e1[0] - t0[0] * e1[2],
                           t0[0] * e1[1] - t0[1] * e1[0]])
            for c in range(3):
                r0[c, 0] = t0[c]
                r0[c, 1] = e1[c]
                r0[c, 2] = e2[c]
            for sp in range(ns):
                s1, s2, ws = sec_pts[sp, 0], sec_pts[sp, 1], sec_pts[sp, 2]
                for c in range(3):
                    a0[c, 0] = 0.0
                    a0[c, 1] = 0.0
                    a0[c, 2] = 0.0
                    for l in range(n):
                        a0[c, 0] += dphi[g, l] * (x[base + l, c] + s1 * v1[base + l, c] + s2 * v2[base + l, c])
                        a0[c, 1] += phi[g, l] * v1[base + l, c]
                        a0[c, 2] += phi[g, l] * v2[base + l, c]
                det = (a0[0, 0] * (a0[1, 1] * a0[2, 2] - a0[1, 2] * a0[2, 1])
                       - a0[0, 1] * (a0[1, 0] * a0[2, 2] - a0[1, 2] * a0[2, 0])
                       + a0[0, 2] * (a0[1, 0] * a0[2, 1] - a0[1, 1] * a0[2, 0]))
                if det <= 0.0:
                    if bad[0] < 0:
                        bad[0] = e
                        bad[1] = det
                    continue
                inv[0, 0] = (a0[1, 1] * a0[2, 2] - a0[1, 2] * a0[2, 1]) / det
                inv[0, 1] = (a0[0, 2] * a0[2, 1] - a0[0, 1] * a0[2, 2]) / det
                inv[0, 2] = (a0[0, 1] * a0[1, 2] - a0[0, 2] * a0[1, 1]) / det
                inv[1, 0] = (a0[1, 2] * a0[2, 0] - a0[1, 0] * a0[2, 2]) / det
                inv[1, 1] = (a0[0, 0] * a0[2, 2] - a0[0, 2] * a0[2, 0]) / det
                inv[1, 2] = (a0[0, 2] * a0[1, 0] - a0[0, 0] * a0[1, 2]) / det
                inv[2, 0] = (a0[1, 0] * a0[2, 1] - a0[1, 1] * a0[2, 0]) / det
                inv[2, 1] = (a0[0, 1] * a0[2, 0] - a0[0, 0] * a0[2, 1]) / det
                inv[2, 2] = (a0[0, 0] * a0[1, 1] - a0[0, 1] * a0[1, 0]) / det
                for i in range(3):                      # m = A0⁻¹ R0
                    for j in range(3):
                        m[i, j] = inv[i, 0] * r0[0, j] + inv[i, 1] * r0[1, j] + inv[i, 2] * r0[2, j]
                row = g * ns + sp
                for l in range(n):
                    for j in range(3 if want_d else 0):
                        # C_ax = dφ_l [1, s1, s2]ᵀ e₁ᵀ (first column), C_sec = diag(0, φ_l, φ_l)
                        dax[e, row, 3 * l, j] = dphi[g, l] * m[0, j]
                        dax[e, row, 3 * l + 1, j] = s1 * dphi[g, l] * m[0, j]
                        dax[e, row, 3 * l + 2, j] = s2 * dphi[g, l] * m[0, j]
                        dsec[e, row, 3 * l, j] = 0.0
                        dsec[e, row, 3 * l + 1, j] = phi[g, l] * m[1, j]
                        dsec[e, row, 3 * l + 2, j] = phi[g, l] * m[2, j]
                    psi[e, row, 3 * l] = phi[g, l]
                    psi[e, row, 3 * l + 1] = phi[g, l] * s1
                    psi[e, row, 3 * l + 2] = phi[g, l] * s2
                w[e, row] = wx[g] * ws * det


def frame_member_geometry(x: np.ndarray, v1: np.ndarray, v2: np.ndarray, order: int, n_axial: int,
                          sec_pts: np.ndarray, elements: int, *, mass_only: bool = False
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Integration data of every element of a member, in one numba call (a 10⁵-element scene
    compiles in seconds; element by element in Python it took minutes).

    Parameters
    ----------
    x, v1, v2 : (elements · order + 1, 3) — the member's reference node positions (m) and unit
        section vectors (principal axes), node after node along the member; element ``e`` has the
        ``n = order + 1`` nodes from ``e · order``.
    order : int — Lagrange order.
    n_axial : int — Gauss points along ξ.
    sec_pts : (ns, 3) — section points (s1, s2, weight) in m, m, m².
    elements : int — number of elements.
    mass_only : bool — compute ``w`` and ``psi`` only (``dax``, ``dsec`` come back empty).

    Returns
    -------
    dax, dsec : (elements, nip, 3n, 3) with nip = n_axial · ns, station-major.
    w : (elements, nip) reference volume weights (m³).
    psi : (elements, nip, 3n) — ``φ_ℓ ψ_t`` per point, the kinetic-energy interpolation (mass).

    Raises
    ------
    ValueError
        For an element with a non-positive reference Jacobian (its index in the message).
    """
    n = order + 1
    _, wx, phi, dphi = frame_points(order, n_axial)
    nip = n_axial * sec_pts.shape[0]
    shape = (0 if mass_only else elements, nip, 3 * n, 3)
    dax = np.empty(shape)
    dsec = np.empty(shape)
    w = np.empty((elements, nip))
    psi = np.empty((elements, nip, 3 * n))
    bad = np.array([-1.0, 0.0])
    _member_geometry_kernel(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(v1, dtype=float),
                            np.ascontiguousarray(v2, dtype=float), order, phi, dphi, wx,
                            np.ascontiguousarray(sec_pts, dtype=float), dax, dsec, w, psi, bad)
    if bad[0] >= 0:
        raise ValueError(f"element {int(bad[0])}: frame element with non-positive reference Jacobian "
                         f"(det A0 = {bad[1]:.3e}); check node order and section vectors")
    return dax, dsec, w, psi


def frame_member_mass(psi: np.ndarray, w: np.ndarray, rho: float, inertia_scale: np.ndarray | None = None
                      ) -> np.ndarray:
    """Consistent mass matrices ``(elements, 9n, 9n)``: ``∫ρ φψ_a φψ_b dV · I₃`` (kg, kg·m…).

    ``inertia_scale`` (3n,) optionally rescales rows/columns per node-vector (benchmark data that
    give ρA and ρI independently of the stiffness section).
    """
    m_v = np.einsum("eip,ei,eiq->epq", psi, rho * w, psi)        # (ne, 3n, 3n)
    if inertia_scale is not None:
        m_v = m_v * np.sqrt(np.outer(inertia_scale, inertia_scale))
    ne, k, _ = m_v.shape
    out = np.zeros((ne, k, 3, k, 3))
    for a in range(3):
        out[:, :, a, :, a] = m_v
    return out.reshape(ne, 3 * k, 3 * k)
