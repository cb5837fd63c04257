"""Global assembly: one njit group loop per element group, loads, and the external force vector."""

from __future__ import annotations

import numpy as np

from ..kernels.constraints import director_tie_group, hinge_group, rigid_corner_group
from ..kernels.frame3d import frame_group, frame_group_actuator_dudlam
from ..kernels.moments import conservative_moments, follower_moments
from ..kernels.shell import shell_group
from ..kernels.truss import truss_group, truss_group_actuator_dudlam
from ..signals import evaluate
from .model import Model
from .workspace import Workspace


def update_load_scales(model: Model, ws: Workspace, t: float) -> None:
    """Evaluate every load signal at ``t`` and form ``ws.f_ext`` (nodal forces + gravity)."""
    for i, s in enumerate(model.load_signals):
        ws.load_scale[i] = evaluate(s, t)
    for i, s in enumerate(model.moments.follower_signals):
        ws.follower_scale[i] = evaluate(s, t)
    for i, s in enumerate(model.moments.cons_signals):
        ws.cons_scale[i] = evaluate(s, t)
    if model.load_vectors.shape[0]:
        np.dot(ws.load_scale, model.load_vectors, out=ws.f_ext)
    else:
        ws.f_ext[:] = 0.0
    g = evaluate(model.gravity_signal, t)
    if g != 0.0:
        ws.f_ext += g * model.gravity_vector


def apply_drives(model: Model, q: np.ndarray, t: float) -> None:
    """Set the prescribed positions and section vectors of driven supports at time ``t``."""
    d = model.drives
    if d is None:
        return
    for k in range(d.y_ids.shape[0]):
        s = 0.0 if d.distance[k] is None else evaluate(d.distance[k], t)
        q[d.y_ids[k]] = d.y0[k] + s * d.direction[k]
    for j in range(d.v_ids.shape[0]):
        k = d.v_drive[j]
        if d.angle[k] is None:
            continue
        th = evaluate(d.angle[k], t)
        a = d.axis[k]
        v0 = d.v0[j]
        c, sn = np.cos(th), np.sin(th)
        q[d.v_ids[j]] = v0 * c + np.cross(a, v0) * sn + a * (a @ v0) * (1.0 - c)


def assemble_constraints(model: Model, ws: Workspace, q: np.ndarray, mult: np.ndarray, want_k: bool) -> None:
    """Multiplier constraints (rigid corners, off-plane hinges): Gᵀλ into ``ws.r``, violations into
    ``ws.rc``, and their tangent blocks into ``ws.kdata`` when ``want_k``."""
    if model.corner_dofs.shape[0]:
        rigid_corner_group(q, mult, model.corner_dofs, model.corner_alpha, model.corner_smap, want_k,
                           ws.r, ws.rc, ws.kdata, ws.corner_ke)
    if model.hinge_dofs.shape[0]:
        hinge_group(q, mult, 6 * model.corner_dofs.shape[0], model.hinge_dofs, model.hinge_alpha,
                    model.hinge_beta, model.hinge_smap, want_k, ws.r, ws.rc, ws.kdata, ws.hinge_ke)
    if model.tie_dofs.shape[0]:
        director_tie_group(q, mult, 6 * model.corner_dofs.shape[0] + 2 * model.hinge_dofs.shape[0], model.tie_dofs,
                           model.tie_alpha, model.tie_smap, want_k, ws.r, ws.rc, ws.kdata, ws.tie_ke)


