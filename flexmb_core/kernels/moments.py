"""Nodal moments applied through the section vectors (SPEC §1.6).

* follower: body-fixed components (m_t, m_1, m_2) in the section frame (t, v1, v2) become forces
  f1 = (m_t/2) V2 − m2 (V1×V2), f2 = −(m_t/2) V1 + m1 (V1×V2) on the two vectors (their moment
  V1×f1 + V2×f2 equals m_t t + m1 v1 + m2 v2 for an orthonormal section); non-symmetric tangent.
* conservative: about a fixed spatial axis n, the work M·θ_n(V) with θ_n the angle of the
  projection of one section vector V in the plane ⊥ n (exact planar end moment, used by the
  roll-up benchmark); symmetric tangent.

Both kernels *subtract* the load from the residual and its derivative from the tangent.
"""

from __future__ import annotations

from numba import njit

from ..jit import KERNEL


@njit(**KERNEL)
def follower_moments(q, vdofs, mbody, scale, smap, want_k, r, kdata):
    """Follower moments. ``vdofs (nm, 6)`` = [V1, V2] global ids, ``mbody (nm, 3)`` (N·m)."""
    for m in range(vdofs.shape[0]):
        s = scale[m]
        mt = mbody[m, 0] * s
        m1 = mbody[m, 1] * s
        m2 = mbody[m, 2] * s
        v1x = q[vdofs[m, 0]]; v1y = q[vdofs[m, 1]]; v1z = q[vdofs[m, 2]]
        v2x = q[vdofs[m, 3]]; v2y = q[vdofs[m, 4]]; v2z = q[vdofs[m, 5]]
        cx = v1y * v2z - v1z * v2y
        cy = v1z * v2x - v1x * v2z
        cz = v1x * v2y - v1y * v2x
        f = (0.5 * mt * v2x - m2 * cx, 0.5 * mt * v2y - m2 * cy, 0.5 * mt * v2z - m2 * cz,
             -0.5 * mt * v1x + m1 * cx, -0.5 * mt * v1y + m1 * cy, -0.5 * mt * v1z + m1 * cz)
        for i in range(6):
            r[vdofs[m, i]] -= f[i]
        if want_k:
            # ∂f/∂[V1,V2]: blocks built from skew matrices [a]× (so [a]× b = a × b).
            w1 = (v1x, v1y, v1z)
            w2 = (v2x, v2y, v2z)
            k = 0
            for i in range(6):
                for j in range(6):
                    bi = i // 3
                    bj = j // 3
                    ii = i % 3
                    jj = j % 3
                    if bj == 0:
                        a = w2
                    else:
                        a = w1
                    # skew(a)[ii, jj]
                    if ii == jj:
                        sk = 0.0
                    elif ii == 0 and jj == 1:
                        sk = -a[2]
                    elif ii == 0 and jj == 2:
                        sk = a[1]
                    elif ii == 1 and jj == 0:
                        sk = a[2]
                    elif ii == 1 and jj == 2:
                        sk = -a[0]
                    elif ii == 2 and jj == 0:
                        sk = -a[1]
                    else:
                        sk = a[0]
                    eye = 1.0 if ii == jj else 0.0
                    if bi == 0 and bj == 0:
                        val = m2 * sk
                    elif bi == 0 and bj == 1:
                        val = 0.5 * mt * eye - m2 * sk
                    elif bi == 1 and bj == 0:
                        val = -0.5 * mt * eye - m1 * sk
                    else:
                        val = m1 * sk
                    sm = smap[m, k]
                    if sm >= 0:
                        kdata[sm] -= val
                    k += 1


@njit(**KERNEL)
def conservative_moments(q, vdofs, axes, magnitude, scale, smap, want_k, r, kdata):
    """Fixed-axis conservative moments ``M θ_n(V)``.

    ``vdofs (nm, 3)`` ids of the section vector used; ``axes (nm, 3, 3)`` rows (a, b, n): an
    orthonormal basis with n the moment axis; ``magnitude (nm,)`` (N·m); ``scale (nm,)``.
    Returns the work-conjugate angle sum is not needed: only force and tangent are assembled.
    """
    for m in range(vdofs.shape[0]):
        mm = magnitude[m] * scale[m]
        vx = q[vdofs[m, 0]]
        vy = q[vdofs[m, 1]]
        vz = q[vdofs[m, 2]]
        ax = axes[m, 0]
        bx = axes[m, 1]
        x = vx * ax[0] + vy * ax[1] + vz * ax[2]
        y = vx * bx[0] + vy * bx[1] + vz * bx[2]
        r2 = x * x + y * y
        for i in range(3):
            r[vdofs[m, i]] -= mm * (x * bx[i] - y * ax[i]) / r2
        if want_k:
            r4 = r2 * r2
            c1 = mm * 2.0 * x * y / r4
            c2 = mm * (y * y - x * x) / r4
            k = 0
            for i in range(3):
                for j in range(3):
                    val = c1 * (ax[i] * ax[j] - bx[i] * bx[j]) + c2 * (ax[i] * bx[j] + bx[i] * ax[j])
                    sm = smap[m, k]
                    if sm >= 0:
                        kdata[sm] -= val
                    k += 1
