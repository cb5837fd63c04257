"""Cross-sections: properties computed from the shape, and the quadrature over the section.

Section coordinates ``(s1, s2)`` are measured from the centroid along the principal axes, which
are the reference section vectors ``V1⁰, V2⁰``. A rectangle's ``width`` lies along ``V1`` and its
``height`` along ``V2``.

The strain energy density of a straight positional frame is a polynomial of degree 4 in
``(s1, s2)`` (F is linear in s, E quadratic), so the rules below integrate it exactly:
3×3 Gauss on rectangles, Radon's 7-point rule on discs, 2 rings × 6 on annuli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .model.shape import gauss_legendre


@dataclass(frozen=True)
class SectionProperties:
    """Geometric properties of a cross-section (SI units).

    Attributes
    ----------
    area : float — A (m²).
    i1, i2 : float — ∫s1² dA, ∫s2² dA (m⁴): bending about V2 and about V1 respectively.
    polar : float — I_p = i1 + i2 (m⁴).
    torsion : float — Saint-Venant torsion constant J (m⁴).
    shear_factor : float — k_s (Cowper), uniform shear stiffness k_s G A.
    points : (ns, 3) float64 — quadrature points (s1, s2, weight m²).
    """

    shape: str
    area: float
    i1: float
    i2: float
    polar: float
    torsion: float
    shear_factor: float
    points: np.ndarray


def _rectangle_torsion(b: float, h: float, terms: int = 50) -> float:
    a, c = max(b, h), min(b, h)
    s = sum(math.tanh(n * math.pi * a / (2 * c)) / n**5 for n in range(1, 2 * terms, 2))
    return a * c**3 * (1.0 / 3.0 - 64.0 / math.pi**5 * (c / a) * s)


def _disc_points(r_in: float, r_out: float) -> np.ndarray:
    """Degree-5 rules on a disc (Radon's 7 points) or an annulus (2 rings × hexagon, 12 points).

    Both integrate every monomial s1^a s2^b with a + b ≤ 5 exactly, which is all the straight
    frame's energy density needs (degree 4).
    """
    hexagon = np.arange(6) * math.pi / 3.0
    if r_in == 0.0:
        # Radon: centre weight πR²/4, six points at R·sqrt(2/3) with weight πR²/8 each.
        rr = r_out * math.sqrt(2.0 / 3.0)
        pts = [(0.0, 0.0, 0.25 * math.pi * r_out**2)]
        pts += [(rr * math.cos(t), rr * math.sin(t), 0.125 * math.pi * r_out**2) for t in hexagon]
        return np.array(pts, dtype=float)
    # ∫ f r dr = ½ ∫ f du with u = r²: the radial moments r^0, r^2, r^4 are u^0, u, u² → 2-point Gauss in u.
    xu, wu = gauss_legendre(2)
    u = 0.5 * (r_out**2 - r_in**2) * xu + 0.5 * (r_out**2 + r_in**2)
    wr = 0.5 * wu * 0.5 * (r_out**2 - r_in**2)
    pts = [(math.sqrt(ui) * math.cos(t), math.sqrt(ui) * math.sin(t), wi * 2.0 * math.pi / 6.0)
           for ui, wi in zip(u, wr) for t in hexagon]
    return np.array(pts, dtype=float)


def _rect_points(b: float, h: float, n: int = 3) -> np.ndarray:
    x, wx = gauss_legendre(n)
    pts = [(0.5 * b * xi, 0.5 * h * eta, 0.25 * b * h * wi * wj)
           for xi, wi in zip(x, wx) for eta, wj in zip(x, wx)]
    return np.array(pts, dtype=float)


def rectangle(width: float, height: float, nu: float, n_points: int = 3) -> SectionProperties:
    """Solid rectangle, ``width`` along V1 and ``height`` along V2 (m)."""
    pts = _rect_points(width, height, n_points)
    return _finish("rectangle", pts, _rectangle_torsion(width, height),
                   10.0 * (1.0 + nu) / (12.0 + 11.0 * nu))


def circle(radius: float, nu: float) -> SectionProperties:
    """Solid circle of ``radius`` (m)."""
    pts = _disc_points(0.0, radius)
    return _finish("circle", pts, 0.5 * math.pi * radius**4, 6.0 * (1.0 + nu) / (7.0 + 6.0 * nu))


def tube(outer_radius: float, inner_radius: float, nu: float) -> SectionProperties:
    """Circular tube (m); ``inner_radius < outer_radius``."""
    pts = _disc_points(inner_radius, outer_radius)
    m2 = (inner_radius / outer_radius) ** 2
    ks = 6.0 * (1.0 + nu) * (1.0 + m2) ** 2 / ((7.0 + 6.0 * nu) * (1.0 + m2) ** 2
                                                + (20.0 + 12.0 * nu) * m2)
    return _finish("tube", pts, 0.5 * math.pi * (outer_radius**4 - inner_radius**4), ks)


def _finish(shape: str, pts: np.ndarray, torsion: float, ks: float) -> SectionProperties:
    area = float(pts[:, 2].sum())
    i1 = float((pts[:, 0] ** 2 * pts[:, 2]).sum())
    i2 = float((pts[:, 1] ** 2 * pts[:, 2]).sum())
    pts.setflags(write=False)
    return SectionProperties(shape, area, i1, i2, i1 + i2, torsion, ks, pts)


def with_overrides(sec: SectionProperties, torsion: float | None,
                   shear_factor: float | None) -> SectionProperties:
    """Replace J and/or k_s (benchmarks that prescribe them, e.g. GJ = G·I_p)."""
    return SectionProperties(sec.shape, sec.area, sec.i1, sec.i2, sec.polar,
                             sec.torsion if torsion is None else float(torsion),
                             sec.shear_factor if shear_factor is None else float(shear_factor),
                             sec.points)
