"""Solid-like positional shell element (SPEC §2): curved cubic triangle, 10 nodes, 7 unknowns per node.

Nodal unknowns ``[Y (3), G (3), a (1)]``: mid-surface position, one unconstrained generalized
vector (director and thickness stretch in one) and the thickness strain rate, ordered node by
node (``q_e`` has 70 values). With ``h = h0/2`` and ζ ∈ [−1, 1] through the thickness,

    x(ξ1, ξ2, ζ) = Σ φℓ Xℓ + h ζ Σ φℓ V⁰ℓ                   (reference; V⁰ the unit nodal normals)
    y(ξ1, ξ2, ζ) = Σ φℓ Yℓ + h (ζ + a ζ²) Σ φℓ Gℓ,  a = Σ φℓ aℓ

so the thickness stretch |G|(1 + 2aζ) varies linearly through the thickness: the section can
contract the way bending with ν ≠ 0 requires, and the full 3D Saint-Venant–Kirchhoff law
``S = λ tr(E) I + 2μ E`` is used as it is (no plane-stress condensation, no Poisson locking).
``F = A¹ (A⁰)⁻¹`` with ``A = [∂/∂ξ1, ∂/∂ξ2, ∂/∂ζ]`` is linear in Y and G for fixed a and bilinear
in (a, G): the only second derivatives of F are the (a, G) cross terms, which enter the geometric
part of the tangent. The strain energy ``∫ ½ S : E* dV₀`` is integrated by a triangle rule times
Gauss points through the thickness; the tangent is exact (``tests/unit/test_shell_kernel.py``).

Assumed strains (membrane and transverse-shear locking, issue 16)
-----------------------------------------------------------------
The strain the law sees is ``E* = E + (A⁰)⁻ᵀ ΔÊ (A⁰)⁻¹``: at every point the covariant components
Ê = A⁰ᵀ E A⁰ (convected ξ1, ξ2, ζ) of the membrane (Ê11, Ê22, Ê12) and transverse-shear (Ê13, Ê23)
strain have their *thickness mean* m (weights w/Ω, Ω = Σ_ζ w the point's area weight) replaced:

    membrane:  m* = Π₁ m + s (m − Π₁ m)        shear:  m* = Π₂ m

where Πₖ is the element's L2 projection (weights Ω) onto polynomials of degree k in (ξ1, ξ2);
the parts that vary through the thickness (bending) and Ê33 are kept. E* is a linear map of the
point strains with constant per-element coefficients, so the energy is a pure energy of q_e:
the residual is ∂U*/∂q_e and the tangent its exact, symmetric derivative; rigid motions leave E
and so E* at zero. Constant strains are in every Πₖ (patch tests pass), and a flat element has
s = 1 (its membrane strains are kept as they are).

Why this choice (measured on the linearized element, then on the kernel; ``docs/benchmarks/
shell_locking.md``): the pinched hemisphere (doubly curved, R/t = 250) is −46 %, −10 %, −3 % off at
4×4, 6×6, 8×8 cells per quarter. Projecting the membrane strain onto P₂ — the MITC6-like choice, the
highest degree that leaves a flat element without spurious modes — only reaches −30 %, −6 %,
−1.7 %; P₁ reaches −0.5 %, +0.4 %, +0.3 %, but a single flat element then has 8 zero-energy modes
(in-plane: 17 compatible quadratic strain modes against 9 projected ones) and a cylindrical one 3.
So the membrane part beyond P₁ is kept with the weight s = 1/√(1 + (α h_e² κ_e / t)²), α = 1/4 (h_e
the longest edge, κ_e the largest principal curvature of the reference element, t the thickness;
:func:`flexmb_core.model.shell_geometry.membrane_weight`): h²κ/t is the ratio that sets membrane
locking of a curved element, so s → 1 on flat elements and under refinement (the element converges
to the unprojected one) and is small only where the element would lock; every element keeps exactly
the 6 rigid zero-energy modes. α = 1 relieved more but let a 2 × 2 octant of the pinched cylinder
(45° per element) come out 47 % too soft with one diagonal pattern; with α = 1/4 no pattern
overshoots. Transverse shear matters on the pinched cylinder (8×8: −8.4 % unprojected, −2.4 % with
the membrane remedy and P₂ shear; −3.7 % with P₂ shear alone) and on thin plates; P₂ — one degree
below the cubic interpolation — adds no zero-energy mode (P₁ would add 4).

Kernel structure. The kernel sums the points through the thickness in 21 node-independent
"virtual" unknowns and spreads them over the 70 once per in-plane point (:func:`shell_element`,
Notes). The projection couples the in-plane points, so the element takes three passes: strains
(:func:`_strains`, then :func:`_l2`), stresses of E* (:func:`_stresses`, then :func:`_l2`'s adjoint:
the effective stress S + ΔS whose work on δE equals the work of S* on δE*),
and the residual/tangent pass of the raw kernel with the effective stress, plus the tangent's
projected parts: per in-plane point within its 21 virtual unknowns, and a rank-21 update over the
projected modes (:func:`_coupled_update`). ``mat`` carries the correction weights (γ_m = 1 − s for
the membrane, γ_s = 1 for the shear): with both 0 the kernel is the unprojected element. What does
not depend on the state — the in-plane bases and weights, A⁰ at every point, the Gram inverses of
the projections — is computed once per model (:func:`shell_constants`, by the same functions the
kernel once called at every evaluation: the same numbers) and read by every evaluation.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..jit import KERNEL
from .scatter import scatter_matrix

NODES = 10          # cubic triangle
NDOF_NODE = 7       # Y, G, a
NLOC = NODES * NDOF_NODE

# Columns of the per-element material table ``mat[e]``: Lamé λ, μ (Pa), half thickness (m), and the
# weights of the assumed-strain corrections of the membrane (1 − s) and transverse-shear strains.
SMAT_LAMBDA, SMAT_MU, SMAT_H, SMAT_GM, SMAT_GS = 0, 1, 2, 3, 4
N_SMAT = 5


# Virtual unknowns v = 7b + ν (b: φ, φ,1, φ,2; ν: Y0 Y1 Y2 G0 G1 G2 a) and the scratch rows.
NV = 3 * NDOF_NODE
D_SD, D_G, D_N = 6, 12, 15          # dv rows: d_k (0–5), w S d_k (6–11), g g,1 g,2 (12–14), N (15–17)
F_NY, F_NZ, F_NZ2, F_RV = 3, 6, 9, 12   # f rows: F (0–2), Σ N, Σ ζN, Σ ζ²N (3 each), r_v (12–14, by b)
N_F = F_RV + 3
B_H = 6             # bmat rows: Voigt B (0–5), H (6–26)
NB = 4              # in-plane points whose Sᵀ T is added to K_e in one pass
C_T = 6             # cb rows: w C B (0–5), T = H S of the NB batch slots (21 rows each), their s_ℓ (3 rows each)
C_S = C_T + NB * NV

# Assumed strains. Projected covariant components c = (a, b): 11, 22, 12 (membrane), 13, 23 (shear).
NC = 5
COMP_A = (0, 1, 0, 0, 1)
COMP_B = (0, 1, 1, 2, 2)
NM_M, NM_S = 3, 6                   # modes: P1 (1, x, y) for the membrane, P2 (…, x², xy, y²) for the shear
NMODE = 3 * NM_M + 2 * NM_S         # 21 projected coefficients; row r = 3c + k (c < 3), 9 + 6(c − 3) + k
IN_PLANE_MAX = 64                   # 8 × 8 in-plane rule (the schema's largest)
NPT_MAX = IN_PLANE_MAX * 6          # × 6 points through the thickness
# (ξ1, ξ2) of the nodes (LOCAL_NODES_3L / 3): the cubic reproduces them, so Σ φ ξℓ is a point's (ξ1, ξ2).
NODE_XI1 = np.array([0.0, 1.0, 0.0, 1 / 3, 2 / 3, 2 / 3, 1 / 3, 0.0, 0.0, 1 / 3])
NODE_XI2 = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 1 / 3, 2 / 3, 2 / 3, 1 / 3, 1 / 3])
# f: rows F_PT + p per point (F 3×3, E, A⁰ 3×3, S* of E*), rows F_IP + i per in-plane point.
F_PT = N_F
F_IP = F_PT + NPT_MAX
N_FROW = F_IP + IN_PLANE_MAX
PT_F, PT_E, PT_A, PT_S = 0, 9, 15, 24
IP_PSI, IP_OM, IP_M, IP_D, IP_T, IP_U, IP_P0, IP_P1 = 0, 6, 7, 12, 17, 22, 27, 28
IP_FL = 30          # the in-plane point's fields (y,1 y,2 g g,1 g,2 a a,1 a,2: 18), kept by pass 1
N_FCOL = IP_FL + 18
# bmat (21 columns): the point's ∂m/∂v (Mv), Lᵀ w C B (Z), Z − Q γ Mv (Y), the modes' G, the Gram
# inverses, Q = Σ w Lᵀ C L, and the point's L (E from ΔÊ) and R (Ê from E) in Voigt form.
B_MV, B_Z, B_Y, B_G = 27, 32, 37, 42
B_MI1, B_MI2 = 63, 66
B_Q, B_LV, B_RV = 72, 77, 83
N_BROW = 88
# cb (70 columns): the projected coefficients' ∂c (Cm), their coupling W, and per in-plane point Mv S, Y S.
C_CM = C_S + 3 * NB
C_W = C_CM + NMODE
C_MS = C_W + NMODE
C_YS = C_MS + NC
N_CBROW = C_YS + NC
# Rows of an element's constants table (shell_constants, 9 columns): the in-plane point count, the
# P1 Gram inverse (3 × 3), the P2 one (6 × 6 over 4 rows), then one row per in-plane point (ψ, Ω,
# its run p0, p1) and one per point (A⁰, row-major).
C_NIP, C_GRAM1, C_GRAM2, C_IPC = 0, 1, 2, 6
IP_CONST = (IP_PSI, IP_PSI + 1, IP_PSI + 2, IP_PSI + 3, IP_PSI + 4, IP_PSI + 5, IP_OM, IP_P0, IP_P1)


@njit(**KERNEL)
def _fields(qe, phi, dphi, p):
    """y,1 y,2; g g,1 g,2; a a,1 a,2 at point ``p`` (an 18-tuple). Plain IEEE rounding here, in
    :func:`_deformation` and :func:`_stresses` (fastmath would fuse their products): E of a small
    strain is a small difference of F's products, and this keeps F, E and S rounded as the
    per-node form of the kernel rounded them (a contracted F moved r_e of a nearly unstrained panel
    by 1e-7 of its size)."""
    y1x = 0.0; y1y = 0.0; y1z = 0.0
    y2x = 0.0; y2y = 0.0; y2z = 0.0
    gx = 0.0; gy = 0.0; gz = 0.0
    g1x = 0.0; g1y = 0.0; g1z = 0.0
    g2x = 0.0; g2y = 0.0; g2z = 0.0
    aa = 0.0; a1 = 0.0; a2 = 0.0
    for n in range(NODES):
        b = NDOF_NODE * n
        ph = phi[p, n]
        s1 = dphi[p, n, 0]
        s2 = dphi[p, n, 1]
        y1x += s1 * qe[b]; y1y += s1 * qe[b + 1]; y1z += s1 * qe[b + 2]
        y2x += s2 * qe[b]; y2y += s2 * qe[b + 1]; y2z += s2 * qe[b + 2]
        gx += ph * qe[b + 3]; gy += ph * qe[b + 4]; gz += ph * qe[b + 5]
        g1x += s1 * qe[b + 3]; g1y += s1 * qe[b + 4]; g1z += s1 * qe[b + 5]
        g2x += s2 * qe[b + 3]; g2y += s2 * qe[b + 4]; g2z += s2 * qe[b + 5]
        aa += ph * qe[b + 6]
        a1 += s1 * qe[b + 6]
        a2 += s2 * qe[b + 6]
    return (y1x, y1y, y1z, y2x, y2y, y2z, gx, gy, gz, g1x, g1y, g1z, g2x, g2y, g2z, aa, a1, a2)


@njit(**KERNEL)
def _deformation(fl, z, hh, a0inv, p, f):
    """F = A¹ (A⁰)⁻¹ into ``f[0:3, 0:3]`` at thickness coordinate ``z`` of point ``p`` from the
    fields ``fl`` of :func:`_fields`."""
    y1x, y1y, y1z, y2x, y2y, y2z, gx, gy, gz, g1x, g1y, g1z, g2x, g2y, g2z, aa, a1, a2 = fl
    q1x = a1 * gx + aa * g1x; q1y = a1 * gy + aa * g1y; q1z = a1 * gz + aa * g1z
    q2x = a2 * gx + aa * g2x; q2y = a2 * gy + aa * g2y; q2z = a2 * gz + aa * g2z
    z2 = z * z
    # Columns of A¹ = [∂y/∂ξ1, ∂y/∂ξ2, ∂y/∂ζ].
    c0x = y1x + hh * (z * g1x + z2 * q1x)
    c0y = y1y + hh * (z * g1y + z2 * q1y)
    c0z = y1z + hh * (z * g1z + z2 * q1z)
    c1x = y2x + hh * (z * g2x + z2 * q2x)
    c1y = y2y + hh * (z * g2y + z2 * q2y)
    c1z = y2z + hh * (z * g2z + z2 * q2z)
    s3 = hh * (1.0 + 2.0 * aa * z)
    c2x = s3 * gx
    c2y = s3 * gy
    c2z = s3 * gz
    for j in range(3):
        i0 = a0inv[p, 0, j]
        i1 = a0inv[p, 1, j]
        i2 = a0inv[p, 2, j]
        f[0, j] = c0x * i0 + c1x * i1 + c2x * i2
        f[1, j] = c0y * i0 + c1y * i1 + c2y * i2
        f[2, j] = c0z * i0 + c1z * i1 + c2z * i2


@njit(**KERNEL)
def _run_end(phi, dphi, p0):
    """End (exclusive) of the run of points through the thickness that share point ``p0``'s
    in-plane position (consecutive rows of ``phi``/``dphi`` equal)."""
    npt = phi.shape[0]
    p1 = p0 + 1
    while p1 < npt:
        for n in range(NODES):
            if (phi[p1, n] != phi[p0, n] or dphi[p1, n, 0] != dphi[p0, n, 0]
                    or dphi[p1, n, 1] != dphi[p0, n, 1]):
                return p1
        p1 += 1
    return p1


@njit(**KERNEL)
def _constants(phi, dphi, w, a0inv, f):
    """The state-independent part of pass 1, into ``f``: per in-plane point i the basis ψ = (1, x, y,
    x², xy, y²) (x = ξ1 − ⅓, y = ξ2 − ⅓), Ω = Σ w and its run of points through the thickness; per
    point A⁰ = ((A⁰)⁻¹)⁻¹ (cofactors: Ê = A⁰ᵀ E A⁰ needs it). Returns the number of in-plane points."""
    npt = w.shape[0]
    nip = npt * 0
    p0 = npt * 0
    while p0 < npt:
        p1 = _run_end(phi, dphi, p0)
        r = F_IP + nip
        x = -1.0 / 3.0
        y = -1.0 / 3.0
        for n in range(NODES):
            x += phi[p0, n] * NODE_XI1[n]
            y += phi[p0, n] * NODE_XI2[n]
        f[r, IP_PSI] = 1.0
        f[r, IP_PSI + 1] = x
        f[r, IP_PSI + 2] = y
        f[r, IP_PSI + 3] = x * x
        f[r, IP_PSI + 4] = x * y
        f[r, IP_PSI + 5] = y * y
        om = 0.0
        for p in range(p0, p1):
            om += w[p]
        f[r, IP_OM] = om
        f[r, IP_P0] = p0
        f[r, IP_P1] = p1
        for p in range(p0, p1):
            row = F_PT + p
            m00 = a0inv[p, 0, 0]; m01 = a0inv[p, 0, 1]; m02 = a0inv[p, 0, 2]
            m10 = a0inv[p, 1, 0]; m11 = a0inv[p, 1, 1]; m12 = a0inv[p, 1, 2]
            m20 = a0inv[p, 2, 0]; m21 = a0inv[p, 2, 1]; m22 = a0inv[p, 2, 2]
            k00 = m11 * m22 - m12 * m21
            k01 = m02 * m21 - m01 * m22
            k02 = m01 * m12 - m02 * m11
            det = m00 * k00 + m10 * k01 + m20 * k02
            inv = 1.0 / det
            a = PT_A
            f[row, a] = k00 * inv
            f[row, a + 1] = k01 * inv
            f[row, a + 2] = k02 * inv
            f[row, a + 3] = (m12 * m20 - m10 * m22) * inv
            f[row, a + 4] = (m00 * m22 - m02 * m20) * inv
            f[row, a + 5] = (m02 * m10 - m00 * m12) * inv
            f[row, a + 6] = (m10 * m21 - m11 * m20) * inv
            f[row, a + 7] = (m01 * m20 - m00 * m21) * inv
            f[row, a + 8] = (m00 * m11 - m01 * m10) * inv
        nip += 1
        p0 = p1
    return nip


@njit(cache=True)
def shell_constants(phi, dphi, zeta, a0inv, w, const):
    """The state-independent numbers of one element's passes, once per model (:func:`shell_element`
    reads them instead of computing them at every call): ``const (6 + nip + npt, 9)`` (its rows: see
    :func:`const_rows`) gets the in-plane point count, the inverted Gram matrices of P1 and P2, per
    in-plane point ψ, Ω and its run of points, per point A⁰ — computed by the very functions the
    kernel used to call at every evaluation, so the kernel's arithmetic is unchanged. Returns nip,
    or −1 (nothing written) when ``const`` has too few rows for it."""
    f = np.zeros((N_FROW, N_FCOL))
    bmat = np.zeros((N_BROW, NV))
    nip = _constants(phi, dphi, w, a0inv, f)
    if const.shape[0] < C_IPC + nip + w.shape[0]:
        return -1
    _invert_grams(f, bmat, nip)
    const[:, :] = 0.0
    const[C_NIP, 0] = nip
    for k in range(NM_M):
        for l in range(NM_M):
            const[C_GRAM1, NM_M * k + l] = bmat[B_MI1 + k, l]
    for k in range(NM_S):
        for l in range(NM_S):
            i = NM_S * k + l
            const[C_GRAM2 + i // 9, i % 9] = bmat[B_MI2 + k, l]
    for i in range(nip):
        for c in range(9):
            const[C_IPC + i, c] = f[F_IP + i, IP_CONST[c]]      # ψ (6), Ω, p0, p1
    for p in range(w.shape[0]):
        for c in range(9):
            const[C_IPC + nip + p, c] = f[F_PT + p, PT_A + c]
    return nip


@njit(**KERNEL)
def _load_constants(const, npt, f, bmat):
    """:func:`shell_constants`' numbers back into the scratch rows the passes read; returns nip."""
    nip = int(const[C_NIP, 0])
    for k in range(NM_M):
        for l in range(NM_M):
            bmat[B_MI1 + k, l] = const[C_GRAM1, NM_M * k + l]
    for k in range(NM_S):
        for l in range(NM_S):
            i = NM_S * k + l
            bmat[B_MI2 + k, l] = const[C_GRAM2 + i // 9, i % 9]
    for i in range(nip):
        for c in range(9):
            f[F_IP + i, IP_CONST[c]] = const[C_IPC + i, c]
    for p in range(npt):
        for c in range(9):
            f[F_PT + p, PT_A + c] = const[C_IPC + nip + p, c]
    return nip


def const_rows(nip: int, npt: int) -> int:
    """Rows of an element's :func:`shell_constants` table: the count, the P1 Gram inverse (9), the P2
    one (36, 4 rows), one per in-plane point, one per point."""
    return C_IPC + nip + npt


@njit(**KERNEL)
def _strains(qe, phi, dphi, zeta, a0inv, w, hh, f, nip):
    """Pass 1: F and E = ½(FᵀF − I) of every point into its ``f`` row and per in-plane point the
    thickness mean m of Ê11, Ê22, Ê12, Ê13, Ê23 (weights w/Ω), from the constants
    :func:`_load_constants` put in ``f`` (ψ, Ω, the runs, A⁰)."""
    for i in range(nip):
        r = F_IP + i
        p0 = int(f[r, IP_P0])
        p1 = int(f[r, IP_P1])
        om = f[r, IP_OM]
        fl = _fields(qe, phi, dphi, p0)
        for k in range(18):
            f[r, IP_FL + k] = fl[k]
        for c in range(NC):
            f[r, IP_M + c] = 0.0
        for p in range(p0, p1):
            _deformation(fl, zeta[p], hh, a0inv, p, f)
            row = F_PT + p
            for i3 in range(3):
                for j in range(3):
                    f[row, PT_F + 3 * i3 + j] = f[i3, j]
            e00 = 0.5 * (f[0, 0] * f[0, 0] + f[1, 0] * f[1, 0] + f[2, 0] * f[2, 0] - 1.0)
            e11 = 0.5 * (f[0, 1] * f[0, 1] + f[1, 1] * f[1, 1] + f[2, 1] * f[2, 1] - 1.0)
            e22 = 0.5 * (f[0, 2] * f[0, 2] + f[1, 2] * f[1, 2] + f[2, 2] * f[2, 2] - 1.0)
            e01 = 0.5 * (f[0, 0] * f[0, 1] + f[1, 0] * f[1, 1] + f[2, 0] * f[2, 1])
            e02 = 0.5 * (f[0, 0] * f[0, 2] + f[1, 0] * f[1, 2] + f[2, 0] * f[2, 2])
            e12 = 0.5 * (f[0, 1] * f[0, 2] + f[1, 1] * f[1, 2] + f[2, 1] * f[2, 2])
            f[row, PT_E] = e00
            f[row, PT_E + 1] = e11
            f[row, PT_E + 2] = e22
            f[row, PT_E + 3] = e01
            f[row, PT_E + 4] = e02
            f[row, PT_E + 5] = e12
            a = PT_A
            wm = w[p] / om
            for c in range(NC):
                ca = COMP_A[c]
                cb_ = COMP_B[c]
                # Ê_ab = A⁰_{ia} E_ij A⁰_{jb}
                b0 = f[row, a + cb_]
                b1 = f[row, a + 3 + cb_]
                b2 = f[row, a + 6 + cb_]
                eb0 = e00 * b0 + e01 * b1 + e02 * b2
                eb1 = e01 * b0 + e11 * b1 + e12 * b2
                eb2 = e02 * b0 + e12 * b1 + e22 * b2
                f[r, IP_M + c] += wm * (f[row, a + ca] * eb0 + f[row, a + 3 + ca] * eb1 + f[row, a + 6 + ca] * eb2)


@njit(**KERNEL)
def _invert_grams(f, bmat, nip):
    """Gram matrices Σ Ω ψ_k ψ_l of P1 (3 × 3) and P2 (6 × 6) over the in-plane points, inverted in
    place (Gauss–Jordan without pivoting: symmetric positive definite) into rows B_MI1, B_MI2."""
    for k in range(NM_S):
        for l in range(NM_S):
            g = 0.0
            for i in range(nip):
                r = F_IP + i
                g += f[r, IP_OM] * f[r, IP_PSI + k] * f[r, IP_PSI + l]
            bmat[B_MI2 + k, l] = g
            if k < NM_M and l < NM_M:
                bmat[B_MI1 + k, l] = g
    for r0, n in ((B_MI1, NM_M), (B_MI2, NM_S)):
        for k in range(n):
            piv = 1.0 / bmat[r0 + k, k]
            bmat[r0 + k, k] = 1.0
            for l in range(n):
                bmat[r0 + k, l] *= piv
            for i in range(n):
                if i == k:
                    continue
                fac = bmat[r0 + i, k]
                bmat[r0 + i, k] = 0.0
                for l in range(n):
                    bmat[r0 + i, l] -= fac * bmat[r0 + k, l]


@njit(**KERNEL)
def _l2(f, bmat, nip, gm, gs, adjoint):
    """The corrections of the projection over the in-plane points, component by component: D =
    γ (Πm − m) from the means m (``adjoint`` False), or its adjoint U = γ (Πᵀ T − T) from the thickness
    sums T of the conjugate stresses (``adjoint`` True). Π = Ψ M⁻¹ Ψᵀ Ω (P1 for the membrane, P2 for
    the shear components); γ = ``gm``, ``gs``."""
    src = IP_T if adjoint else IP_M
    dst = IP_U if adjoint else IP_D
    for c in range(NC):
        nm = NM_M if c < 3 else NM_S
        r0 = B_MI1 if c < 3 else B_MI2
        g = gm if c < 3 else gs
        # rhs_k = Σ ψ_k x (× Ω unless adjoint) into f[3], β = M⁻¹ rhs into f[4].
        for k in range(nm):
            t = 0.0
            for i in range(nip):
                r = F_IP + i
                wt = 1.0 if adjoint else f[r, IP_OM]
                t += wt * f[r, IP_PSI + k] * f[r, src + c]
            f[3, k] = t
        for k in range(nm):
            t = 0.0
            for l in range(nm):
                t += bmat[r0 + k, l] * f[3, l]
            f[4, k] = t
        for i in range(nip):
            r = F_IP + i
            t = 0.0
            for k in range(nm):
                t += f[r, IP_PSI + k] * f[4, k]
            if adjoint:
                t *= f[r, IP_OM]
            f[r, dst + c] = g * (t - f[r, src + c])


@njit(inline="always", **KERNEL)
def _congruence(x00, x01, x02, x10, x11, x12, x20, x21, x22, d0, d1, d2, d3, d4):
    """Mᵀ D M of the 3 × 3 M = [x_ab] and the symmetric D = [[d0, d2, d3], [d2, d1, d4], [d3, d4, 0]]
    (the shell's assumed-strain corrections have no thickness-normal component): its components
    (00, 11, 22, 01, 02, 12). With u, v, z the rows of D M, (Mᵀ D M)_ij = x_0i u_j + x_1i v_j + x_2i z_j."""
    u0 = d0 * x00 + d2 * x10 + d3 * x20; u1 = d0 * x01 + d2 * x11 + d3 * x21; u2 = d0 * x02 + d2 * x12 + d3 * x22
    v0 = d2 * x00 + d1 * x10 + d4 * x20; v1 = d2 * x01 + d1 * x11 + d4 * x21; v2 = d2 * x02 + d1 * x12 + d4 * x22
    z0 = d3 * x00 + d4 * x10; z1 = d3 * x01 + d4 * x11; z2 = d3 * x02 + d4 * x12
    return (x00 * u0 + x10 * v0 + x20 * z0, x01 * u1 + x11 * v1 + x21 * z1, x02 * u2 + x12 * v2 + x22 * z2,
            x00 * u1 + x10 * v1 + x20 * z1, x00 * u2 + x10 * v2 + x20 * z2, x01 * u2 + x11 * v2 + x21 * z2)


@njit(**KERNEL)
def _stresses(a0inv, w, lam_l, mu, f, nip):
    """Pass 2: E* = E + (A⁰)⁻ᵀ ΔÊ(D) (A⁰)⁻¹ at every point, its SVK stress S* (into the point's row)
    and, per in-plane point, T = Σ w Ŝ* of the conjugate covariant stresses (Ŝ = (A⁰)⁻¹ S (A⁰)⁻ᵀ,
    off-diagonal components twice). Returns the strain energy Σ ½ w S* : E* (J)."""
    energy = 0.0
    for i in range(nip):
        r = F_IP + i
        d0 = f[r, IP_D]; d1 = f[r, IP_D + 1]; d2 = f[r, IP_D + 2]; d3 = f[r, IP_D + 3]; d4 = f[r, IP_D + 4]
        t0 = 0.0; t1 = 0.0; t2 = 0.0; t3 = 0.0; t4 = 0.0
        for p in range(int(f[r, IP_P0]), int(f[r, IP_P1])):
            row = F_PT + p
            # ΔE_ij = Σ_ab a_ai ΔÊ_ab a_bj with a = (A⁰)⁻¹ (rows a_0, a_1, a_2), ΔÊ from d (symmetric).
            x00 = a0inv[p, 0, 0]; x01 = a0inv[p, 0, 1]; x02 = a0inv[p, 0, 2]
            x10 = a0inv[p, 1, 0]; x11 = a0inv[p, 1, 1]; x12 = a0inv[p, 1, 2]
            x20 = a0inv[p, 2, 0]; x21 = a0inv[p, 2, 1]; x22 = a0inv[p, 2, 2]
            c00, c11, c22, c01, c02, c12 = _congruence(x00, x01, x02, x10, x11, x12, x20, x21, x22,
                                                       d0, d1, d2, d3, d4)
            e00 = f[row, PT_E] + c00
            e11 = f[row, PT_E + 1] + c11
            e22 = f[row, PT_E + 2] + c22
            e01 = f[row, PT_E + 3] + c01
            e02 = f[row, PT_E + 4] + c02
            e12 = f[row, PT_E + 5] + c12
            tr = e00 + e11 + e22
            s00 = lam_l * tr + 2.0 * mu * e00
            s11 = lam_l * tr + 2.0 * mu * e11
            s22 = lam_l * tr + 2.0 * mu * e22
            s01 = 2.0 * mu * e01
            s02 = 2.0 * mu * e02
            s12 = 2.0 * mu * e12
            wp = w[p]
            energy += 0.5 * wp * (s00 * e00 + s11 * e11 + s22 * e22 + 2.0 * (s01 * e01 + s02 * e02 + s12 * e12))
            f[row, PT_S] = s00
            f[row, PT_S + 1] = s11
            f[row, PT_S + 2] = s22
            f[row, PT_S + 3] = s01
            f[row, PT_S + 4] = s02
            f[row, PT_S + 5] = s12
            # S a_k for k = 0, 1, 2, then Ŝ_ab = a_a · S a_b.
            p00 = s00 * x00 + s01 * x01 + s02 * x02; p01 = s01 * x00 + s11 * x01 + s12 * x02
            p02 = s02 * x00 + s12 * x01 + s22 * x02
            p10 = s00 * x10 + s01 * x11 + s02 * x12; p11 = s01 * x10 + s11 * x11 + s12 * x12
            p12 = s02 * x10 + s12 * x11 + s22 * x12
            t0 += wp * (x00 * p00 + x01 * p01 + x02 * p02)
            t1 += wp * (x10 * p10 + x11 * p11 + x12 * p12)
            t2 += 2.0 * wp * (x00 * p10 + x01 * p11 + x02 * p12)
            t3 += 2.0 * wp * (x20 * p00 + x21 * p01 + x22 * p02)
            t4 += 2.0 * wp * (x20 * p10 + x21 * p11 + x22 * p12)
        f[r, IP_T] = t0
        f[r, IP_T + 1] = t1
        f[r, IP_T + 2] = t2
        f[r, IP_T + 3] = t3
        f[r, IP_T + 4] = t4
    return energy


@njit(**KERNEL)
def _projection_rows(a0inv, p, f, row, bmat, cb, wp, om, lam_l, mu, gm):
    """At one point: L (Voigt ΔE of each ΔÊ component) and R (the Ê components of a Voigt E), then
    Mv += (w/Ω) R B, Z += Lᵀ (w C B) and Q += w Lᵀ C L (the B and w C B rows of the point already
    in ``bmat`` and ``cb``). The membrane components only when γ_m ≠ 0 (a flat element has γ_m = 0:
    they would be multiplied by 0)."""
    c0 = 0 if gm != 0.0 else 3
    vi = (0, 1, 2, 0, 0, 1)
    vj = (0, 1, 2, 1, 2, 2)
    for c in range(c0, NC):
        ca = COMP_A[c]
        cb_ = COMP_B[c]
        for vo in range(6):
            i = vi[vo]
            j = vj[vo]
            x = a0inv[p, ca, i] * a0inv[p, cb_, j]
            if ca != cb_:
                x += a0inv[p, cb_, i] * a0inv[p, ca, j]
            if vo >= 3:
                x *= 2.0
            bmat[B_LV + vo, c] = x
            aia = f[row, PT_A + 3 * i + ca]
            ajb = f[row, PT_A + 3 * j + cb_]
            if vo < 3:
                bmat[B_RV + c, vo] = aia * ajb
            else:
                bmat[B_RV + c, vo] = 0.5 * (aia * ajb + f[row, PT_A + 3 * j + ca] * f[row, PT_A + 3 * i + cb_])
    wm = wp / om
    for c in range(c0, NC):
        for v in range(3, NV):
            m = 0.0
            z = 0.0
            for vo in range(6):
                m += bmat[B_RV + c, vo] * bmat[vo, v]
                z += bmat[B_LV + vo, c] * cb[vo, v]
            bmat[B_MV + c, v] += wm * m
            bmat[B_Z + c, v] += z
    for c in range(c0, NC):
        l0 = bmat[B_LV, c]
        l1 = bmat[B_LV + 1, c]
        l2 = bmat[B_LV + 2, c]
        tr = lam_l * (l0 + l1 + l2)
        cl0 = tr + 2.0 * mu * l0
        cl1 = tr + 2.0 * mu * l1
        cl2 = tr + 2.0 * mu * l2
        cl3 = mu * bmat[B_LV + 3, c]
        cl4 = mu * bmat[B_LV + 4, c]
        cl5 = mu * bmat[B_LV + 5, c]
        for c2 in range(c0, NC):
            bmat[B_Q + c, c2] += wp * (cl0 * bmat[B_LV, c2] + cl1 * bmat[B_LV + 1, c2] + cl2 * bmat[B_LV + 2, c2]
                                       + cl3 * bmat[B_LV + 3, c2] + cl4 * bmat[B_LV + 4, c2]
                                       + cl5 * bmat[B_LV + 5, c2])


@njit(**KERNEL)
def _assumed_in_plane(f, r_ip, phi, dphi, p0, bmat, cb, gm, gs):
    """The projection's tangent parts of one in-plane point (its Mv, Z, Q summed over the thickness):
    H += −Zᵀ γMv − (γMv)ᵀ Y (upper triangle; Y = Z − Q γ Mv), and for the rank-21 update the rows
    ∂c += γ Ω (M⁻¹ψ)_k Mv S, W += ψ_k Y S and G += ψ_k ψ_k' Q of the active classes (γ ≠ 0; the
    membrane components are skipped when γ_m = 0)."""
    c0 = 0 if gm != 0.0 else 3
    for c in range(c0, NC):
        g = gm if c < 3 else gs
        for v in range(3, NV):
            t = bmat[B_Z + c, v]
            for c2 in range(c0, NC):
                g2 = gm if c2 < 3 else gs
                t -= bmat[B_Q + c, c2] * g2 * bmat[B_MV + c2, v]
            bmat[B_Y + c, v] = t
    for v in range(3, NV):
        for v2 in range(v, NV):
            t = 0.0
            for c in range(c0, NC):
                g = gm if c < 3 else gs
                t += g * (bmat[B_Z + c, v] * bmat[B_MV + c, v2] + bmat[B_MV + c, v] * bmat[B_Y + c, v2])
            bmat[B_H + v, v2] -= t
    # Mv S and Y S (5 × 70): (X S)_c[7n + ν] = Σ_b X[c, 7b + ν] s_n[b].
    for n in range(NODES):
        ph = phi[p0, n]
        s1 = dphi[p0, n, 0]
        s2 = dphi[p0, n, 1]
        for nu in range(NDOF_NODE):
            col = NDOF_NODE * n + nu
            for c in range(c0, NC):
                cb[C_MS + c, col] = (ph * bmat[B_MV + c, nu] + s1 * bmat[B_MV + c, NDOF_NODE + nu]
                                     + s2 * bmat[B_MV + c, 2 * NDOF_NODE + nu])
                cb[C_YS + c, col] = (ph * bmat[B_Y + c, nu] + s1 * bmat[B_Y + c, NDOF_NODE + nu]
                                     + s2 * bmat[B_Y + c, 2 * NDOF_NODE + nu])
    om = f[r_ip, IP_OM]
    for c in range(c0, NC):
        g = gm if c < 3 else gs
        if g == 0.0:
            continue
        nm = NM_M if c < 3 else NM_S
        r0 = 3 * c if c < 3 else 9 + NM_S * (c - 3)
        mi = B_MI1 if c < 3 else B_MI2
        for k in range(nm):
            alpha = 0.0
            for l in range(nm):
                alpha += bmat[mi + k, l] * f[r_ip, IP_PSI + l]
            alpha *= g * om
            psi = f[r_ip, IP_PSI + k]
            r = r0 + k
            for col in range(NLOC):
                cb[C_CM + r, col] += alpha * cb[C_MS + c, col]
                cb[C_W + r, col] += psi * cb[C_YS + c, col]
            for c2 in range(c0, NC):
                g2 = gm if c2 < 3 else gs
                if g2 == 0.0:
                    continue
                nm2 = NM_M if c2 < 3 else NM_S
                r02 = 3 * c2 if c2 < 3 else 9 + NM_S * (c2 - 3)
                q = psi * bmat[B_Q + c, c2]
                for k2 in range(nm2):
                    bmat[B_G + r, r02 + k2] += q * f[r_ip, IP_PSI + k2]


@njit(fastmath={"reassoc", "contract"}, **KERNEL)
def _coupled_update(cb, bmat, ke, gm, gs):
    """Upper triangle of K_e += ∂cᵀ V + Vᵀ ∂c with V = W + ½ G ∂c over the active projected
    coefficients (membrane rows 0–8 when γ_m ≠ 0, shear rows 9–20 when γ_s ≠ 0): the material
    stiffness that couples the in-plane points through the projection."""
    lo = 0 if gm != 0.0 else 3 * NM_M
    hi = NMODE if gs != 0.0 else 3 * NM_M
    for r in range(lo, hi):
        for r2 in range(lo, hi):
            g = 0.5 * bmat[B_G + r, r2]
            for col in range(NLOC):
                cb[C_W + r, col] += g * cb[C_CM + r2, col]
    for r in range(lo, hi):
        for row in range(NLOC):
            a = cb[C_CM + r, row]
            b = cb[C_W + r, row]
            for col in range(row, NLOC):
                ke[row, col] += a * cb[C_W + r, col] + b * cb[C_CM + r, col]


@njit(fastmath={"reassoc", "contract"}, **KERNEL)
def _spread_slot(cb, ke, slot):
    """Upper triangle of K_e += Sᵀ T for one batch slot (T rows ``C_T + 21·slot + v``, s_ℓ rows
    ``C_S + 3·slot``); the 70-long inner loops run over contiguous columns of ``ke`` and ``cb``."""
    tb = C_T + NV * slot
    sb = C_S + 3 * slot
    for n in range(NODES):
        ph = cb[sb, n]
        s1 = cb[sb + 1, n]
        s2 = cb[sb + 2, n]
        for nu in range(3):
            row = NDOF_NODE * n + nu
            t = tb + NDOF_NODE + nu
            for c in range(row, NLOC):
                ke[row, c] += s1 * cb[t, c] + s2 * cb[t + NDOF_NODE, c]
        for nu in range(3, NDOF_NODE):
            row = NDOF_NODE * n + nu
            t = tb + nu
            for c in range(row, NLOC):
                ke[row, c] += ph * cb[t, c] + s1 * cb[t + NDOF_NODE, c] + s2 * cb[t + 2 * NDOF_NODE, c]


@njit(fastmath={"reassoc", "contract"}, **KERNEL)
def _spread_batch(cb, ke):
    """Upper triangle of K_e += Σ_slots Sᵀ T for a full batch (NB = 4 slots): one pass over K_e."""
    u = NDOF_NODE
    t1 = C_T + NV
    t2 = C_T + 2 * NV
    t3 = C_T + 3 * NV
    for n in range(NODES):
        a00 = cb[C_S, n]; a01 = cb[C_S + 1, n]; a02 = cb[C_S + 2, n]
        a10 = cb[C_S + 3, n]; a11 = cb[C_S + 4, n]; a12 = cb[C_S + 5, n]
        a20 = cb[C_S + 6, n]; a21 = cb[C_S + 7, n]; a22 = cb[C_S + 8, n]
        a30 = cb[C_S + 9, n]; a31 = cb[C_S + 10, n]; a32 = cb[C_S + 11, n]
        for nu in range(3):
            row = NDOF_NODE * n + nu
            r0 = C_T + nu
            r1 = t1 + nu
            r2 = t2 + nu
            r3 = t3 + nu
            for c in range(row, NLOC):
                ke[row, c] += (a01 * cb[r0 + u, c] + a02 * cb[r0 + 2 * u, c] + a11 * cb[r1 + u, c]
                               + a12 * cb[r1 + 2 * u, c] + a21 * cb[r2 + u, c] + a22 * cb[r2 + 2 * u, c]
                               + a31 * cb[r3 + u, c] + a32 * cb[r3 + 2 * u, c])
        for nu in range(3, NDOF_NODE):
            row = NDOF_NODE * n + nu
            r0 = C_T + nu
            r1 = t1 + nu
            r2 = t2 + nu
            r3 = t3 + nu
            for c in range(row, NLOC):
                ke[row, c] += (a00 * cb[r0, c] + a01 * cb[r0 + u, c] + a02 * cb[r0 + 2 * u, c]
                               + a10 * cb[r1, c] + a11 * cb[r1 + u, c] + a12 * cb[r1 + 2 * u, c]
                               + a20 * cb[r2, c] + a21 * cb[r2 + u, c] + a22 * cb[r2 + 2 * u, c]
                               + a30 * cb[r3, c] + a31 * cb[r3 + u, c] + a32 * cb[r3 + 2 * u, c])


@njit(**KERNEL)
def shell_element(qe, phi, dphi, zeta, a0inv, w, mat, const, want_k, dv, dfa, f, bmat, cb, re, ke):
    """Residual, tangent and strain energy of one positional shell element (assumed strains E*).

    Parameters
    ----------
    qe : (70,) float64 — element unknowns [Y (m), G (–), a (–)] per node.
    phi : (npt, 10) float64 — shape functions at the integration points.
    dphi : (npt, 10, 2) float64 — their derivatives ∂φ/∂ξ1, ∂φ/∂ξ2.
    zeta : (npt,) float64 — thickness coordinate ζ ∈ [−1, 1] of each point.
    a0inv : (npt, 3, 3) float64 — (A⁰)⁻¹ of the reference map per point (1/m, 1/m, 1/m rows).
    w : (npt,) float64 — reference volume weights W·det A⁰ (m³).
    mat : (5,) float64 — Lamé λ, μ (Pa), the half thickness h = h0/2 (m) and the correction
        weights γ_m = 1 − s (membrane) and γ_s (transverse shear) of the assumed strains (–).
    const : (6 + nip + npt, 9) float64 — the element's :func:`shell_constants`.
    want_k : bool — also compute the tangent.
    dv, dfa, f, bmat, cb : scratch of :func:`shell_scratch` (row roles: ``D_*``, ``F_*``/``PT_*``/
        ``IP_*``, ``B_*``, ``C_*``).
    re : (70,) out — internal force ∂U/∂q_e (N for Y, N·m for G and a).
    ke : (70, 70) out — tangent ∂²U/∂q_e² (symmetric; written only if ``want_k``).

    Returns
    -------
    float — strain energy U = Σ ½ w S* : E* (J).

    Notes
    -----
    Every derivative of F with respect to a nodal unknown (ℓ, ν) is Σ_b s_ℓ[b] ∂F/∂v, with
    s_ℓ = (φℓ, φℓ,1, φℓ,2) and 21 "virtual" unknowns v = 7b + ν whose ∂F depend on the point but not
    on the node (Y_i: e_i ⊗ d_k with d = a⁰₀, a⁰₁ for b = 1, 2; G_i: e_i ⊗ d_k with the G columns of
    ∂A¹; a: the g, g,1, g,2 terms; a⁰_c the rows of (A⁰)⁻¹). The points through the thickness at one
    in-plane point share s_ℓ, so their contributions are summed over the 21 virtual unknowns first
    and spread over the 70 once: r_e += Sᵀ r_v and K_e += Sᵀ H S (21 × 21 H; T = H S, then Sᵀ T for
    NB in-plane points in one pass over K_e). r_v only needs the thickness moments Σ N, Σ ζN, Σ ζ²N
    of N = w P (A⁰)⁻ᵀ, P = F S_eff.

    Assumed strains (module docstring): with E* = E + L(D), D = γ(Πm − m) of the thickness means m
    of the projected covariant components, U = Σ ½ w S* : E*. Its residual is the raw kernel's with
    the effective stress S_eff = S* + ΔS, ΔS = A⁰ Ũ A⁰ᵀ / Ω (Ũ the adjoint U = γ(ΠᵀT − T) of the
    stress sums T = Σ w Ŝ*), and so is the tangent's geometric part. Its material part is
    Σ w B*ᵀ C B* with B* = B + L ∂D, ∂D = N − γ Mv S (N = Σ_k ψ_k ∂c_k the projected part): the terms
    within one in-plane point go into H, the ones through N into a rank-21 update ∂cᵀ V + Vᵀ ∂c
    (:func:`_assumed_in_plane`, :func:`_coupled_update`).
    """
    lam_l = mat[SMAT_LAMBDA]
    mu = mat[SMAT_MU]
    hh = mat[SMAT_H]
    gm = mat[SMAT_GM]
    gs = mat[SMAT_GS]
    re[:] = 0.0
    if want_k:
        ke[:, :] = 0.0
        for r in range(C_CM, C_MS):
            for c in range(NLOC):
                cb[r, c] = 0.0
        for r in range(B_G, B_G + NMODE):
            for c in range(NV):
                bmat[r, c] = 0.0
    # Passes 1 and 2: strains, their projection, the stresses of E* and the adjoint projection.
    nip = _load_constants(const, w.shape[0], f, bmat)
    _strains(qe, phi, dphi, zeta, a0inv, w, hh, f, nip)
    _l2(f, bmat, nip, gm, gs, nip < 0)
    energy = _stresses(a0inv, w, lam_l, mu, f, nip)
    _l2(f, bmat, nip, gm, gs, nip >= 0)
    ns = 0              # filled slots of the tangent batch
    for ip in range(nip):
        r_ip = F_IP + ip
        p0 = int(f[r_ip, IP_P0])
        p1 = int(f[r_ip, IP_P1])
        om = f[r_ip, IP_OM]
        # Ũ / Ω as a symmetric 3 × 3 (ΔS = A⁰ Ũ A⁰ᵀ / Ω).
        u00 = f[r_ip, IP_U] / om
        u11 = f[r_ip, IP_U + 1] / om
        u01 = 0.5 * f[r_ip, IP_U + 2] / om
        u02 = 0.5 * f[r_ip, IP_U + 3] / om
        u12 = 0.5 * f[r_ip, IP_U + 4] / om
        # Interpolated fields (independent of ζ): y,1 y,2; g g,1 g,2; a a,1 a,2, as pass 1 kept them.
        fr = f[r_ip]
        y1x = fr[IP_FL]; y1y = fr[IP_FL + 1]; y1z = fr[IP_FL + 2]
        y2x = fr[IP_FL + 3]; y2y = fr[IP_FL + 4]; y2z = fr[IP_FL + 5]
        gx = fr[IP_FL + 6]; gy = fr[IP_FL + 7]; gz = fr[IP_FL + 8]
        g1x = fr[IP_FL + 9]; g1y = fr[IP_FL + 10]; g1z = fr[IP_FL + 11]
        g2x = fr[IP_FL + 12]; g2y = fr[IP_FL + 13]; g2z = fr[IP_FL + 14]
        aa = fr[IP_FL + 15]; a1 = fr[IP_FL + 16]; a2 = fr[IP_FL + 17]
        for i in range(F_NY, F_RV):
            f[i, 0] = 0.0
            f[i, 1] = 0.0
            f[i, 2] = 0.0
        if want_k:
            dv[D_G, 0] = gx; dv[D_G, 1] = gy; dv[D_G, 2] = gz
            dv[D_G + 1, 0] = g1x; dv[D_G + 1, 1] = g1y; dv[D_G + 1, 2] = g1z
            dv[D_G + 2, 0] = g2x; dv[D_G + 2, 1] = g2y; dv[D_G + 2, 2] = g2z
            for v in range(3, NV):
                for v2 in range(NV):
                    bmat[B_H + v, v2] = 0.0
            for r in range(B_MV, B_Y):
                for v in range(NV):
                    bmat[r, v] = 0.0
            for r in range(B_Q, B_Q + NC):
                for c in range(NC):
                    bmat[r, c] = 0.0
        for p in range(p0, p1):
            row = F_PT + p
            z = zeta[p]
            z2 = z * z
            hz = hh * z
            hz2 = hh * z2
            s3 = hh * (1.0 + 2.0 * aa * z)
            for i in range(3):
                for j in range(3):
                    f[i, j] = f[row, PT_F + 3 * i + j]
            # S_eff = S* + A⁰ Ũ A⁰ᵀ / Ω.
            al00 = f[row, PT_A]; al01 = f[row, PT_A + 1]; al02 = f[row, PT_A + 2]
            al10 = f[row, PT_A + 3]; al11 = f[row, PT_A + 4]; al12 = f[row, PT_A + 5]
            al20 = f[row, PT_A + 6]; al21 = f[row, PT_A + 7]; al22 = f[row, PT_A + 8]
            # A⁰ Ũ A⁰ᵀ = Mᵀ Ũ M with M = A⁰ᵀ
            c00, c11, c22, c01, c02, c12 = _congruence(al00, al10, al20, al01, al11, al21, al02, al12, al22,
                                                       u00, u11, u01, u02, u12)
            s00 = f[row, PT_S] + c00
            s11 = f[row, PT_S + 1] + c11
            s22 = f[row, PT_S + 2] + c22
            s01 = f[row, PT_S + 3] + c01
            s02 = f[row, PT_S + 4] + c02
            s12 = f[row, PT_S + 5] + c12
            wp = w[p]
            # w P = w F S, then N = w P (A⁰)⁻ᵀ and its thickness moments.
            for i in range(3):
                fi0 = f[i, 0]
                fi1 = f[i, 1]
                fi2 = f[i, 2]
                pi0 = wp * (fi0 * s00 + fi1 * s01 + fi2 * s02)
                pi1 = wp * (fi0 * s01 + fi1 * s11 + fi2 * s12)
                pi2 = wp * (fi0 * s02 + fi1 * s12 + fi2 * s22)
                for c in range(3):
                    nic = pi0 * a0inv[p, c, 0] + pi1 * a0inv[p, c, 1] + pi2 * a0inv[p, c, 2]
                    dv[D_N + i, c] = nic
                    f[F_NY + i, c] += nic
                    f[F_NZ + i, c] += z * nic
                    f[F_NZ2 + i, c] += z2 * nic
            if not want_k:
                continue
            # Virtual ∂F: Y, G (e_i ⊗ d_k, k = 3t + b) and a (dfa[b]).
            cg = hh * (z + z2 * aa)
            for j in range(3):
                i0 = a0inv[p, 0, j]
                i1 = a0inv[p, 1, j]
                i2 = a0inv[p, 2, j]
                dv[0, j] = 0.0
                dv[1, j] = i0
                dv[2, j] = i1
                dv[3, j] = hz2 * (a1 * i0 + a2 * i1) + s3 * i2
                dv[4, j] = cg * i0
                dv[5, j] = cg * i1
                for i in range(3):
                    dfa[0, i, j] = hz2 * (dv[D_G + 1, i] * i0 + dv[D_G + 2, i] * i1) + 2.0 * hz * dv[D_G, i] * i2
                    dfa[1, i, j] = hz2 * dv[D_G, i] * i0
                    dfa[2, i, j] = hz2 * dv[D_G, i] * i1
            # Voigt B = ∂E/∂v (engineering shears) and w C B.
            for nu in range(6):
                i = nu % 3
                fi0 = f[i, 0]
                fi1 = f[i, 1]
                fi2 = f[i, 2]
                for bb in range(3):
                    k = 3 * (nu // 3) + bb
                    d0 = dv[k, 0]
                    d1 = dv[k, 1]
                    d2 = dv[k, 2]
                    col = NDOF_NODE * bb + nu
                    bmat[0, col] = fi0 * d0
                    bmat[1, col] = fi1 * d1
                    bmat[2, col] = fi2 * d2
                    bmat[3, col] = fi0 * d1 + fi1 * d0
                    bmat[4, col] = fi0 * d2 + fi2 * d0
                    bmat[5, col] = fi1 * d2 + fi2 * d1
            for bb in range(3):
                col = NDOF_NODE * bb + 6
                m00 = 0.0; m11 = 0.0; m22 = 0.0; m01 = 0.0; m02 = 0.0; m12 = 0.0
                for i in range(3):
                    fi0 = f[i, 0]
                    fi1 = f[i, 1]
                    fi2 = f[i, 2]
                    h0 = dfa[bb, i, 0]
                    h1 = dfa[bb, i, 1]
                    h2 = dfa[bb, i, 2]
                    m00 += fi0 * h0
                    m11 += fi1 * h1
                    m22 += fi2 * h2
                    m01 += fi0 * h1 + fi1 * h0
                    m02 += fi0 * h2 + fi2 * h0
                    m12 += fi1 * h2 + fi2 * h1
                bmat[0, col] = m00
                bmat[1, col] = m11
                bmat[2, col] = m22
                bmat[3, col] = m01
                bmat[4, col] = m02
                bmat[5, col] = m12
            for c in range(3, NV):
                tr_b = bmat[0, c] + bmat[1, c] + bmat[2, c]
                cb[0, c] = wp * (lam_l * tr_b + 2.0 * mu * bmat[0, c])
                cb[1, c] = wp * (lam_l * tr_b + 2.0 * mu * bmat[1, c])
                cb[2, c] = wp * (lam_l * tr_b + 2.0 * mu * bmat[2, c])
                cb[3, c] = wp * mu * bmat[3, c]
                cb[4, c] = wp * mu * bmat[4, c]
                cb[5, c] = wp * mu * bmat[5, c]
            _projection_rows(a0inv, p, f, row, bmat, cb, wp, om, lam_l, mu, gm)
            # Material part Bᵀ C B (upper triangle).
            for v in range(3, NV):
                b0 = bmat[0, v]; b1 = bmat[1, v]; b2 = bmat[2, v]
                b3 = bmat[3, v]; b4 = bmat[4, v]; b5 = bmat[5, v]
                for v2 in range(v, NV):
                    bmat[B_H + v, v2] += (b0 * cb[0, v2] + b1 * cb[1, v2] + b2 * cb[2, v2]
                                          + b3 * cb[3, v2] + b4 * cb[4, v2] + b5 * cb[5, v2])
            # Geometric part among Y/G: δ_ij w d_k S d_k2 (k = 3t + b ↔ v = 7b + 3t + i).
            for k in range(1, 6):
                d0 = dv[k, 0]
                d1 = dv[k, 1]
                d2 = dv[k, 2]
                dv[D_SD + k, 0] = wp * (s00 * d0 + s01 * d1 + s02 * d2)
                dv[D_SD + k, 1] = wp * (s01 * d0 + s11 * d1 + s12 * d2)
                dv[D_SD + k, 2] = wp * (s02 * d0 + s12 * d1 + s22 * d2)
            for k in range(1, 6):
                vk = NDOF_NODE * (k % 3) + 3 * (k // 3)
                for k2 in range(1, 6):
                    vk2 = NDOF_NODE * (k2 % 3) + 3 * (k2 // 3)
                    if vk2 < vk:
                        continue
                    gkk = dv[k, 0] * dv[D_SD + k2, 0] + dv[k, 1] * dv[D_SD + k2, 1] + dv[k, 2] * dv[D_SD + k2, 2]
                    for i in range(3):
                        bmat[B_H + vk + i, vk2 + i] += gkk
            # (Y/G, a): (w ∂F/∂a S d_k)_i; (a, a): w ∂F/∂a S : ∂F/∂a.
            for bb in range(3):
                va = NDOF_NODE * bb + 6
                for i in range(3):
                    h0 = dfa[bb, i, 0]
                    h1 = dfa[bb, i, 1]
                    h2 = dfa[bb, i, 2]
                    dfa[3 + bb, i, 0] = wp * (h0 * s00 + h1 * s01 + h2 * s02)
                    dfa[3 + bb, i, 1] = wp * (h0 * s01 + h1 * s11 + h2 * s12)
                    dfa[3 + bb, i, 2] = wp * (h0 * s02 + h1 * s12 + h2 * s22)
                for k in range(1, 6):
                    vk = NDOF_NODE * (k % 3) + 3 * (k // 3)
                    for i in range(3):
                        x = dfa[3 + bb, i, 0] * dv[k, 0] + dfa[3 + bb, i, 1] * dv[k, 1] + dfa[3 + bb, i, 2] * dv[k, 2]
                        if vk + i < va:
                            bmat[B_H + vk + i, va] += x
                        else:
                            bmat[B_H + va, vk + i] += x
                for b2 in range(bb, 3):
                    s = 0.0
                    for i in range(3):
                        for j in range(3):
                            s += dfa[3 + bb, i, j] * dfa[b2, i, j]
                    bmat[B_H + va, NDOF_NODE * b2 + 6] += s
            # Second derivative ∂²F/∂a ∂G_i: P_i · (h [ζ² (s_a,1 s_b + s_a s_b,1), ζ² (…,2), 2ζ s_a s_b] (A⁰)⁻¹),
            # at (v_G, v_a) = (7b + 3 + i, 7b' + 6) for (b, b') = (φ, φ), (φ,1, φ), (φ, φ,1), (φ,2, φ), (φ, φ,2).
            for i in range(3):
                x0 = hz2 * dv[D_N + i, 0]
                x1 = hz2 * dv[D_N + i, 1]
                bmat[B_H + 3 + i, 6] += 2.0 * hz * dv[D_N + i, 2]
                bmat[B_H + 3 + i, NDOF_NODE + 6] += x0
                bmat[B_H + 3 + i, 2 * NDOF_NODE + 6] += x1
                bmat[B_H + 6, NDOF_NODE + 3 + i] += x0
                bmat[B_H + 6, 2 * NDOF_NODE + 3 + i] += x1

        # Virtual residual from the thickness moments, then r_e += Sᵀ r_v.
        for i in range(3):
            f[F_RV, i] = 0.0
            f[F_RV + 1, i] = f[F_NY + i, 0]
            f[F_RV + 2, i] = f[F_NY + i, 1]
            f[F_RV, 3 + i] = hh * (a1 * f[F_NZ2 + i, 0] + a2 * f[F_NZ2 + i, 1] + f[F_NY + i, 2]
                                   + 2.0 * aa * f[F_NZ + i, 2])
            f[F_RV + 1, 3 + i] = hh * (f[F_NZ + i, 0] + aa * f[F_NZ2 + i, 0])
            f[F_RV + 2, 3 + i] = hh * (f[F_NZ + i, 1] + aa * f[F_NZ2 + i, 1])
        f[F_RV, 6] = hh * (f[F_NZ2, 0] * g1x + f[F_NZ2 + 1, 0] * g1y + f[F_NZ2 + 2, 0] * g1z
                           + f[F_NZ2, 1] * g2x + f[F_NZ2 + 1, 1] * g2y + f[F_NZ2 + 2, 1] * g2z
                           + 2.0 * (f[F_NZ, 2] * gx + f[F_NZ + 1, 2] * gy + f[F_NZ + 2, 2] * gz))
        f[F_RV + 1, 6] = hh * (f[F_NZ2, 0] * gx + f[F_NZ2 + 1, 0] * gy + f[F_NZ2 + 2, 0] * gz)
        f[F_RV + 2, 6] = hh * (f[F_NZ2, 1] * gx + f[F_NZ2 + 1, 1] * gy + f[F_NZ2 + 2, 1] * gz)
        for n in range(NODES):
            ph = phi[p0, n]
            s1 = dphi[p0, n, 0]
            s2 = dphi[p0, n, 1]
            b = NDOF_NODE * n
            for nu in range(NDOF_NODE):
                re[b + nu] += ph * f[F_RV, nu] + s1 * f[F_RV + 1, nu] + s2 * f[F_RV + 2, nu]
        if want_k:
            _assumed_in_plane(f, r_ip, phi, dphi, p0, bmat, cb, gm, gs)
            # K_e += Sᵀ H S: T = H S (21 × 70) into the batch slot, then (per NB slots) the upper triangle
            # of Sᵀ T. Rows v < 3 (Y·φ) are zero.
            for v in range(3, NV):
                for v2 in range(3, v):
                    bmat[B_H + v, v2] = bmat[B_H + v2, v]
            tb = C_T + NV * ns
            for v in range(3, NV):
                for m in range(NODES):
                    ph = phi[p0, m]
                    s1 = dphi[p0, m, 0]
                    s2 = dphi[p0, m, 1]
                    c0 = NDOF_NODE * m
                    for nu in range(NDOF_NODE):
                        cb[tb + v, c0 + nu] = (ph * bmat[B_H + v, nu] + s1 * bmat[B_H + v, NDOF_NODE + nu]
                                               + s2 * bmat[B_H + v, 2 * NDOF_NODE + nu])
            for n in range(NODES):
                cb[C_S + 3 * ns, n] = phi[p0, n]
                cb[C_S + 3 * ns + 1, n] = dphi[p0, n, 0]
                cb[C_S + 3 * ns + 2, n] = dphi[p0, n, 1]
            ns += 1
            if ns == NB:
                _spread_batch(cb, ke)
                ns = 0
    if want_k:
        for slot in range(ns):
            _spread_slot(cb, ke, slot)
        _coupled_update(cb, bmat, ke, gm, gs)
    if want_k:
        for r in range(NLOC):
            for c in range(r + 1, NLOC):
                ke[c, r] = ke[r, c]
    return energy




@njit(**KERNEL)
def shell_group(q, edofs, phi, dphi, zeta, a0inv, w, mat, const, smap, want_k, r, kdata, dv, dfa, f, bmat, cb,
                qe, re, ke):
    """Loop over one shell group: gather, element kernel, scatter into ``r`` and CSR ``kdata``.

    ``edofs (ne, 70)`` global DOF ids; ``a0inv (ne, npt, 3, 3)``, ``w (ne, npt)``, ``mat (ne, 5)``;
    ``const (ne, 6 + nip + npt, 9)`` the elements' :func:`shell_constants`; ``smap (ne, 4900)`` CSR
    position of each local entry (−1: prescribed). Returns the strain energy (J).
    """
    energy = 0.0
    for e in range(edofs.shape[0]):
        for i in range(NLOC):
            qe[i] = q[edofs[e, i]]
        energy += shell_element(qe, phi, dphi, zeta, a0inv[e], w[e], mat[e], const[e], want_k, dv, dfa, f, bmat,
                                cb, re, ke)
        for i in range(NLOC):
            r[edofs[e, i]] += re[i]
        if want_k:
            scatter_matrix(smap[e], ke, kdata)
    return energy


def shell_scratch() -> tuple[np.ndarray, ...]:
    """Scratch buffers for :func:`shell_group` (allocated once per model): dv, dfa, f, bmat, cb, qe, re, ke.

    ``dv (20, 3)`` virtual d_k, w S d_k, g g,1 g,2 and N; ``dfa (10, 3, 3)`` virtual ∂F/∂a and
    w ∂F/∂a S; ``f (463, 48)`` F, the thickness moments of N and r_v, then per point F, E, A⁰, S* and
    per in-plane point ψ, Ω, m, D, T, U, its run and its fields (up to 8 × 8 × 6 points); ``bmat (88, 21)`` Voigt B, H and the
    projection's Mv, Z, Y, G, Gram inverses, Q, L, R; ``cb (154, 70)`` w C B, the batch's T and s_ℓ,
    ∂c, W, Mv S and Y S; ``qe, re (70,)``; ``ke (70, 70)``.
    """
    return (np.zeros((2 * NODES, 3)), np.zeros((NODES, 3, 3)), np.zeros((N_FROW, N_FCOL)), np.zeros((N_BROW, NV)),
            np.zeros((N_CBROW, NLOC)), np.zeros(NLOC), np.zeros(NLOC), np.zeros((NLOC, NLOC)))
