"""The model in flat packs for the numba kernels, and the assembly every kernel shares.

A Newton step needs about 150 arrays, and every array argument of a numba call costs dispatch time
(≈ 0.1 µs), so they travel in four flat packs — read-only floats ``cf`` and ints ``ci`` (model
arrays, read-only like the model's so that the kernels called inside keep their one compiled
signature), writable floats ``wf`` and ints ``wi`` (scratch, the skyline structure) — with a
layout table ``lay``: row ``[offset, d0, d1, d2, d3, size]`` per item. Items of the whole model are
rows ``L_*``; frame group ``k`` has rows ``F0 + k·NF + F_*`` and shell group ``k`` rows
``S0 + k·NS + S_*`` (``F0, S0`` and the group counts in the step constants ``P_*``).

:func:`assemble_packed` is :func:`flexmb_core.model.assembly.assemble` over the packs (the same
kernels in the same order: bit-identical); :func:`factor_packed` and :func:`solve_packed` are the
tangent's factorization and solve both Newtons share; :class:`ModelPacks` builds the packs of a
model once. The dynamic step (:mod:`.fast`) and the static Newton (:mod:`.static_step`) run on
them.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit
from numba.extending import register_jitable

from ..jit import KERNEL
from ..kernels.constraints import director_tie_group, hinge_group, rigid_corner_group
from ..kernels.corotation import rotation_bodies
from ..kernels.frame3d import frame_group, frame_scratch
from ..kernels.guard import conservative_moment_work
from ..kernels.moments import conservative_moments, follower_moments
from ..kernels.shell import shell_group, shell_scratch
from ..kernels.truss import truss_group
from ..model.assembly import apply_drives
from ..model.model import Model, TrussGroup
from ..solvers.banded import (BACKWARD_ERROR_TOL, STATIC_PIVOT, _factor_kernel, _refine_kernel, _solve_kernel,
                              refine_scratch)
from .views import view1, view2, view3, view4

# Items of the whole model (rows of the layout table).
(L_DSCALE, L_Q0, L_GRAV, L_PAR, L_MV, L_TL0, L_TEA, L_TTAU, L_CALPHA, L_HALPHA, L_HBETA, L_TIEALPHA,
 L_FMBODY, L_CAXES, L_CMAG, L_BV,                                                             # cf
 L_FREE, L_MI, L_MJ, L_TEDOFS, L_TACT, L_TSMAP, L_CDOFS, L_CSMAP, L_HDOFS, L_HSMAP, L_TIEDOFS, L_TIESMAP,
 L_FVDOFS, L_FSMAP, L_MVDOFS, L_MSMAP, L_DRVIDX, L_BI, L_BJ, L_FPOS,                          # ci
 L_INVS, L_MASSK, L_VEVAL, L_WBUF, L_RF, L_DQ, L_KDATA, L_IVEC, L_LUWORK, L_TQE, L_TVE, L_TRE, L_TKE,
 L_SDV, L_SDFA, L_SF, L_SBMAT, L_SCB, L_SQE, L_SRE, L_SKE, L_CKE, L_HKE, L_TIEKE, L_RC, L_CP, L_MULTN,
 L_FSCALE, L_MSCALE, L_RM, L_QL, L_KDUMMY, L_DRVVAL, L_ZLAM, L_QEVAL, L_LAMN, L_RATEN,                 # wf
 L_SLOT, L_ZSLOT, L_BASE, L_LRP, L_LRL, L_LRH, L_URP, L_URL, L_URH, L_BLK, L_PERM, L_DRIVE,   # wi
 L_KPTR, L_KIDX,                                 # wi (writable like the skyline's, for one signature)
 L_KREF, L_RES, L_CORR, L_KRYLOV, L_HESS, L_ROT, L_RHS, L_AUGRHO,                               # wf
 L_AUGA, L_AUGB, L_AUGD, L_GPOS, L_GROW,                                                      # wi
 L_RNODE, L_RBODY,                                                                            # ci
 L_RMAT, L_RRHS,                                                                              # wf
 N_ITEMS) = range(105)
# Items of one frame group (rows F0 + k·NF + item).
(F_DAX, F_DSEC, F_W, F_MAT,                                                                   # cf
 F_EDOFS, F_ACT, F_SMAP, F_NSEC,                                                              # ci
 F_PHIST, F_DPHIST, F_SPT, F_HACC, F_GACC, F_TK, F_TG, F_D, F_FP, F_FD, F_EP, F_ED, F_BMAT, F_BDOT, F_GBAR,
 F_GDOT, F_QE, F_VE, F_RE, F_KE, F_KN, F_GPHI, F_GDPHI, F_GIDET, F_GILEN, F_GRAM,             # wf
 F_STRAIGHT, F_BLOCKS,                                                                        # wi
 NF) = range(37)
# Items of one shell group (rows S0 + k·NS + item).
S_PHI, S_DPHI, S_ZETA, S_A0INV, S_W, S_MAT, S_EDOFS, S_SMAP, S_CONST, NS = range(10)
# Step constants in the L_PAR block of cf.
(P_AM, P_AF, P_BETA, P_GAMMA, P_CM, P_TOL, P_MAXIT, P_MODIFIED, P_CONTRACTION, P_MAXAGE, P_SVK, P_RISE, P_BAL,
 P_CMASS, P_PIVTOL, P_MINPIV, P_ACCUM, P_DAMPED, P_NFG, P_NSG, P_F0, P_S0, P_NMULT, P_KEEP, P_MBLOCK,
 P_CH, P_COROT, N_PAR) = range(28)


# The tangent's factorization and solve, shared by the numba steps of dynamics and statics.
@register_jitable
def suspect_factors(stats, min_pivot_ratio):
    """The last factorization replaced a pivot (static pivoting) or its smallest pivot is below
    ``min_pivot_ratio`` · max |diag|: its solves are refined and checked (:func:`solve_packed`)."""
    return stats[2] > 0.0 or stats[1] < min_pivot_ratio * stats[0]


@register_jitable
def factor_packed(kdata, mass, coef, env, inv_diag, stats, nmult, wf, wi, lay, par):
    """Factor ``A = kdata + coef · mass`` with the skyline LU and static pivoting
    (:func:`~flexmb_core.solvers.banded._factor_kernel`) into ``env, inv_diag, stats``. False when
    it cannot (a non-finite pivot, a zero matrix).

    With multipliers, factors that had to replace pivots are made again of the augmented system
    ``[K + ρ GᵀG, Gᵀ; G, 0]`` (:func:`augment`): its zero pivots were those of the members'
    vectors that only the constraints tie, which ``ρ GᵀG`` stiffens; the augmented system has the
    same solution (:func:`solve_packed` adds ``ρ Gᵀ c`` to the right-hand side). Suspect and
    augmented factors keep a copy of the matrix they factored (``L_KREF``) to refine their solves
    against."""
    aug = view1(wf, lay[L_AUGRHO])
    aug[0] = 0.0
    if not _factor(kdata, mass, coef, env, inv_diag, stats, nmult, wi, lay, par):
        return False
    if nmult > 0 and stats[2] > 0.0:
        aug[0] = augment(kdata, stats[0], wi, lay)
        if not _factor(kdata, mass, coef, env, inv_diag, stats, nmult, wi, lay, par):
            return False
    if aug[0] != 0.0 or suspect_factors(stats, par[P_MINPIV]):
        kref = view1(wf, lay[L_KREF])
        for p in range(kref.size):
            kref[p] = kdata[p] + coef * mass[p]
    return True


@register_jitable
def _factor(kdata, mass, coef, env, inv_diag, stats, nmult, wi, lay, par):
    step = _factor_kernel(kdata, mass, coef, view1(wi, lay[L_SLOT]), par[P_ACCUM] != 0.0, view1(wi, lay[L_ZSLOT]),
                          view1(wi, lay[L_BASE]), view1(wi, lay[L_LRP]), view1(wi, lay[L_LRL]), view1(wi, lay[L_LRH]),
                          view1(wi, lay[L_URP]), view1(wi, lay[L_URL]), view1(wi, lay[L_URH]), view1(wi, lay[L_BLK]),
                          env, inv_diag, par[P_PIVTOL], STATIC_PIVOT, stats, nmult)
    return step < 0 and stats[0] > 0.0


@register_jitable
def augment(kdata, dmax, wi, lay):
    """``K += ρ GᵀG`` in place on the tangent ``kdata``, with ``ρ = dmax / max G_ij²`` (``dmax``:
    the largest |diagonal| of the system, so that ``ρ GᵀG`` is of the stiffness's size; the
    constraint rows ``G`` are the multiplier rows of ``kdata``; every pair of DOFs of one
    constraint is in the pattern already, :func:`augmentation_maps`). Returns ``ρ`` (0 when ``G``
    is zero: nothing added)."""
    src_a, src_b, dst = view1(wi, lay[L_AUGA]), view1(wi, lay[L_AUGB]), view1(wi, lay[L_AUGD])
    gg = 0.0
    for t in range(dst.size):
        if src_a[t] == src_b[t]:
            gg = max(gg, kdata[src_a[t]] * kdata[src_a[t]])
    if not gg > 0.0:
        return 0.0
    rho = dmax / gg
    for t in range(dst.size):
        kdata[dst[t]] += rho * (kdata[src_a[t]] * kdata[src_b[t]])
    return rho


@register_jitable
def solve_packed(rf, dq, env, inv_diag, stats, wf, wi, lay, par):
    """``dq = A⁻¹ rf`` with the factors of :func:`factor_packed` (of the augmented system: with
    ``ρ Gᵀ c`` added to a copy of ``rf``); with suspect factors, refined against the matrix
    factored (:func:`~flexmb_core.solvers.banded._refine_kernel`), as every solve of an augmented
    system is. Returns the normwise backward error of ``dq`` (0 when not measured), to compare with
    :data:`~flexmb_core.solvers.banded.BACKWARD_ERROR_TOL`."""
    perm, base = view1(wi, lay[L_PERM]), view1(wi, lay[L_BASE])
    lrp, lrl, lrh = view1(wi, lay[L_LRP]), view1(wi, lay[L_LRL]), view1(wi, lay[L_LRH])
    urp, url, urh = view1(wi, lay[L_URP]), view1(wi, lay[L_URL]), view1(wi, lay[L_URH])
    work = view1(wf, lay[L_LUWORK])
    rho = view1(wf, lay[L_AUGRHO])[0]
    b = rf
    if rho != 0.0:
        b = view1(wf, lay[L_RHS])
        for i in range(rf.size):
            b[i] = rf[i]
        g_pos, g_row = view1(wi, lay[L_GPOS]), view1(wi, lay[L_GROW])
        kref = view1(wf, lay[L_KREF])
        kidx = view1(wi, lay[L_KIDX])
        for t in range(g_pos.size):     # ρ Gᵀ c, G from the factored copy (its rows are K's)
            p = g_pos[t]
            b[kidx[p]] += rho * kref[p] * rf[g_row[t]]
    _solve_kernel(b, perm, base, lrp, lrl, lrh, urp, url, urh, env, inv_diag, work, dq)
    if not suspect_factors(stats, par[P_MINPIV]) and rho == 0.0:
        return 0.0
    kref = view1(wf, lay[L_KREF])
    return _refine_kernel(kref, kref, 0.0, view1(wi, lay[L_KPTR]), view1(wi, lay[L_KIDX]), b, dq, perm, base, lrp,
                          lrl, lrh, urp, url, urh, env, inv_diag, work, view1(wf, lay[L_RES]), view1(wf, lay[L_CORR]),
                          view2(wf, lay[L_KRYLOV]), view2(wf, lay[L_HESS]), view2(wf, lay[L_ROT]))


def augmentation_maps(model: Model) -> tuple[np.ndarray, ...]:
    """Where :func:`augment` and :func:`solve_packed` find ``G`` and put ``ρ GᵀG``: for every pair
    of entries ``(i, j), (i, k)`` of a multiplier row ``i`` of the system pattern whose columns are
    free DOFs, their CSR positions ``(a, b)`` and that of ``(j, k)`` (``d``); and every such entry's
    position with its system row (``pos, row``). All int64; empty without multipliers."""
    nf, ns = model.nfree, model.nsys
    indptr, indices = np.asarray(model.indptr, dtype=np.int64), np.asarray(model.indices, dtype=np.int64)
    rows = np.repeat(np.arange(ns, dtype=np.int64), np.diff(indptr))
    pos = np.nonzero((rows >= nf) & (indices < nf))[0]      # G's entries, row by row (CSR order)
    row = rows[pos]
    _, first, count = np.unique(row, return_index=True, return_counts=True)
    size = np.repeat(count, count)                           # the size of each entry's row
    a = np.repeat(pos, size)
    offset = np.arange(a.size) - np.repeat(np.cumsum(size) - size, size)
    b = pos[np.repeat(np.repeat(first, count), size) + offset]
    want = indices[a] * ns + indices[b]
    keys = rows * ns + indices                               # sorted: CSR rows, sorted columns
    d = np.searchsorted(keys, want)
    missing = (d >= keys.size) | (keys[np.minimum(d, keys.size - 1)] != want)
    if missing.any():
        k = int(np.argmax(missing))
        raise ValueError(f"augmentation_maps: ({want[k] // ns}, {want[k] % ns}) is not in the pattern")
    return tuple(np.asarray(x, dtype=np.int64) for x in (a, b, d, pos, row))


def singular_note(omega: float) -> str:
    """What a failed Newton's message adds when one of its solves kept a backward error ``omega``
    above :data:`~flexmb_core.solvers.banded.BACKWARD_ERROR_TOL` after refinement (else nothing)."""
    if not omega > BACKWARD_ERROR_TOL:
        return ""
    return (f"; the tangent was singular to working precision (a solve's backward error {omega:.1e} after "
            "refinement): a mechanism with a free motion needs a support")


@njit(nogil=True, **KERNEL)
def assemble_packed(q, v_k, lam, lam_rate, c_vk, refresh, no_dlam, mult, r, kdata, cf, ci, wf, wi, lay, par):
    """Internal forces (+ multiplier forces, − moment loads) into ``r (ndof,)`` and their tangent
    into ``kdata (nnz,)`` when ``refresh``, in :func:`flexmb_core.model.assembly.assemble`'s order
    (the sums bit-identical); the violations into the ``L_RC`` item. ``v_k (ndof,)``, ``lam_rate
    (na,)`` and ``c_vk`` are read by damped elements only. Returns (strain energy J, dissipated
    power W)."""
    for i in range(r.size):
        r[i] = 0.0
    if refresh:
        for i in range(kdata.size):
            kdata[i] = 0.0
    strain = 0.0
    diss = 0.0
    f0 = int(par[P_F0])
    for k in range(int(par[P_NFG])):
        b = f0 + k * NF
        u, dp = frame_group(q, v_k, view2(ci, lay[b + F_EDOFS]), view4(cf, lay[b + F_DAX]), view4(cf, lay[b + F_DSEC]),
                            view2(cf, lay[b + F_W]), ci[lay[b + F_NSEC, 0]], view2(cf, lay[b + F_MAT]),
                            view1(ci, lay[b + F_ACT]), lam, lam_rate, c_vk, view2(ci, lay[b + F_SMAP]), refresh, no_dlam,
                            r, kdata, view3(wf, lay[b + F_D]), view3(wf, lay[b + F_FP]), view3(wf, lay[b + F_FD]),
                            view2(wf, lay[b + F_EP]), view2(wf, lay[b + F_ED]), view2(wf, lay[b + F_BMAT]),
                            view2(wf, lay[b + F_BDOT]), view2(wf, lay[b + F_GBAR]), view2(wf, lay[b + F_GDOT]),
                            view1(wf, lay[b + F_QE]), view1(wf, lay[b + F_VE]), view1(wf, lay[b + F_RE]),
                            view2(wf, lay[b + F_KE]), view2(wf, lay[b + F_KN]), view1(wi, lay[b + F_STRAIGHT]),
                            view3(wf, lay[b + F_PHIST]), view3(wf, lay[b + F_DPHIST]), view3(wf, lay[b + F_SPT]),
                            view3(wi, lay[b + F_BLOCKS]), view3(wf, lay[b + F_HACC]), view1(wf, lay[b + F_GACC]),
                            view4(wf, lay[b + F_TK]), view2(wf, lay[b + F_TG]), view3(wf, lay[b + F_GRAM]))
        strain += u
        diss += dp
    t_edofs = view2(ci, lay[L_TEDOFS])
    if t_edofs.shape[0]:
        u, dp = truss_group(q, v_k, t_edofs, view1(cf, lay[L_TL0]), view1(cf, lay[L_TEA]), view1(cf, lay[L_TTAU]),
                            view1(ci, lay[L_TACT]), lam, lam_rate, c_vk, view2(ci, lay[L_TSMAP]), refresh, r, kdata,
                            view1(wf, lay[L_TQE]), view1(wf, lay[L_TVE]), view1(wf, lay[L_TRE]), view2(wf, lay[L_TKE]))
        strain += u
        diss += dp
    s0 = int(par[P_S0])
    for k in range(int(par[P_NSG])):
        b = s0 + k * NS
        strain += shell_group(q, view2(ci, lay[b + S_EDOFS]), view2(cf, lay[b + S_PHI]), view3(cf, lay[b + S_DPHI]),
                              view1(cf, lay[b + S_ZETA]), view4(cf, lay[b + S_A0INV]), view2(cf, lay[b + S_W]),
                              view2(cf, lay[b + S_MAT]), view3(cf, lay[b + S_CONST]), view2(ci, lay[b + S_SMAP]),
                              refresh, r, kdata,
                              view2(wf, lay[L_SDV]), view3(wf, lay[L_SDFA]), view2(wf, lay[L_SF]), view2(wf, lay[L_SBMAT]),
                              view2(wf, lay[L_SCB]), view1(wf, lay[L_SQE]), view1(wf, lay[L_SRE]), view2(wf, lay[L_SKE]))
    rc = view1(wf, lay[L_RC])
    c_dofs = view2(ci, lay[L_CDOFS])
    h_dofs = view2(ci, lay[L_HDOFS])
    tie_dofs = view2(ci, lay[L_TIEDOFS])
    nc = c_dofs.shape[0]
    if nc:
        rigid_corner_group(q, mult, c_dofs, view3(cf, lay[L_CALPHA]), view2(ci, lay[L_CSMAP]), refresh, r, rc, kdata,
                           view2(wf, lay[L_CKE]))
    if h_dofs.shape[0]:
        hinge_group(q, mult, 6 * nc, h_dofs, view2(cf, lay[L_HALPHA]), view3(cf, lay[L_HBETA]), view2(ci, lay[L_HSMAP]),
                    refresh, r, rc, kdata, view2(wf, lay[L_HKE]))
    if tie_dofs.shape[0]:
        director_tie_group(q, mult, 6 * nc + 2 * h_dofs.shape[0], tie_dofs, view2(cf, lay[L_TIEALPHA]),
                           view2(ci, lay[L_TIESMAP]), refresh, r, rc, kdata, view2(wf, lay[L_TIEKE]))
    f_vdofs = view2(ci, lay[L_FVDOFS])
    if f_vdofs.shape[0]:
        follower_moments(q, f_vdofs, view2(cf, lay[L_FMBODY]), view1(wf, lay[L_FSCALE]), view2(ci, lay[L_FSMAP]), refresh,
                         r, kdata)
    m_vdofs = view2(ci, lay[L_MVDOFS])
    if m_vdofs.shape[0]:
        conservative_moments(q, m_vdofs, view3(cf, lay[L_CAXES]), view1(cf, lay[L_CMAG]), view1(wf, lay[L_MSCALE]),
                             view2(ci, lay[L_MSMAP]), refresh, r, kdata)
    return strain, diss


@njit(nogil=True, **KERNEL)
def moment_work_packed(q, q_p, no_k, cf, ci, wf, lay):
    """Work of the moment loads from ``q_p`` to ``q`` (J), as
    :meth:`~flexmb_core.solvers.guard.StepGuard.moment_work` forms it (its follower part sums
    ``r·(q_p − q)`` in a loop where numpy's dot sums pairwise: the last bits of a guard value
    may differ, never a state)."""
    w = 0.0
    m_vdofs = view2(ci, lay[L_MVDOFS])
    if m_vdofs.shape[0]:
        w += conservative_moment_work(q, q_p, m_vdofs, view3(cf, lay[L_CAXES]), view1(cf, lay[L_CMAG]),
                                      view1(wf, lay[L_MSCALE]))
    f_vdofs = view2(ci, lay[L_FVDOFS])
    if f_vdofs.shape[0]:
        rm = view1(wf, lay[L_RM])
        for i in range(rm.size):
            rm[i] = 0.0
        for x in (q_p, q):
            follower_moments(x, f_vdofs, view2(cf, lay[L_FMBODY]), view1(wf, lay[L_FSCALE]), view2(ci, lay[L_FSMAP]),
                             no_k, rm, view1(wf, lay[L_KDUMMY]))
        s = 0.0
        for i in range(rm.size):
            s += rm[i] * (q_p[i] - q[i])
        w += 0.5 * s
    return w


class _Packer:
    """Builds one pack (a flat array) and its rows of the layout table."""

    def __init__(self, lay: np.ndarray, dtype):
        self.lay = lay
        self.dtype = dtype
        self.parts: list[np.ndarray] = []
        self.size = 0

    def add(self, item: int, arr) -> None:
        arr = np.ascontiguousarray(arr, dtype=self.dtype)
        dims = list(arr.shape) + [1] * (4 - arr.ndim)
        self.lay[item, 0] = self.size
        self.lay[item, 1:5] = dims
        self.lay[item, 5] = arr.size
        self.parts.append(arr.ravel())
        self.size += arr.size

    def build(self, writable: bool) -> np.ndarray:
        buf = np.concatenate(self.parts) if self.parts else np.zeros(0, self.dtype)
        buf = np.ascontiguousarray(buf, dtype=self.dtype)
        buf.setflags(write=writable)
        return buf


# Model fields model_step accounts for. A field added to Model later makes a model that uses it
# refused (NumbaStep.unsupported, NumbaStatic.unsupported) until it is looked at here.
_KNOWN_MODEL_FIELDS = frozenset((
    "scene", "ndof", "q0", "dof_scale", "free", "free_index", "indptr", "indices", "mass_kdata", "mass_csr",
    "frame_groups", "truss", "moments", "load_vectors", "load_signals", "gravity_vector", "gravity_signal",
    "actuators", "members", "node_names", "node_ydofs", "mass_damping", "total_mass", "drives", "program",
    "program_index", "nsys", "corner_dofs", "corner_alpha", "corner_smap", "hinge_dofs", "hinge_alpha",
    "hinge_beta", "hinge_smap", "node_lookup", "member_lookup", "shell_groups", "shells", "tie_dofs",
    "tie_alpha", "tie_smap"))


def _empty(value) -> bool:
    return value is None or (hasattr(value, "__len__") and len(value) == 0)

def unknown_fields(model: Model) -> list[str]:
    """Model fields that are not empty and that the packs do not know (a field added to Model
    later makes the model refused, with its name, until it is looked at here)."""
    return [f.name for f in dataclasses.fields(model)
            if f.name not in _KNOWN_MODEL_FIELDS and not _empty(getattr(model, f.name))]


class ModelPacks:
    """The packs and layout table of one model (see the module), allocated once.

    Parameters
    ----------
    model, ws : the compiled model and its workspace (frame structures).
    sky : the skyline LU (its symbolic structure goes into ``wi``).
    guard : the step guard (its frame stations and driven DOFs).
    inv_scale : (nfree,) 1 / DOF scale of the free DOFs.
    mass : the compact mass CSR ``(indptr, indices, data)`` (the guard reads its rows).
    blocks : the same mass in block form, :func:`~.energy.mass_blocks` ``(mb, ptr, idx, val)``
        (the step's mass products).
    par : (N_PAR,) the step constants; the group counts and offsets are set here.

    Attributes
    ----------
    lay : (rows, 6) int64; packs : (cf, ci, wf, wi).
    follower_scale, cons_scale, drive_values : writable views of their ``wf`` items, set by the
        caller before a step (moment load scales, the driven DOFs' values at the step's end).
    """

    def __init__(self, model: Model, ws, sky, guard, inv_scale: np.ndarray, mass: tuple, blocks: tuple,
                 par: np.ndarray):
        m = model
        tg = m.truss if m.truss is not None else _empty_truss_group()
        mo = m.moments
        n = m.ndof
        nfg, nsg = len(m.frame_groups), len(m.shell_groups)
        lay = np.zeros((N_ITEMS + nfg * NF + nsg * NS, 6), dtype=np.int64)
        par[P_NFG], par[P_NSG], par[P_F0], par[P_S0] = nfg, nsg, N_ITEMS, N_ITEMS + nfg * NF
        par[P_NMULT] = m.n_multipliers
        par[P_ACCUM] = sky._accumulate
        mi, mj, mv = mass
        mb, bi, bj, bv = blocks
        par[P_MBLOCK] = mb
        cf, ci = _Packer(lay, np.float64), _Packer(lay, np.int64)
        wf, wi = _Packer(lay, np.float64), _Packer(lay, np.int64)
        for item, arr in ((L_DSCALE, m.dof_scale), (L_Q0, m.q0), (L_GRAV, m.gravity_vector), (L_PAR, par),
                          (L_MV, mv), (L_TL0, tg.l0), (L_TEA, tg.ea), (L_TTAU, tg.tau), (L_CALPHA, m.corner_alpha),
                          (L_HALPHA, m.hinge_alpha), (L_HBETA, m.hinge_beta), (L_TIEALPHA, m.tie_alpha),
                          (L_FMBODY, mo.follower_mbody), (L_CAXES, mo.cons_axes), (L_CMAG, mo.cons_magnitude),
                          (L_BV, bv)):
            cf.add(item, arr)
        drive_ids = guard._drive_ids
        for item, arr in ((L_FREE, m.free), (L_MI, mi), (L_MJ, mj), (L_TEDOFS, tg.edofs), (L_TACT, tg.act),
                          (L_TSMAP, tg.smap), (L_CDOFS, m.corner_dofs), (L_CSMAP, m.corner_smap),
                          (L_HDOFS, m.hinge_dofs), (L_HSMAP, m.hinge_smap), (L_TIEDOFS, m.tie_dofs),
                          (L_TIESMAP, m.tie_smap), (L_FVDOFS, mo.follower_vdofs), (L_FSMAP, mo.follower_smap),
                          (L_MVDOFS, mo.cons_vdofs), (L_MSMAP, mo.cons_smap), (L_DRVIDX, drive_ids), (L_BI, bi),
                          (L_BJ, bj), (L_FPOS, m.free_index)):
            ci.add(item, arr)
        nm = m.n_multipliers
        for item, arr in ((L_INVS, inv_scale), (L_MASSK, m.mass_kdata), (L_VEVAL, np.zeros(n)),
                          (L_WBUF, np.zeros(n)), (L_RF, np.zeros(m.nsys)), (L_DQ, np.zeros(m.nsys)),
                          (L_KDATA, np.zeros(m.nnz)), (L_IVEC, np.zeros((7, n))), (L_LUWORK, np.zeros(sky.n)),
                          (L_TQE, np.zeros(6)), (L_TVE, np.zeros(6)), (L_TRE, np.zeros(6)), (L_TKE, np.zeros((6, 6))),
                          (L_CKE, np.zeros((18, 18))), (L_HKE, np.zeros((14, 14))), (L_TIEKE, np.zeros((12, 12))),
                          (L_RC, np.zeros(nm)), (L_CP, np.zeros(nm)), (L_MULTN, np.zeros(nm)),
                          (L_FSCALE, np.ones(mo.follower_vdofs.shape[0])), (L_MSCALE, np.ones(mo.cons_vdofs.shape[0])),
                          (L_RM, np.zeros(n)), (L_QL, np.zeros(n)), (L_KDUMMY, np.zeros(0)),
                          (L_DRVVAL, np.zeros(drive_ids.size)), (L_ZLAM, np.zeros(m.actuators.l0.size)),
                          (L_QEVAL, np.zeros(n)), (L_LAMN, np.zeros(m.actuators.l0.size)),
                          (L_RATEN, np.zeros(m.actuators.l0.size)), (L_KREF, np.zeros(m.nnz)),
                          *zip((L_RES, L_CORR, L_KRYLOV, L_HESS, L_ROT), refine_scratch(m.nsys)),
                          (L_RHS, np.zeros(m.nsys)), (L_AUGRHO, np.zeros(1))):
            wf.add(item, arr)
        rot_nodes, rot_ptr = rotation_bodies(m)
        ci.add(L_RNODE, rot_nodes)
        ci.add(L_RBODY, rot_ptr)
        wf.add(L_RMAT, np.zeros((rot_ptr.size - 1, 9)))
        wf.add(L_RRHS, np.zeros(m.nsys if rot_ptr.size > 1 else 0))
        for item, arr in zip(range(L_SDV, L_SKE + 1), shell_scratch()):
            wf.add(item, arr)
        for item, arr in ((L_SLOT, sky._slot), (L_ZSLOT, sky._zero_slots), (L_BASE, sky._base),
                          (L_LRP, sky._lrun[0]), (L_LRL, sky._lrun[1]), (L_LRH, sky._lrun[2]), (L_URP, sky._urun[0]),
                          (L_URL, sky._urun[1]), (L_URH, sky._urun[2]), (L_BLK, sky._blk_ptr), (L_PERM, sky.perm),
                          (L_DRIVE, drive_ids), (L_KPTR, m.indptr), (L_KIDX, m.indices),
                          *zip((L_AUGA, L_AUGB, L_AUGD, L_GPOS, L_GROW), augmentation_maps(m))):
            wi.add(item, arr)
        for k, (g, st, gst) in enumerate(zip(m.frame_groups, ws.frame_structure, guard._stations)):
            b = N_ITEMS + k * NF
            for item, arr in ((F_DAX, g.dax), (F_DSEC, g.dsec), (F_W, g.w), (F_MAT, g.mat)):
                cf.add(b + item, arr)
            for item, arr in ((F_EDOFS, g.edofs), (F_ACT, g.act), (F_SMAP, g.smap), (F_NSEC, [g.nsec])):
                ci.add(b + item, arr)
            for item, arr in ((F_PHIST, st[1]), (F_DPHIST, st[2]), (F_SPT, st[3]), (F_HACC, st[5]),
                              (F_GACC, st[6]), (F_TK, st[7]), (F_TG, st[8]), (F_GRAM, st[9])):
                wf.add(b + item, arr)
            for item, arr in zip(range(F_D, F_KN + 1), frame_scratch(g.w.shape[1], g.dax.shape[2])):
                wf.add(b + item, arr)
            for item, arr in zip((F_GPHI, F_GDPHI, F_GIDET, F_GILEN), gst):
                wf.add(b + item, arr)
            wi.add(b + F_STRAIGHT, st[0])
            wi.add(b + F_BLOCKS, st[4])
        for k, g in enumerate(m.shell_groups):
            b = N_ITEMS + nfg * NF + k * NS
            for item, arr in ((S_PHI, g.phi), (S_DPHI, g.dphi), (S_ZETA, g.zeta), (S_A0INV, g.a0inv), (S_W, g.w),
                              (S_MAT, g.mat), (S_CONST, g.const)):
                cf.add(b + item, arr)
            ci.add(b + S_EDOFS, g.edofs)
            ci.add(b + S_SMAP, g.smap)
        self.model = m
        self.lay = lay
        self.packs = (cf.build(False), ci.build(False), wf.build(True), wi.build(True))
        self.follower_scale, self.cons_scale = self.view(L_FSCALE), self.view(L_MSCALE)
        self.drive_values, self._drive_ids = self.view(L_DRVVAL), drive_ids
        self._q_drive = np.zeros(n) if m.drives is not None else None

    def view(self, item: int, pack: int = 2) -> np.ndarray:
        """The flat view of an item of ``packs[pack]`` (0 ``cf``, 1 ``ci``, 2 ``wf``, 3 ``wi``; the
        work packs' views are writable): what ``view1`` gives numba code, for Python."""
        o, size = self.lay[item, 0], self.lay[item, 5]
        return self.packs[pack][o:o + size]

    def drives(self, q: np.ndarray, t: float) -> None:
        """The driven supports' DOFs at ``t`` into their ``wf`` item (by :func:`apply_drives`
        itself on a copy of ``q``: the same operations as a Python caller's)."""
        if self._q_drive is None:
            return
        self._q_drive[:] = q
        apply_drives(self.model, self._q_drive, t)
        np.take(self._q_drive, self._drive_ids, out=self.drive_values)


def _empty_truss_group() -> TrussGroup:
    i0 = np.zeros(0, dtype=np.int64)
    return TrussGroup(edofs=np.zeros((0, 6), dtype=np.int64), l0=np.zeros(0), ea=np.zeros(0), act=i0,
                      smap=np.zeros((0, 36), dtype=np.int64), member=i0, tau=np.zeros(0))
