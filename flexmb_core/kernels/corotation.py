"""A held tangent that follows the rigid rotation of each shell (modified Newton, dynamics).

Why: the internal forces are objective, so a rigid rotation R of a body maps its tangent to
R K Rᵀ (and leaves its mass term, M_s ⊗ I₃ over the position and director triplets, as it is).
A tangent held since some earlier state is therefore wrong by the body's rotation since then,
and for a shell that error is not small: its director is far stiffer along the thickness than
the plate is in bending, so a rotation of a few milliradians mixes the one into the other. On the
Stewart twin with a shell platform (``scenes/stewart_platform_shell.yaml``) the held tangent's
iteration matrix I − A₀⁻¹A reached a spectral radius of 0.18 after 20 steps (9.4 mrad of platform
rotation) and 0.012 once A₀ was rotated by the platform's rotation: the held tangent spent two
Newton iterations a step, three or four every 20 steps with a refresh, and its accepted states
were 1e-6 from the root (the increment test passed on a far from normal iteration matrix) —
rotated, one iteration a step, 1e-9 from it (``docs/benchmarks/numba_step.md``).

So the step solves with ``R A₀ Rᵀ`` instead of ``A₀``: ``Δq = R A₀⁻¹ Rᵀ r``, with R block
diagonal — each shell's rotation on every position and director triplet of its nodes, the
identity elsewhere (bars, frames, the thickness strain rate, multipliers). Each shell's R is the
rotation that best maps its nodes from the state the tangent was formed at to the current one
(:func:`body_rotations`): the orthogonal polar factor of their cross-covariance, directors
included so that a flat shell's is regular (:func:`polar_rotation`). The factors are not
touched; two 3 × 3 products per node and solve, and one polar decomposition per shell and step.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..jit import KERNEL

# Columns of a rotation node row: the global ids of its position (0–2) and director (3–5) and
# their positions among the free DOFs (6–8, 9–11; −1 where prescribed).
RN_Y, RN_G, RN_FY, RN_FG, RN_COLS = 0, 3, 6, 9, 12
_POLAR_ITERATIONS = 30


@njit(**KERNEL)
def polar_rotation(x):
    """The orthogonal polar factor of the 3 × 3 matrix ``x (9,)`` (row-major), in place, by the
    scaled Newton iteration X ← (γX + (γX)⁻ᵀ)/2, γ = |det X|^(−1/3) (Higham 1986). Returns False
    — and leaves the identity — when ``x`` is singular, not finite, or not a rotation's
    (det ≤ 0: a reflection is no rigid motion)."""
    ok = False
    for _ in range(_POLAR_ITERATIONS):
        c00 = x[4] * x[8] - x[5] * x[7]
        c01 = x[5] * x[6] - x[3] * x[8]
        c02 = x[3] * x[7] - x[4] * x[6]
        c10 = x[2] * x[7] - x[1] * x[8]
        c11 = x[0] * x[8] - x[2] * x[6]
        c12 = x[1] * x[6] - x[0] * x[7]
        c20 = x[1] * x[5] - x[2] * x[4]
        c21 = x[2] * x[3] - x[0] * x[5]
        c22 = x[0] * x[4] - x[1] * x[3]
        det = x[0] * c00 + x[1] * c01 + x[2] * c02
        if not (det > 0.0 and math.isfinite(det)):
            break
        g = det ** (-1.0 / 3.0)
        h = 1.0 / (g * det)         # (γX)⁻ᵀ = cof(X) / (γ det X)
        change = 0.0
        for i, c in enumerate((c00, c01, c02, c10, c11, c12, c20, c21, c22)):
            y = 0.5 * (g * x[i] + h * c)
            change = max(change, abs(y - x[i]))
            x[i] = y
        if change <= 1e-12:     # quadratic: the next iterate would move by round-off
            ok = True
            break
    if not ok:
        for i in range(9):
            x[i] = 1.0 if i % 4 == 0 else 0.0
    return ok


@njit(**KERNEL)
def body_rotations(q, q_ref, nodes, body_ptr, rot):
    """Each body's rotation from ``q_ref`` to ``q`` into ``rot (nb, 9)`` (row-major R).

    Body ``b`` is the node rows ``nodes[body_ptr[b]:body_ptr[b + 1]]`` (columns ``RN_*``). R is the
    polar factor of H = Σ (y − ȳ)(y₀ − ȳ₀)ᵀ + ℓ² Σ g g₀ᵀ (y, g: position and director; ₀ at
    ``q_ref``; ℓ² the mean squared distance of the reference nodes from their centroid, so that the
    directors weigh like positions and a flat body's H is regular): the rotation that best maps
    the body's reference nodes and directors onto the current ones. A body whose H has no rotation
    (degenerate, non-finite) keeps the identity."""
    for b in range(body_ptr.size - 1):
        n0, n1 = body_ptr[b], body_ptr[b + 1]
        cx = cy = cz = rx = ry = rz = 0.0
        for k in range(n0, n1):
            cx += q[nodes[k, RN_Y]]
            cy += q[nodes[k, RN_Y + 1]]
            cz += q[nodes[k, RN_Y + 2]]
            rx += q_ref[nodes[k, RN_Y]]
            ry += q_ref[nodes[k, RN_Y + 1]]
            rz += q_ref[nodes[k, RN_Y + 2]]
        count = n1 - n0
        cx /= count
        cy /= count
        cz /= count
        rx /= count
        ry /= count
        rz /= count
        ell2 = 0.0
        for k in range(n0, n1):
            ell2 += ((q_ref[nodes[k, RN_Y]] - rx) ** 2 + (q_ref[nodes[k, RN_Y + 1]] - ry) ** 2
                     + (q_ref[nodes[k, RN_Y + 2]] - rz) ** 2)
        ell2 /= count
        h = rot[b]
        h[:] = 0.0
        for k in range(n0, n1):
            d = (q[nodes[k, RN_Y]] - cx, q[nodes[k, RN_Y + 1]] - cy, q[nodes[k, RN_Y + 2]] - cz)
            e = (q_ref[nodes[k, RN_Y]] - rx, q_ref[nodes[k, RN_Y + 1]] - ry, q_ref[nodes[k, RN_Y + 2]] - rz)
            for i in range(3):
                gi = ell2 * q[nodes[k, RN_G + i]]
                for j in range(3):
                    h[3 * i + j] += d[i] * e[j] + gi * q_ref[nodes[k, RN_G + j]]
        polar_rotation(h)


@njit(**KERNEL)
def rotate_triplets(x, nodes, body_ptr, rot, transpose):
    """``x ← Rᵀ x`` (``transpose``) or ``x ← R x`` in place on the free triplets of every body's
    nodes (``x`` over the free DOFs and multipliers; a triplet with a prescribed DOF is left: the
    tangent has no rows there to rotate)."""
    for b in range(body_ptr.size - 1):
        r = rot[b]
        for k in range(body_ptr[b], body_ptr[b + 1]):
            for c0 in (RN_FY, RN_FG):
                i0, i1, i2 = nodes[k, c0], nodes[k, c0 + 1], nodes[k, c0 + 2]
                if i0 < 0 or i1 < 0 or i2 < 0:
                    continue
                a0, a1, a2 = x[i0], x[i1], x[i2]
                if transpose:
                    x[i0] = r[0] * a0 + r[3] * a1 + r[6] * a2
                    x[i1] = r[1] * a0 + r[4] * a1 + r[7] * a2
                    x[i2] = r[2] * a0 + r[5] * a1 + r[8] * a2
                else:
                    x[i0] = r[0] * a0 + r[1] * a1 + r[2] * a2
                    x[i1] = r[3] * a0 + r[4] * a1 + r[5] * a2
                    x[i2] = r[6] * a0 + r[7] * a1 + r[8] * a2


def rotation_bodies(model) -> tuple[np.ndarray, np.ndarray]:
    """The node rows ``(N, RN_COLS)`` int64 of every shell of ``model`` (its mesh nodes) and the
    bodies' row pointer ``(nb + 1,)``: each scene shell is one body."""
    rows, ptr = [], [0]
    fi = model.free_index
    for info in model.shells:
        for y, g in zip(info.ydofs, info.gdofs):
            rows.append([*y, *g, *fi[y], *fi[g]])
        ptr.append(len(rows))
    return np.asarray(rows, dtype=np.int64).reshape(-1, RN_COLS), np.asarray(ptr, dtype=np.int64)
