"""Reference geometry of the cubic positional shell triangle: quadrature, shape functions, the
per-point (A⁰)⁻¹ and volume weights, and the constant mass matrix (compile time, numpy)."""

from __future__ import annotations

import numpy as np
from scipy.special import roots_jacobi, roots_legendre

# Local node order of the 10-node triangle, in area coordinates (L0, L1, L2) scaled by 3:
# vertices 0, 1, 2; two nodes on each edge 0→1, 1→2, 2→0 (the first nearer the edge's start);
# the centroid.
LOCAL_NODES_3L = np.array([[3, 0, 0], [0, 3, 0], [0, 0, 3],
                           [2, 1, 0], [1, 2, 0], [0, 2, 1], [0, 1, 2], [1, 0, 2], [2, 0, 1],
                           [1, 1, 1]], dtype=np.int64)


def triangle_rule(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Conical-product (Stroud) rule on the reference triangle {ξ1, ξ2 ≥ 0, ξ1 + ξ2 ≤ 1}.

    ``n × n`` points, exact for polynomials of total degree ``2n − 1``: Gauss–Jacobi (weight
    1 − u) in u, Gauss–Legendre in v, with ξ1 = u, ξ2 = v (1 − u).

    Returns
    -------
    points : (n², 2) — (ξ1, ξ2).  weights : (n²,) — summing to the area 1/2.
    """
    xu, wu = roots_jacobi(n, 1.0, 0.0)          # ∫ f (1 − x) dx on [−1, 1]
    xv, wv = roots_legendre(n)
    u = 0.5 * (xu + 1.0)
    v = 0.5 * (xv + 1.0)
    pts = np.array([[ui, vj * (1.0 - ui)] for ui in u for vj in v])
    wts = np.array([wi * wj / 8.0 for wi in wu for wj in wv])   # (1/2)(1/2)·(1/2) from the maps
    return pts, wts


def cubic_triangle(xi1: float, xi2: float) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Lagrange shape functions of the 10-node triangle at (ξ1, ξ2).

    Returns ``phi (10,)`` and ``dphi (10, 2)`` = (∂φ/∂ξ1, ∂φ/∂ξ2), with L0 = 1 − ξ1 − ξ2, L1 = ξ1,
    L2 = ξ2 and the node order of :data:`LOCAL_NODES_3L`.
    """
    lam = np.array([1.0 - xi1 - xi2, xi1, xi2])
    phi = np.empty(10)
    dl = np.zeros((10, 3))                       # ∂φ/∂(L0, L1, L2)
    for i in range(3):
        li = lam[i]
        phi[i] = 0.5 * li * (3.0 * li - 1.0) * (3.0 * li - 2.0)
        dl[i, i] = 0.5 * (27.0 * li * li - 18.0 * li + 2.0)
    for k, (i, j) in enumerate(((0, 1), (1, 2), (2, 0))):
        li, lj = lam[i], lam[j]
        a, b = 3 + 2 * k, 4 + 2 * k
        phi[a] = 4.5 * li * lj * (3.0 * li - 1.0)              # nearer node i
        dl[a, i] = 4.5 * lj * (6.0 * li - 1.0)
        dl[a, j] = 4.5 * li * (3.0 * li - 1.0)
        phi[b] = 4.5 * li * lj * (3.0 * lj - 1.0)              # nearer node j
        dl[b, j] = 4.5 * li * (6.0 * lj - 1.0)
        dl[b, i] = 4.5 * lj * (3.0 * lj - 1.0)
    phi[9] = 27.0 * lam[0] * lam[1] * lam[2]
    dl[9] = 27.0 * np.array([lam[1] * lam[2], lam[0] * lam[2], lam[0] * lam[1]])
    dphi = np.stack((dl[:, 1] - dl[:, 0], dl[:, 2] - dl[:, 0]), axis=1)
    return phi, dphi


def shell_rule(n_in_plane: int, n_thickness: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Tensor rule (triangle × thickness Gauss) and the shape functions at its points.

    Returns ``phi (npt, 10)``, ``dphi (npt, 10, 2)``, ``zeta (npt,)`` and ``weights (npt,)``
    (reference-space weights: they sum to 1/2 · 2 = 1), points ordered in-plane-major.
    """
    pts, wts = triangle_rule(n_in_plane)
    zs, wz = roots_legendre(n_thickness)
    npt = pts.shape[0] * zs.size
    phi = np.empty((npt, 10))
    dphi = np.empty((npt, 10, 2))
    zeta = np.empty(npt)
    weights = np.empty(npt)
    k = 0
    for (x1, x2), wp in zip(pts, wts):
        ph, dph = cubic_triangle(x1, x2)
        for z, w in zip(zs, wz):
            phi[k], dphi[k], zeta[k], weights[k] = ph, dph, z, wp * w
            k += 1
    return phi, dphi, zeta, weights


def shell_element_geometry(x: np.ndarray, v0: np.ndarray, half_thickness: float, phi: np.ndarray,
                           dphi: np.ndarray, zeta: np.ndarray, weights: np.ndarray,
                           where: str = "shell") -> tuple[np.ndarray, np.ndarray]:
    """(A⁰)⁻¹ and volume weights of one element at every point of the rule.

    Parameters
    ----------
    x, v0 : (10, 3) — reference nodal positions (m) and unit normals.
    half_thickness : h0/2 (m).

    Returns
    -------
    a0inv : (npt, 3, 3).  w : (npt,) — W·det A⁰ (m³).

    Raises
    ------
    ValueError
        if det A⁰ ≤ 0 somewhere (an element inverted against its normals, or a curvature radius
        smaller than the half thickness), naming ``where``.
    """
    npt = zeta.size
    a0inv = np.empty((npt, 3, 3))
    w = np.empty(npt)
    for p in range(npt):
        g = phi[p] @ v0
        a0 = np.column_stack((dphi[p, :, 0] @ x + half_thickness * zeta[p] * (dphi[p, :, 0] @ v0),
                              dphi[p, :, 1] @ x + half_thickness * zeta[p] * (dphi[p, :, 1] @ v0),
                              half_thickness * g))
        det = np.linalg.det(a0)
        if not det > 0.0:
            raise ValueError(f"{where}: reference map not positive (det A⁰ = {det:.3g}); the element is "
                             "inverted with respect to its nodal normals or thicker than its curvature radius")
        a0inv[p] = np.linalg.inv(a0)
        w[p] = weights[p] * det
    return a0inv, w


MEMBRANE_ALPHA = 0.25   # s = 1/√(1 + (α h²κ/t)²); chosen by measurement (docs/benchmarks/shell_locking.md)


def membrane_weight(x: np.ndarray, v0: np.ndarray, thickness: float, dphi: np.ndarray) -> float:
    """Weight s of the membrane strain beyond P1 in the assumed strains of one element
    (:mod:`flexmb_core.kernels.shell`): s = 1/√(1 + (α h_e² κ_e / t)²), α = :data:`MEMBRANE_ALPHA`.

    h_e is the longest chord between the element's vertices (m), κ_e the largest absolute principal
    curvature of the interpolated reference surface over the points of ``dphi`` (1/m), from its
    metric a_αβ = x,α·x,β and the interpolated normals' b_αβ = −½(x,α·v,β + x,β·v,α). h²κ/t
    measures how much a curved element's membrane strains lock its bending (s → 1 on flat elements
    and as the mesh is refined). α = 1/4: with α = 1 an octant of the pinched cylinder on 2 × 2 cells
    (45° per element) came out 47 % too soft with one diagonal pattern (the stabilization s² of the
    membrane modes beyond P1 too weak); with α = 1/4 no pattern overshoots and the hemisphere at 4 × 4
    to 8 × 8 is within 0.5 % of its 32 × 32 value.

    Parameters
    ----------
    x, v0 : (10, 3) — reference nodal positions (m) and unit normals.
    thickness : t = h0 (m).
    dphi : (npt, 10, 2) — shape function derivatives at the stiffness rule's points.
    """
    kappa = 0.0
    for p in range(dphi.shape[0]):
        a = dphi[p].T @ x                         # (2, 3) x,α
        dn = dphi[p].T @ v0                       # (2, 3) v,α
        metric = a @ a.T
        b = -0.5 * (a @ dn.T + dn @ a.T)
        low = np.linalg.cholesky(metric)
        li = np.linalg.inv(low)
        kappa = max(kappa, float(np.abs(np.linalg.eigvalsh(li @ b @ li.T)).max()))
    h = max(float(np.linalg.norm(x[i] - x[j])) for i, j in ((0, 1), (1, 2), (2, 0)))
    return 1.0 / float(np.sqrt(1.0 + (MEMBRANE_ALPHA * h * h * kappa / thickness) ** 2))


def shell_element_mass(phi: np.ndarray, zeta: np.ndarray, w: np.ndarray, rho: float,
                       half_thickness: float) -> np.ndarray:
    """Constant consistent mass (70 × 70) of one element (kg, kg·m, kg·m²).

    The kinetic energy is taken with the part of the velocity that is linear in the unknowns,
    ẏ ≈ Σφ(Ẏ + hζ Ġ) (SPEC §2), plus the strain-rate mode's own inertia hζ² ȧ G⁰ with the
    reference |G⁰| = 1: blocks ρ∫φφ, ρ∫φφ hζ and ρ∫φφ (hζ)² for Y–Y, Y–G and G–G (times I₃),
    ρ∫φφ (hζ²)² for a–a. Constant, symmetric, positive definite; the a–a block keeps the system
    regular at the thickness mode. ``w`` must come from a rule exact for ζ⁴ (3 Gauss points).
    """
    from ..kernels.shell import NDOF_NODE
    m = np.zeros((10 * NDOF_NODE, 10 * NDOF_NODE))
    h = half_thickness
    for p in range(zeta.size):
        pp = rho * w[p] * np.outer(phi[p], phi[p])          # (10, 10)
        z = zeta[p]
        blocks = ((0, 0, pp), (0, 3, pp * h * z), (3, 0, pp * h * z), (3, 3, pp * (h * z) ** 2))
        for oa, ob, val in blocks:
            for i in range(3):
                m[oa + i::NDOF_NODE, ob + i::NDOF_NODE] += val
        m[6::NDOF_NODE, 6::NDOF_NODE] += pp * (h * z * z) ** 2
    return m
