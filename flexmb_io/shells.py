"""Shells for drawing: each cubic triangle as flat triangles through its nodes, and every shell's
node positions gathered from the state in one ``np.take``.

A shell element is a 10-node cubic triangle (:data:`flexmb_core.model.shell_geometry.LOCAL_NODES_3L`:
vertices 0, 1, 2; edge nodes 3, 4 on 0→1, 5, 6 on 1→2, 7, 8 on 2→0; centroid 9). Its nodes sit on
the lattice of barycentric coordinates (i, j, k)/3, which splits it into 9 flat triangles through
its own nodes — 6 pointing like the element, 3 upside down — so a drawing follows the deformed
shell at every node and needs no sampling of the shape functions.

Pure NumPy (no ROS, no rerun): the ``~/shape`` messages, the live fillers and the rerun view all
draw from :class:`ShellShapes`.
"""

from __future__ import annotations

import numpy as np

from flexmb_core.model.shell_geometry import LOCAL_NODES_3L

SUBTRIANGLES_PER_ELEMENT = 9


def _subtriangles() -> np.ndarray:
    """(9, 3) local node ids of the flat triangles of one cubic triangle, each ordered like the
    element (vertex 0 → 1 → 2), so their normals agree with the element's."""
    node = {tuple(p): k for k, p in enumerate(LOCAL_NODES_3L.tolist())}     # lattice point → local id
    tris = []
    # upright: the corners next to a lattice point p with |p| = 2, in the directions of vertices 0, 1, 2
    for i in range(3):
        for j in range(3 - i):
            k = 2 - i - j
            tris.append((node[(i + 1, j, k)], node[(i, j + 1, k)], node[(i, j, k + 1)]))
    # upside down: around p with |p| = 1; a point reflection of an upright one, same orientation
    for i in range(2):
        for j in range(2 - i):
            k = 1 - i - j
            tris.append((node[(i, j + 1, k + 1)], node[(i + 1, j, k + 1)], node[(i + 1, j + 1, k)]))
    return np.array(tris, dtype=np.int64)


SUBTRIANGLES = _subtriangles()        # (9, 3) local node ids


def shell_triangles(tri: np.ndarray) -> np.ndarray:
    """Flat triangles of a shell mesh.

    Parameters
    ----------
    tri : (ne, 10) int
        Cubic triangles in mesh-node indices (``ShellInfo.tri``).

    Returns
    -------
    (ne·9, 3) int64
        Mesh-node indices of the 9 flat triangles of each element, element by element.
    """
    tri = np.asarray(tri, dtype=np.int64).reshape(-1, 10)
    return np.ascontiguousarray(tri[:, SUBTRIANGLES].reshape(-1, 3))          # (ne, 9, 3) → (ne·9, 3)


class ShellShapes:
    """Every shell of a compiled model, ready to draw; built once per model.

    Parameters
    ----------
    model
        A compiled :class:`~flexmb_core.model.model.Model` (``model.shells``).

    Attributes
    ----------
    names : tuple[str, ...]
        Shell names, in model order.
    triangles : tuple of (nt_k, 3) int64
        Flat triangles of shell ``k`` in its mesh-node indices (nt_k = 9 · elements).
    points : list of (N_k, 3) float64
        Node positions of shell ``k`` (m): views into :attr:`xyz`, refreshed by :meth:`read`.
    xyz : (ΣN_k, 3) float64
        Every shell's node positions, shell by shell.
    """

    def __init__(self, model):
        shells = tuple(getattr(model, "shells", ()))
        self.names = tuple(s.name for s in shells)
        self.triangles = tuple(shell_triangles(s.tri) for s in shells)
        # a TRIANGLE_LIST marker lists 3 vertices per triangle: node ids in that order, (3 nt_k,)
        self._corners = tuple(t.ravel() for t in self.triangles)
        # every shell's node positions in one gather: q[self._ids] → (ΣN_k, 3)
        self._ids = (np.ascontiguousarray(np.concatenate([s.ydofs for s in shells]), dtype=np.int64)
                     if shells else np.zeros((0, 3), dtype=np.int64))
        self.xyz = np.zeros(self._ids.shape)
        bounds = np.cumsum([0] + [s.ydofs.shape[0] for s in shells])
        self.points = [self.xyz[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
        self._vertices = [np.zeros((c.size, 3)) for c in self._corners]

    def __len__(self) -> int:
        return len(self.names)

    def read(self, q: np.ndarray) -> None:
        """Refresh :attr:`points` from the position DOFs of ``q (ndof,)`` (no allocation)."""
        if len(self.names):
            np.take(q, self._ids, out=self.xyz)

    def vertices(self, k: int) -> np.ndarray:
        """Triangle-list vertices of shell ``k``: ``(3 nt_k, 3)`` (m), three per flat triangle, from
        the last :meth:`read` (a buffer reused by the next call: copy what you keep)."""
        return np.take(self.points[k], self._corners[k], axis=0, out=self._vertices[k])
