"""Scene → :class:`Model`: DOF numbering, element groups (only the kinds present), constant mass,
free–free sparse pattern and the scatter maps that let kernels add into CSR data directly."""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
import scipy.sparse as sp

from .. import sections as secmod
from ..errors import SceneError
from ..scene.limits import Limits, check_size
from ..scene.schema import Scene, Signal
from ..servo import ServoParams
from .frame_geometry import frame_member_geometry, frame_member_mass
from .model import Actuators, Drives, FrameGroup, Model, MomentLoads, TrussGroup
from .pattern import Pattern
from .constraints import build_constraints
from .dof_numbering import _axis_offset, member_geometry, number_dofs
from .shell_compile import (build_shell_groups, clamp_node_gdofs, edge_load_patterns, edge_support_dofs,
                            shell_element_pairs, shell_point_node)

__all__ = ["compile_scene", "member_geometry"]


def _freeze(*arrays: np.ndarray) -> None:
    for a in arrays:
        a.setflags(write=False)


def compile_scene(scene: Scene, limits: Limits | None = None) -> Model:
    """Build the read-only :class:`Model` of a validated scene; a :class:`SceneError` first if the
    scene exceeds ``limits`` (elements, DOFs: :func:`~flexmb_core.scene.limits.check_size`)."""
    check_size(scene, limits)
    mats = scene.materials
    secs = _sections(scene)
    dofs = number_dofs(scene)
    ndof, q0, q0_arr, dof_scale = dofs.ndof, dofs.q0, dofs.q0_array, dofs.dof_scale
    node_names, node_x, node_lookup, node_ydofs = dofs.node_names, dofs.node_x, dofs.node_lookup, dofs.node_ydofs
    member_infos, member_geom, member_lookup = dofs.member_infos, dofs.member_geom, dofs.member_lookup
    shells = dofs.shells

    # -- prescribed DOFs ------------------------------------------------------------------
    fixed = np.zeros(ndof, dtype=bool)
    drive_rows: list[tuple] = []
    drive_vectors: list[tuple] = []
    for ids in edge_support_dofs(scene, shells):
        fixed[ids] = True
    for s in scene.supports:
        if s.edge is not None:
            continue
        n = node_lookup[s.node]
        if s.type == "clamp" and s.member is None:      # a member's clamp leaves a hinged shell free
            for ids in clamp_node_gdofs(shells, n):
                fixed[ids] = True
        if s.type in ("clamp", "ball", "driven"):
            fixed[node_ydofs[n]] = True
        if s.type == "roller":                          # the position along the axis 'normal' only
            fixed[node_ydofs[n][int(np.argmax(np.abs(s.normal)))]] = True
        if s.type == "driven":
            drive_rows.append((node_ydofs[n], np.asarray(node_x[n], dtype=float),   # a shell point too
                               s.direction or (0.0, 0.0, 0.0), s.distance, s.axis or (0.0, 0.0, 1.0), s.angle))
        if s.type == "revolute":
            fixed[node_ydofs[n]] = True
            mi = member_infos[member_lookup[s.member]]
            k = int(np.nonzero(mi.nodes == n)[0][0])
            _, _, v1, v2 = member_geom[s.member]
            off = _axis_offset(f"{scene.source}:supports", s.member, s.node, v1[k], v2[k], np.asarray(s.axis))
            fixed[mi.vdofs[k, off:off + 3]] = True
        if s.type in ("clamp", "fixed_vector", "driven"):
            for mi in member_infos:
                if s.member is not None and mi.name != s.member:
                    continue
                for k in np.nonzero(mi.nodes == n)[0]:
                    if mi.vdofs[k, 0] < 0:
                        continue
                    if s.type in ("clamp", "driven"):
                        fixed[mi.vdofs[k]] = True
                        if s.type == "driven":
                            for off in (0, 3):
                                ids = mi.vdofs[k, off:off + 3]
                                drive_vectors.append((ids, q0[ids[0]:ids[0] + 3], len(drive_rows) - 1))
                    else:
                        off = 0 if s.vector == "v1" else 3
                        fixed[mi.vdofs[k, off:off + 3]] = True
    free = np.nonzero(~fixed)[0].astype(np.int64)
    free_index = np.full(ndof, -1, dtype=np.int64)
    free_index[free] = np.arange(free.size)

    # -- actuators ------------------------------------------------------------------------
    act_names = [m.name for m in scene.members.values() if m.kind == "actuator"]
    act_lookup = {n: i for i, n in enumerate(act_names)}
    act_l0 = np.array([member_infos[member_lookup[n]].length for n in act_names], dtype=float)
    act_cmd = tuple(scene.members[n].actuator.command for n in act_names)
    act_stroke = np.array([scene.members[n].actuator.stroke or (0.0, math.inf) for n in act_names],
                          dtype=float).reshape(-1, 2)
    act_ends = np.array([np.concatenate((member_infos[member_lookup[n]].ydofs[0],
                                         member_infos[member_lookup[n]].ydofs[-1])) for n in act_names],
                        dtype=np.int64).reshape(-1, 6)

    # -- elements ------------------------------------------------------------------------
    frame_build: dict[tuple[int, int], dict[str, list]] = defaultdict(lambda: defaultdict(list))
    truss_build: dict[str, list] = defaultdict(list)
    mass_rows: list[np.ndarray] = []
    mass_cols: list[np.ndarray] = []
    mass_vals: list[np.ndarray] = []
    for mi_id, mem in enumerate(scene.members.values()):
        info = member_infos[mi_id]
        mat = mats[mem.material]
        sec = secs[mem.section]
        act = act_lookup.get(mem.name, -1)
        x, _, v1, v2 = member_geom[mem.name]
        if info.vdofs[0, 0] >= 0:
            # Reduced rule (p Gauss points) is free of shear and membrane locking: thin members
            # bent into arcs converge with few elements; "full" (p + 2) is kept for comparison.
            n_axial = mem.order if mem.integration == "reduced" else mem.order + 2
            key = (mem.order, n_axial, sec.points.shape[0])
            row = np.array([mat.E, mat.E, mat.G, mat.G, sec.torsion / sec.polar, sec.shear_factor,
                            mat.eta / mat.E])
            iscale = None
            if mem.mass is not None:
                iscale = np.ones(3)
                if mem.mass.per_length is not None:
                    iscale[0] = mem.mass.per_length / (mat.rho * sec.area)
                if mem.mass.rotary_inertia is not None:
                    iscale[1] = mem.mass.rotary_inertia[0] / (mat.rho * sec.i1)
                    iscale[2] = mem.mass.rotary_inertia[1] / (mat.rho * sec.i2)
                iscale = np.tile(iscale, mem.order + 1)
            # every element of the member at once (numba): a 10⁵-element scene compiles in seconds
            ne = mem.elements
            where = f"{scene.source}:members.{mem.name}"
            dax, dsec, w, _ = _member_geometry(where, x, v1, v2, mem.order, n_axial, sec.points, ne)
            # The mass needs an exact rule whatever the stiffness rule: φℓφm has degree 2p.
            _, _, w_m, psi = _member_geometry(where, x, v1, v2, mem.order, mem.order + 1, sec.points, ne,
                                              mass_only=True)
            node_dofs = np.concatenate((info.ydofs, info.vdofs), axis=1)          # (nodes, 9)
            local = np.arange(ne)[:, None] * mem.order + np.arange(mem.order + 1)[None, :]
            edofs = node_dofs[local].reshape(ne, -1)                                 # (ne, 9n)
            b = frame_build[key]
            b["edofs"].append(edofs)
            b["dax"].append(dax)
            b["dsec"].append(dsec)
            b["w"].append(w)
            b["mat"].append(np.tile(row, (ne, 1)))
            b["act"].append(np.full(ne, act, dtype=np.int64))
            b["member"].append(np.full(ne, mi_id, dtype=np.int64))
            me = frame_member_mass(psi, w_m, mat.rho, iscale)
            k9 = edofs.shape[1]
            mass_rows.append(np.repeat(edofs, k9, axis=1).ravel())
            mass_cols.append(np.tile(edofs, (1, k9)).ravel())
            mass_vals.append(me.ravel())
        else:
            ea = mat.E * sec.area
            rho_a = mem.mass.per_length if (mem.mass and mem.mass.per_length) else mat.rho * sec.area
            for e in range(mem.elements):
                edofs = np.concatenate((info.ydofs[e], info.ydofs[e + 1]))
                l0 = float(np.linalg.norm(x[e + 1] - x[e]))
                truss_build["edofs"].append(edofs)
                truss_build["l0"].append(l0)
                truss_build["ea"].append(ea)
                truss_build["tau"].append(mat.eta / mat.E)
                truss_build["act"].append(act)
                truss_build["member"].append(mi_id)
                me = rho_a * l0 / 6.0 * np.kron(np.array([[2.0, 1.0], [1.0, 2.0]]), np.eye(3))
                mass_rows.append(np.repeat(edofs, 6))
                mass_cols.append(np.tile(edofs, 6))
                mass_vals.append(me.ravel())
    for pm in scene.point_masses:
        d = node_ydofs[node_lookup[pm.node]]
        mass_rows.append(d)
        mass_cols.append(d)
        mass_vals.append(np.full(3, pm.mass))

    # -- multiplier constraints and the sparse pattern over the system (free DOFs, then multipliers)
    cons = build_constraints(scene, dofs, free_index, free.size)
    nsys = cons.nsys
    # The mass adds no pair: every mass entry lies in the block of an element (frames, bars,
    # shells) or on the diagonal of a node that has one.
    parts = [free_index[ed] for b in frame_build.values() for ed in b["edofs"]]
    if truss_build:
        parts.append(free_index[np.asarray(truss_build["edofs"], dtype=np.int64)])
    parts += [free_index[ed][None, :] for ed in shell_element_pairs(shells)]
    parts += [idx[None, :] for idx in cons.system_blocks()]
    pattern = Pattern.from_blocks(parts, nsys, free_index)
    del parts
    keys, indptr, indices = pattern.keys, pattern.indptr, pattern.indices
    scatter_map = pattern.map

    groups = []
    for (order, _, nsec), b in sorted(frame_build.items()):
        edofs = np.ascontiguousarray(np.concatenate(b["edofs"]), dtype=np.int64)
        g = FrameGroup(order, nsec, edofs, np.ascontiguousarray(np.concatenate(b["dax"])),
                       np.ascontiguousarray(np.concatenate(b["dsec"])), np.ascontiguousarray(np.concatenate(b["w"])),
                       np.ascontiguousarray(np.concatenate(b["mat"]), dtype=float),
                       np.ascontiguousarray(np.concatenate(b["act"]), dtype=np.int64),
                       np.ascontiguousarray(pattern.maps(edofs), dtype=np.int64),
                       np.ascontiguousarray(np.concatenate(b["member"]), dtype=np.int64))
        _freeze(g.edofs, g.dax, g.dsec, g.w, g.mat, g.act, g.smap, g.member)
        groups.append(g)
        b.clear()                                   # the per-member blocks: copied into the group
    truss = None
    if truss_build:
        edofs = np.asarray(truss_build["edofs"], dtype=np.int64)
        truss = TrussGroup(edofs, np.asarray(truss_build["l0"], dtype=float),
                           np.asarray(truss_build["ea"], dtype=float),
                           np.asarray(truss_build["act"], dtype=np.int64),
                           np.ascontiguousarray([scatter_map(ed) for ed in edofs], dtype=np.int64),
                           np.asarray(truss_build["member"], dtype=np.int64),
                           np.asarray(truss_build["tau"], dtype=float))
        _freeze(truss.edofs, truss.l0, truss.ea, truss.act, truss.smap, truss.member, truss.tau)

    shell_groups = build_shell_groups(scene, shells, scatter_map, mass_rows, mass_cols, mass_vals)
    for out in scene.outputs:
        if out.kind == "shell_point":
            shell_point_node(next(i for i in shells if i.name == out.shell), out.at,
                             f"{scene.source}:outputs.{out.name}.at", out.edge and out.edge[1])

    # -- mass -------------------------------------------------------------------------------
    mr, mc, mv = np.concatenate(mass_rows), np.concatenate(mass_cols), np.concatenate(mass_vals)
    mfull = sp.csr_matrix((mv, (mr, mc)), shape=(ndof, ndof))
    mfull.sum_duplicates()
    mfull.sort_indices()
    fr, fc = free_index[mr], free_index[mc]
    ok = (fr >= 0) & (fc >= 0)
    mass_kdata = np.zeros(keys.size)
    mkeys = fr[ok] * nsys + fc[ok]
    pos = np.minimum(np.searchsorted(keys, mkeys), keys.size - 1)
    if not np.array_equal(keys[pos], mkeys):      # the pattern holds every mass entry (see above)
        raise AssertionError("compile_scene: a mass entry outside the element blocks' sparsity pattern")
    np.add.at(mass_kdata, pos, mv[ok])
    # free the per-entry temporaries before the rest is built (a 10⁴-element frame scene holds
    # ~10⁸ bytes per copy of them)
    del mass_rows, mass_cols, mass_vals, mr, mc, mv, fr, fc, ok, mkeys, pos
    u_trans = np.zeros((ndof, 3))
    for n in range(len(node_names)):
        u_trans[node_ydofs[n], np.arange(3)] = 1.0
    total_mass = float((mfull @ u_trans)[:, 0].sum())

    # -- loads ------------------------------------------------------------------------------
    edge_patterns, edge_signals, edge_moments = edge_load_patterns(scene, shells, ndof)
    load_vectors = np.zeros((len(scene.forces) + len(edge_patterns), ndof))
    for i, f in enumerate(scene.forces):
        load_vectors[i, node_ydofs[node_lookup[f.node]]] = f.force
    for i, edge_pattern in enumerate(edge_patterns):
        load_vectors[len(scene.forces) + i] = edge_pattern
    gravity_vector = np.zeros(ndof)
    gravity_signal = Signal()
    if scene.gravity is not None:
        gravity_vector = mfull @ (u_trans @ np.asarray(scene.gravity.acceleration, dtype=float))
        gravity_signal = scene.gravity.signal
    moments = _moment_loads(scene, member_infos, member_lookup, member_geom, node_lookup, scatter_map, edge_moments)

    drives = None
    if drive_rows:
        drives = Drives(np.array([r[0] for r in drive_rows], dtype=np.int64), np.array([r[1] for r in drive_rows]),
                        np.array([r[2] for r in drive_rows], dtype=float), tuple(r[3] for r in drive_rows),
                        np.array([r[4] for r in drive_rows], dtype=float), tuple(r[5] for r in drive_rows),
                        np.array([v[0] for v in drive_vectors], dtype=np.int64).reshape(-1, 3),
                        np.array([v[1] for v in drive_vectors], dtype=float).reshape(-1, 3),
                        np.array([v[2] for v in drive_vectors], dtype=np.int64))
        _freeze(drives.y_ids, drives.y0, drives.direction, drives.axis, drives.v_ids, drives.v0, drives.v_drive)
    program, program_index = None, np.zeros(0, dtype=np.int64)
    if scene.commands is not None:
        from ..commands import build_program
        program_index = np.array([act_lookup[a] for a in scene.commands.actuators], dtype=np.int64)
        program = build_program(scene.commands, act_l0[program_index], f"{scene.source}:commands")
    mass_csr = (mfull.indptr.astype(np.int64), mfull.indices.astype(np.int64), mfull.data.astype(float))
    actuators = Actuators(tuple(act_names), np.array([member_lookup[n] for n in act_names], dtype=np.int64),
                          act_l0, act_cmd, act_stroke, act_ends, _servo_params(scene, act_names, act_stroke))
    _freeze(q0_arr, dof_scale, free, free_index, indptr, indices, mass_kdata, *mass_csr, load_vectors,
            gravity_vector, node_ydofs, act_l0, act_stroke, act_ends, actuators.member)
    return Model(scene, ndof, q0_arr, dof_scale, free, free_index, indptr, indices, mass_kdata, mass_csr,
                 tuple(groups), truss, moments, load_vectors,
                 tuple(f.signal for f in scene.forces) + tuple(edge_signals),
                 gravity_vector, gravity_signal, actuators, tuple(member_infos), tuple(node_names), node_ydofs,
                 scene.mass_damping, total_mass, drives, program, program_index, nsys, **cons.arrays(pattern),
                 node_lookup=node_lookup, member_lookup=member_lookup, shell_groups=shell_groups, shells=shells)


