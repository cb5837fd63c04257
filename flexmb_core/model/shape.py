"""1D Lagrange shape functions on equally spaced nodes and Gauss–Legendre rules (compile time)."""

from __future__ import annotations

import numpy as np


def lagrange_1d(order: int, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shape functions and their ξ-derivatives on ``order + 1`` equally spaced nodes of [−1, 1].

    Parameters
    ----------
    order : int — polynomial order p (1…4).
    xi : (m,) float64 — evaluation points.

    Returns
    -------
    phi, dphi : (m, p+1) float64.
    """
    nodes = np.linspace(-1.0, 1.0, order + 1)
    xi = np.atleast_1d(np.asarray(xi, dtype=float))
    phi = np.ones((xi.size, order + 1))
    dphi = np.zeros((xi.size, order + 1))
    for a in range(order + 1):
        others = [b for b in range(order + 1) if b != a]
        denom = np.prod([nodes[a] - nodes[b] for b in others])
        for b in others:
            phi[:, a] *= xi - nodes[b]
        for c in others:
            term = np.ones(xi.size)
            for b in others:
                if b != c:
                    term *= xi - nodes[b]
            dphi[:, a] += term
        phi[:, a] /= denom
        dphi[:, a] /= denom
    return phi, dphi


def gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre points and weights on [−1, 1]."""
    return np.polynomial.legendre.leggauss(n)
