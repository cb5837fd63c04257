"""Structured meshes of cubic (10-node) shell triangles on parametric surfaces, with named edges.

Every generator returns a :class:`ShellMesh`: node positions and exact unit normals on the
surface, the 10-node connectivity and, for each named edge, its nodes in order along the edge.
Quad-type surfaces (rectangle, annulus, cylinder, spherical cap) sample a (3·n_u + 1) × (3·n_v + 1)
grid in the parameters (u, v) ∈ [0, 1]² and split each cell into two triangles; the triangle samples
a triangular lattice of 3·n + 1 points per side (n² triangles). All element nodes are grid points,
except the centroids of a closed cap's pole fan. A ``closed`` surface (a full turn in v) shares the
seam's nodes; grid points no element uses (at a pole) are dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .shell_geometry import LOCAL_NODES_3L


@dataclass(frozen=True)
class ShellMesh:
    """``x (N, 3)`` positions (m), ``normal (N, 3)`` unit normals, ``tri (ne, 10)`` node ids in
    the local order of :data:`~flexmb_core.model.shell_geometry.LOCAL_NODES_3L`; ``edges``: name →
    node ids along the edge (3·n + 1 of them); ``corners``: corner index → node id;
    ``param (N, 2)`` the (u, v) of each node (lattice coordinates for triangles)."""

    x: np.ndarray
    normal: np.ndarray
    tri: np.ndarray
    edges: dict[str, np.ndarray]
    corners: tuple[int, ...]
    param: np.ndarray


QUAD_EDGE_NAMES = {
    "rectangle": {"v0": "bottom", "u1": "right", "v1": "top", "u0": "left"},
    "annulus": {"u0": "inner", "u1": "outer", "v0": "start", "v1": "end"},
    "cylinder": {"u0": "bottom", "u1": "top", "v0": "start", "v1": "end"},
    "spherical_cap": {"u0": "hole", "u1": "rim", "v0": "start", "v1": "end"},
}
TRIANGLE_EDGE_NAMES = ("ab", "bc", "ca")


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _cell_triangles(i0: int, j0: int, nu: int, flip: bool) -> list[list[int]]:
    """Two 10-node triangles of the grid cell whose lower-left grid point is (i0, j0)."""
    if flip:
        verts = (((0, 0), (3, 0), (0, 3)), ((3, 0), (3, 3), (0, 3)))
    else:
        verts = (((0, 0), (3, 0), (3, 3)), ((0, 0), (3, 3), (0, 3)))
    out = []
    for tri in verts:
        v = np.array(tri)
        ids = []
        for l3 in LOCAL_NODES_3L:               # node = Σ L_k vertex_k, with 3L integer
            off = (l3 @ v) // 3
            ids.append((j0 + off[1]) * nu + i0 + off[0])
        out.append(ids)
    return out


def quad_surface(kind: str, surface, nu_el: int, nv_el: int, pattern: str = "alternate", *,
                 closed: bool = False, normal=None, pole: bool = False) -> ShellMesh:
    """Mesh of a parametric surface ``surface(u, v) -> (x, x_u, x_v)`` on [0, 1]².

    ``pattern``: diagonal of each cell — ``right`` (all from (0,0) to (1,1)), ``left`` (from (1,0)
    to (0,1)), ``alternate`` (chequered, no preferred direction). ``closed``: the surface is
    periodic in v (x(u, 0) = x(u, 1)); the two rows become one (a joined seam, not a slit) and the
    edges along v are dropped. ``normal(u, v, x)``: the unit normal where x_u × x_v may vanish
    (default: the normalized cross product). ``pole``: the row u = 0 is one point; its cells become
    a fan of one triangle per cell, whose nodes lie on the meridians v = const (conforming), and the
    edge u = 0 is dropped.
    """
    nu, nv = 3 * nu_el + 1, 3 * nv_el + 1
    uu, vv = np.meshgrid(np.linspace(0.0, 1.0, nu), np.linspace(0.0, 1.0, nv))   # (nv, nu)
    param = np.column_stack((uu.ravel(), vv.ravel()))
    x = np.empty((param.shape[0], 3))
    nrm = np.empty_like(x)
    for k, (u, v) in enumerate(param):
        p, pu, pv = surface(u, v)
        x[k] = p
        nrm[k] = normal(u, v, p) if normal is not None else _unit(np.cross(pu, pv))
    tri = []
    extra_x, extra_n, extra_p = [], [], []
    for b in range(nv_el):
        for a in range(nu_el):
            if pole and a == 0:
                tri.append(_fan_triangle(b, nu, x.shape[0] + len(extra_x)))
                uc, vc = (2.0 / 3.0) / nu_el, (b + 0.5) / nv_el        # the centroid in polar (u, v)
                p, pu, pv = surface(uc, vc)
                extra_x.append(p)
                extra_n.append(normal(uc, vc, p) if normal is not None else _unit(np.cross(pu, pv)))
                extra_p.append((uc, vc))
                continue
            flip = {"right": False, "left": True, "alternate": (a + b) % 2 == 1}[pattern]
            tri.extend(_cell_triangles(3 * a, 3 * b, nu, flip))
    if extra_x:
        x = np.vstack((x, extra_x))
        nrm = np.vstack((nrm, extra_n))
        param = np.vstack((param, extra_p))
    grid = np.arange(nu * nv).reshape(nv, nu)
    raw = {"v0": grid[0, :], "u1": grid[:, -1], "v1": grid[-1, :], "u0": grid[:, 0]}
    merge = np.arange(x.shape[0])
    if closed:
        merge[grid[-1, :]] = grid[0, :]
        raw.pop("v0"), raw.pop("v1")
    if pole:
        merge[grid[:, 0]] = grid[0, 0]
        raw.pop("u0")
    edges = {QUAD_EDGE_NAMES[kind][k]: v.copy() for k, v in raw.items()}
    corners = (int(grid[0, 0]), int(grid[0, -1]), int(grid[-1, -1]), int(grid[-1, 0]))
    return _compact(ShellMesh(x, nrm, np.asarray(tri, dtype=np.int64), edges, corners, param), merge)


def _fan_triangle(b: int, nu: int, centroid: int) -> list[int]:
    """The 10 node ids of the pole triangle of cell row b (v from 3b to 3b + 3): vertices pole (0, 3b),
    A (3, 3b), B (3, 3b + 3); its side nodes on the meridians v = 3b and 3b + 3 and on the ring u = 3,
    the centroid a node of its own (in the order of :data:`LOCAL_NODES_3L`)."""
    g = lambda i, j: j * nu + i          # noqa: E731 - grid id of lattice point (i along u, j along v)
    j0, j1 = 3 * b, 3 * b + 3
    return [g(0, j0), g(3, j0), g(3, j1), g(1, j0), g(2, j0), g(3, j0 + 1), g(3, j0 + 2), g(2, j1), g(1, j1),
            centroid]


def _compact(mesh: ShellMesh, merge: np.ndarray) -> ShellMesh:
    """Apply ``merge`` (node id → the id it is the same node as) and drop nodes no element uses."""
    if np.array_equal(merge, np.arange(merge.size)):
        return mesh
    tri = merge[mesh.tri]
    used = np.unique(tri)
    new = np.full(merge.size, -1, dtype=np.int64)
    new[used] = np.arange(used.size)
    edges = {k: new[merge[v]] for k, v in mesh.edges.items()}
    corners = tuple(int(new[merge[c]]) for c in mesh.corners)
    return ShellMesh(mesh.x[used], mesh.normal[used], new[tri], edges, corners, mesh.param[used])


def rectangle(corners: np.ndarray, divisions: tuple[int, int], pattern: str = "alternate") -> ShellMesh:
    """Bilinear patch through four corners c0, c1, c2, c3 (counter-clockwise about the normal).

    u runs c0 → c1, v runs c0 → c3. Edges: ``bottom`` (c0–c1), ``right`` (c1–c2), ``top``
    (c3–c2), ``left`` (c0–c3). A planar convex quadrilateral gives a flat mesh.
    """
    c0, c1, c2, c3 = (np.asarray(c, dtype=float) for c in corners)

    def surface(u, v):
        p = (1 - u) * (1 - v) * c0 + u * (1 - v) * c1 + u * v * c2 + (1 - u) * v * c3
        pu = (1 - v) * (c1 - c0) + v * (c2 - c3)
        pv = (1 - u) * (c3 - c0) + u * (c2 - c1)
        return p, pu, pv
    return quad_surface("rectangle", surface, divisions[0], divisions[1], pattern)


def _frame(axis, reference) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = _unit(np.asarray(axis, dtype=float))
    e1 = np.asarray(reference, dtype=float)
    e1 = _unit(e1 - (e1 @ n) * n)
    return n, e1, np.cross(n, e1)


def annulus(center, normal, reference, r_inner: float, r_outer: float, angles: tuple[float, float],
            divisions: tuple[int, int], pattern: str = "alternate", closed: bool = False) -> ShellMesh:
    """Flat annular sector: r from ``r_inner`` to ``r_outer`` (u), angle θ from ``angles[0]`` to
    ``angles[1]`` (v) measured from ``reference`` about ``normal``. A full turn (θ1 − θ0 = 2π)
    leaves the two radial edges ``start`` and ``end`` coincident but unconnected: a slit, unless
    ``closed`` (then one ring of nodes, no ``start``/``end``). Edges: ``inner``, ``outer``,
    ``start``, ``end``."""
    c = np.asarray(center, dtype=float)
    n, e1, e2 = _frame(normal, reference)
    t0, t1 = angles

    def surface(u, v):
        r = r_inner + u * (r_outer - r_inner)
        th = t0 + v * (t1 - t0)
        er = math.cos(th) * e1 + math.sin(th) * e2
        et = -math.sin(th) * e1 + math.cos(th) * e2
        return c + r * er, (r_outer - r_inner) * er, r * (t1 - t0) * et
    return quad_surface("annulus", surface, divisions[0], divisions[1], pattern, closed=closed)


def cylinder(origin, axis, reference, radius: float, length: float, angles: tuple[float, float],
             divisions: tuple[int, int], pattern: str = "alternate", closed: bool = False) -> ShellMesh:
    """Cylindrical patch: axial coordinate s = u·length from ``origin`` along ``axis``, angle θ
    from ``angles[0]`` to ``angles[1]`` (v) about ``axis`` from ``reference``. Normals point to the
    axis. Edges: ``bottom`` (s = 0), ``top`` (s = length), ``start`` (θ0), ``end`` (θ1).
    ``closed`` (θ1 − θ0 = 2π): the seam's nodes are one set of mesh nodes (a closed tube, not a
    slit); ``bottom`` and ``top`` are then loops (their last node is their first) and there is no
    ``start``/``end``."""
    o = np.asarray(origin, dtype=float)
    d, e1, e2 = _frame(axis, reference)
    t0, t1 = angles

    def surface(u, v):
        th = t0 + v * (t1 - t0)
        er = math.cos(th) * e1 + math.sin(th) * e2
        et = -math.sin(th) * e1 + math.cos(th) * e2
        return o + u * length * d + radius * er, length * d, radius * (t1 - t0) * et
    return quad_surface("cylinder", surface, divisions[0], divisions[1], pattern, closed=closed)


def spherical_cap(center, axis, reference, radius: float, polar_angles: tuple[float, float],
                  angles: tuple[float, float], divisions: tuple[int, int], pattern: str = "alternate",
                  closed: bool = False) -> ShellMesh:
    """Part of a sphere of ``radius`` about ``center``: polar angle α (from ``axis``, the pole) from
    ``polar_angles[0]`` to ``polar_angles[1]`` (u, rad), azimuth θ from ``angles[0]`` to ``angles[1]``
    (v, rad) about ``axis`` from ``reference``. Normals point outwards (x − center)/R.

    α0 > 0 leaves a polar hole (edge ``hole``); α0 = 0 closes the cap at the pole, one node there,
    with a fan of one cubic triangle per azimuthal cell in the first ring. ``closed`` (θ1 − θ0 = 2π)
    joins the seam as :func:`cylinder` does. Edges: ``hole`` (α0 > 0 only), ``rim`` (α1), ``start``
    (θ0), ``end`` (θ1) — the last two are meridians, absent when closed.
    """
    c = np.asarray(center, dtype=float)
    n, e1, e2 = _frame(axis, reference)
    a0, a1 = polar_angles
    t0, t1 = angles

    def surface(u, v):
        al = a0 + u * (a1 - a0)
        th = t0 + v * (t1 - t0)
        er = math.cos(th) * e1 + math.sin(th) * e2
        et = -math.sin(th) * e1 + math.cos(th) * e2
        p = c + radius * (math.sin(al) * er + math.cos(al) * n)
        p_u = radius * (a1 - a0) * (math.cos(al) * er - math.sin(al) * n)
        return p, p_u, radius * math.sin(al) * (t1 - t0) * et

    def outward(u, v, p):
        return _unit(p - c)
    return quad_surface("spherical_cap", surface, divisions[0], divisions[1], pattern, closed=closed,
                        normal=outward, pole=a0 == 0.0)


def triangle(corners: np.ndarray, divisions: int) -> ShellMesh:
    """Flat triangle a, b, c split into ``divisions²`` elements (edges ``ab``, ``bc``, ``ca``);
    the normal is (b − a) × (c − a)."""
    a, b, c = (np.asarray(p, dtype=float) for p in corners)
    m = 3 * divisions
    index = -np.ones((m + 1, m + 1), dtype=np.int64)
    pts, lat = [], []
    for j in range(m + 1):
        for i in range(m + 1 - j):
            index[i, j] = len(pts)
            pts.append(a + (i / m) * (b - a) + (j / m) * (c - a))
            lat.append((i, j))
    normal = _unit(np.cross(b - a, c - a))
    tri = []
    for bj in range(divisions):
        for ai in range(divisions - bj):
            i0, j0 = 3 * ai, 3 * bj
            cells = [((i0, j0), (i0 + 3, j0), (i0, j0 + 3))]
            if ai + bj <= divisions - 2:
                cells.append(((i0 + 3, j0), (i0 + 3, j0 + 3), (i0, j0 + 3)))
            for verts in cells:
                v = np.array(verts)
                tri.append([index[tuple((l3 @ v) // 3)] for l3 in LOCAL_NODES_3L])
    edges = {"ab": np.array([index[i, 0] for i in range(m + 1)]),
             "bc": np.array([index[m - j, j] for j in range(m + 1)]),
             "ca": np.array([index[0, m - j] for j in range(m + 1)])}
    corners_ = (int(index[0, 0]), int(index[m, 0]), int(index[0, m]))
    x = np.asarray(pts)
    return ShellMesh(x, np.tile(normal, (x.shape[0], 1)), np.asarray(tri, dtype=np.int64), edges, corners_,
                     np.asarray(lat, dtype=float))


def edge_weights(x: np.ndarray) -> np.ndarray:
    """Consistent nodal weights (m) of a uniform line load along an edge given by its 3·n + 1
    reference nodes ``x`` (cubic segments): w_k = ∫ φ_k ds, exact for straight edges and to the
    rule's degree (6-point Gauss) on curved ones. Σ w_k is the edge length."""
    from scipy.special import roots_legendre
    xg, wg = roots_legendre(6)
    s = 0.5 * (xg + 1.0)
    nodes = np.array([0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0])
    w = np.zeros(x.shape[0])
    for seg in range(0, x.shape[0] - 1, 3):
        xs = x[seg:seg + 4]
        for sk, wk in zip(s, wg):
            phi = np.array([np.prod([(sk - nodes[m]) / (nodes[k] - nodes[m]) for m in range(4) if m != k])
                            for k in range(4)])
            dphi = np.array([sum(np.prod([(sk - nodes[m]) / (nodes[k] - nodes[m])
                                          for m in range(4) if m not in (k, l)]) / (nodes[k] - nodes[l])
                                 for l in range(4) if l != k) for k in range(4)])
            jac = np.linalg.norm(dphi @ xs)
            w[seg:seg + 4] += 0.5 * wk * phi * jac
    return w