def _sections(scene: Scene) -> dict[str, secmod.SectionProperties]:
    """Section properties per section name (SI: m², m⁴), with the Poisson ratio of the first
    member's material that uses the section (0 if none does) for the shear factor."""
    mats = scene.materials
    secs: dict[str, secmod.SectionProperties] = {}
    for name, spec in scene.sections.items():
        used_nu = [mats[m.material].nu for m in scene.members.values() if m.section == name]
        nu = used_nu[0] if used_nu else 0.0
        if spec.shape == "rectangle":
            p = secmod.rectangle(*spec.dims, nu)
        elif spec.shape == "circle":
            p = secmod.circle(*spec.dims, nu)
        else:
            p = secmod.tube(*spec.dims, nu)
        secs[name] = secmod.with_overrides(p, spec.torsion_constant, spec.shear_factor)
    return secs


def _servo_params(scene: Scene, act_names: list[str], act_stroke: np.ndarray) -> ServoParams | None:
    """The declared servos as arrays (:mod:`flexmb_core.servo`); None when no actuator has one."""
    specs = [(i, scene.members[n].actuator.servo) for i, n in enumerate(act_names)
             if scene.members[n].actuator.servo is not None]
    if not specs:
        return None
    idx = np.array([i for i, _ in specs], dtype=np.int64)
    col = lambda f: np.array([f(s) for _, s in specs], dtype=float)  # noqa: E731
    p = ServoParams(idx, col(lambda s: 2.0 * math.pi * s.bandwidth_hz), col(lambda s: s.damping_ratio),
                    col(lambda s: s.max_rate), col(lambda s: s.max_accel), np.ascontiguousarray(act_stroke[idx]))
    _freeze(p.index, p.wn, p.zeta, p.max_rate, p.max_accel, p.stroke)
    return p