def assemble(model: Model, ws: Workspace, q: np.ndarray, lam: np.ndarray, want_k: bool,
             mult: np.ndarray | None = None, *, v: np.ndarray | None = None,
             lam_rate: np.ndarray | None = None, c_v: float = 0.0) -> float:
    """Internal forces minus configuration-dependent loads into ``ws.r`` (full), and the tangent
    of that into ``ws.kdata`` (system CSR: free DOFs, then multipliers) when ``want_k``. With rigid
    corners, ``mult`` adds the constraint forces Gᵀλ to ``ws.r`` and the violations go to ``ws.rc``.
    Returns the strain energy (J).

    Material (Kelvin–Voigt) damping reads the rates ``v (ndof,)`` and the actuator stretch rates
    ``lam_rate (na,)`` (zero when not given: statics, modes); its viscous forces join ``ws.r`` and
    ``∂r/∂q + c_v ∂r/∂v`` joins the tangent (``c_v = ∂v/∂q`` of the integrator, γ/(βΔt)). The
    dissipated power goes to ``ws.dissipation``. Moment loads use the scales last set by
    :func:`update_load_scales`.
    """
    ws.r[:] = 0.0
    if want_k:
        ws.kdata[:] = 0.0
    v = ws.zero_v if v is None else v
    lam_rate = ws.zero_lam_rate if lam_rate is None else lam_rate
    c_v = float(c_v)
    energy = 0.0
    diss = 0.0
    for g, sc, st in zip(model.frame_groups, ws.frame_scratch, ws.frame_structure):
        u, dp = frame_group(q, v, g.edofs, g.dax, g.dsec, g.w, g.nsec, g.mat, g.act, lam, lam_rate, c_v, g.smap,
                            want_k, False, ws.r, ws.kdata, *sc, *st)
        energy += u
        diss += dp
    if model.truss is not None:
        t = model.truss
        u, dp = truss_group(q, v, t.edofs, t.l0, t.ea, t.tau, t.act, lam, lam_rate, c_v, t.smap, want_k, ws.r,
                            ws.kdata, *ws.truss_scratch)
        energy += u
        diss += dp
    for g in model.shell_groups:
        energy += shell_group(q, g.edofs, g.phi, g.dphi, g.zeta, g.a0inv, g.w, g.mat, g.const, g.smap, want_k, ws.r,
                              ws.kdata, *ws.shell_scratch)
    ws.dissipation = diss
    assemble_constraints(model, ws, q, ws.no_mult if mult is None else mult, want_k)
    m = model.moments
    if m.follower_vdofs.shape[0]:
        follower_moments(q, m.follower_vdofs, m.follower_mbody, ws.follower_scale, m.follower_smap,
                         want_k, ws.r, ws.kdata)
    if m.cons_vdofs.shape[0]:
        conservative_moments(q, m.cons_vdofs, m.cons_axes, m.cons_magnitude, ws.cons_scale, m.cons_smap,
                             want_k, ws.r, ws.kdata)
    return energy


def actuator_dudlam(model: Model, ws: Workspace, q: np.ndarray, lam: np.ndarray, *,
                    v: np.ndarray | None = None, lam_rate: np.ndarray | None = None) -> np.ndarray:
    """Generalized force conjugate to λ per actuator (J) into ``ws.dudlam``: ``∂U/∂λ``, plus the
    viscous ``∂D/∂λ̇`` of damped actuators when the rates ``v`` and ``lam_rate`` are given. The
    axial force is ``−dudlam / L0``."""
    ws.dudlam[:] = 0.0
    v = ws.zero_v if v is None else v
    lam_rate = ws.zero_lam_rate if lam_rate is None else lam_rate
    for g, sc, st in zip(model.frame_groups, ws.frame_scratch, ws.frame_structure):
        if np.any(g.act >= 0):
            frame_group_actuator_dudlam(q, v, g.edofs, g.dax, g.dsec, g.w, g.nsec, g.mat, g.act, lam, lam_rate, 0.0,
                                        False, True, ws.dudlam, *sc, *st)
    if model.truss is not None and np.any(model.truss.act >= 0):
        t = model.truss
        truss_group_actuator_dudlam(q, v, t.edofs, t.l0, t.ea, t.tau, t.act, lam, lam_rate, 0.0, False, ws.dudlam,
                                    *ws.truss_scratch)
    return ws.dudlam