def _member_geometry(where: str, *args, **kw):
    """:func:`frame_member_geometry` with its ValueError (a degenerate element) as a SceneError."""
    try:
        return frame_member_geometry(*args, **kw)
    except ValueError as exc:
        raise SceneError(where, str(exc)) from None


def _moment_loads(scene, member_infos, member_lookup, member_geom, node_lookup, scatter_map,
                  extra_conservative=()) -> MomentLoads:
    """Member end moments, plus ``extra_conservative`` (vector ids, axes, magnitude, signal) entries
    (shell edge moments on the directors)."""
    f_v, f_m, f_s, f_sig = [], [], [], []
    c_v, c_ax, c_mag, c_s, c_sig = [], [], [], [], []
    for ids, axes, mag, sig in extra_conservative:
        c_v.append(ids)
        c_ax.append(axes)
        c_mag.append(mag)
        c_s.append(scatter_map(ids))
        c_sig.append(sig)
    for mo in scene.moments:
        info = member_infos[member_lookup[mo.member]]
        k = int(np.nonzero(info.nodes == node_lookup[mo.node])[0][0])
        _, t, v1, v2 = member_geom[mo.member]
        vd = info.vdofs[k]
        mvec = np.asarray(mo.moment, dtype=float)
        if mo.follower:
            f_v.append(vd)
            f_m.append([mvec @ t[k], mvec @ v1[k], mvec @ v2[k]])
            f_s.append(scatter_map(vd))
            f_sig.append(mo.signal)
        else:
            mag = float(np.linalg.norm(mvec))
            if mag == 0.0:
                continue
            n = mvec / mag
            use_v1 = abs(v1[k] @ n) <= abs(v2[k] @ n)
            v0 = v1[k] if use_v1 else v2[k]
            ids = vd[:3] if use_v1 else vd[3:]
            a = v0 - (v0 @ n) * n
            a /= np.linalg.norm(a)
            c_v.append(ids)
            c_ax.append(np.array([a, np.cross(n, a), n]))
            c_mag.append(mag)
            c_s.append(scatter_map(ids))
            c_sig.append(mo.signal)
    out = MomentLoads(np.asarray(f_v, dtype=np.int64).reshape(-1, 6), np.asarray(f_m, dtype=float).reshape(-1, 3),
                      np.asarray(f_s, dtype=np.int64).reshape(-1, 36), tuple(f_sig),
                      np.asarray(c_v, dtype=np.int64).reshape(-1, 3), np.asarray(c_ax, dtype=float).reshape(-1, 3, 3),
                      np.asarray(c_mag, dtype=float), np.asarray(c_s, dtype=np.int64).reshape(-1, 9), tuple(c_sig))
    _freeze(out.follower_vdofs, out.follower_mbody, out.follower_smap, out.cons_vdofs, out.cons_axes,
            out.cons_magnitude, out.cons_smap)
    return out
