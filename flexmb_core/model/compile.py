"""Scene → :class:`Model`: DOF numbering, element groups (only the kinds present), constant mass,
free–free sparse pattern and the scatter maps that let kernels add into CSR data directly."""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
import scipy.sparse as sp

from .. import sections as secmod
from ..errors import SceneError, excerpt, name_list, thousands
from ..scene.limits import Limits, check_size
from ..scene.schema import Member, Scene, Signal
from ..servo import ServoParams
from .frame_geometry import frame_member_geometry, frame_member_mass
from .model import Actuators, Drives, FrameGroup, MemberInfo, Model, MomentLoads, TrussGroup
from .shell_compile import (build_shell_groups, clamp_node_gdofs, compact_drafts, edge_load_patterns,
                            edge_support_dofs, number_shell_nodes, shell_element_pairs, shell_infos,
                            shell_point_node)


def _freeze(*arrays: np.ndarray) -> None:
    for a in arrays:
        a.setflags(write=False)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def member_geometry(mem: Member, nodes: dict, source: str = "<scene>"
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Reference node positions, tangents and section vectors along a member.

    Returns ``x (m, 3)``, ``t (m, 3)``, ``v1 (m, 3)``, ``v2 (m, 3)`` with m = elements·order + 1.
    ``V2`` is ``up`` made orthogonal to the tangent (default: global z, or x for members within
    8° of vertical); ``V1 = V2 × t`` so that (t, V1, V2) is right-handed.
    """
    a = np.asarray(nodes[mem.start], dtype=float)
    b = np.asarray(nodes[mem.end], dtype=float)
    m = mem.elements * mem.order + 1
    s = np.linspace(0.0, 1.0, m)
    if mem.arc_center is None:
        x = a + s[:, None] * (b - a)
        t = np.tile(_unit(b - a), (m, 1))
    else:
        c = np.asarray(mem.arc_center, dtype=float)
        ra, rb = a - c, b - c
        radius = np.linalg.norm(ra)
        normal = np.cross(ra, rb)
        if np.linalg.norm(normal) < 1e-12 * radius**2:
            raise SceneError(f"{source}:members.{mem.name}.arc", "arc from/to are collinear with the centre (180° or 0° arc): ambiguous plane")
        normal = _unit(normal)
        angle = math.atan2(np.linalg.norm(np.cross(ra, rb)), ra @ rb)
        e1 = ra / radius
        e2 = np.cross(normal, e1)
        phi = s * angle
        x = c + radius * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
        t = -np.sin(phi)[:, None] * e1 + np.cos(phi)[:, None] * e2
    # every node at once (a 10⁵-element scene has 3·10⁵ of them)
    if mem.up is not None:
        up = np.broadcast_to(np.asarray(mem.up, dtype=float), t.shape)
    else:
        steep = np.abs(t[:, 2]) >= math.cos(math.radians(8))
        up = np.where(steep[:, None], np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]))
    u = up - np.einsum("ij,ij->i", up, t)[:, None] * t
    norm_u = np.sqrt(np.einsum("ij,ij->i", u, u))
    norm_up = np.sqrt(np.einsum("ij,ij->i", up, up))
    flat = norm_u < 1e-9 * norm_up
    if flat.any():
        raise SceneError(f"{source}:members.{mem.name}.up",
                         f"'up' {excerpt(up[int(np.argmax(flat))].tolist())} is parallel to the member axis")
    v2 = u / norm_u[:, None]
    v1 = np.cross(v2, t)
    return x, t, v1, v2


def _number_member_dofs(ids: np.ndarray, ydof: list, node_x: list, x: np.ndarray, v1: np.ndarray,
                        v2: np.ndarray, is_frame: bool, take) -> tuple[np.ndarray, np.ndarray]:
    """DOFs of a member's nodes, node after node: the position (3, if the node has none yet) then,
    for frames, the two section vectors (6) — the numbering of a per-node loop, done in one pass.

    ``ydof`` (node → first position DOF or −1) is updated in place; ``take(values, kinds)`` appends
    the reference values and their kinds (0 position, 1 vector) and returns the first new DOF.
    Returns ``yd (m, 3)`` and ``vd (m, 6)`` (−1 for bars).
    """
    m = ids.size
    new_y = np.fromiter((ydof[n] < 0 for n in ids.tolist()), dtype=bool, count=m)
    per_node = 3 * new_y + (6 if is_frame else 0)
    block = np.concatenate((x, v1, v2), axis=1)                  # (m, 9) reference values
    for k in np.flatnonzero(new_y).tolist():
        block[k, :3] = node_x[ids[k]]                             # a scene node keeps its own coordinates
    mask = np.zeros((m, 9), dtype=bool)
    mask[:, :3] = new_y[:, None]
    mask[:, 3:] = is_frame
    kinds = np.broadcast_to(np.array([0, 0, 0, 1, 1, 1, 1, 1, 1]), (m, 9))
    base = take(block[mask], kinds[mask])
    starts = base + np.concatenate(([0], np.cumsum(per_node)[:-1]))
    for k in np.flatnonzero(new_y).tolist():
        ydof[ids[k]] = int(starts[k])
    yd = np.fromiter((ydof[n] for n in ids.tolist()), dtype=np.int64, count=m)[:, None] + np.arange(3)
    vd = np.full((m, 6), -1, dtype=np.int64)
    if is_frame:
        vd[:] = (starts + 3 * new_y)[:, None] + np.arange(6)
    return yd, vd


def member_length(x: np.ndarray) -> float:
    """Polyline length through the member's nodes (m)."""
    return float(np.sum(np.linalg.norm(np.diff(x, axis=0), axis=1)))


def compile_scene(scene: Scene, limits: Limits | None = None) -> Model:
    """Build the read-only :class:`Model` of a validated scene; a :class:`SceneError` first if the
    scene exceeds ``limits`` (elements, DOFs: :func:`~flexmb_core.scene.limits.check_size`)."""
    check_size(scene, limits)
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

    node_names = list(scene.nodes)
    node_x = [np.asarray(scene.nodes[n], dtype=float) for n in node_names]
    node_lookup = {n: i for i, n in enumerate(node_names)}
    ydof = [-1] * len(node_names)
    ndof = 0
    q0: list[float] = []
    scale_kind: list[int] = []  # 0 position, 1 vector

    def take(values, kind):
        """Append reference values (their kind: 0 position, 1 vector; one for all or one each)."""
        nonlocal ndof
        start = ndof
        values = np.asarray(values, dtype=float).ravel()
        q0.extend(values.tolist())
        scale_kind.extend(np.broadcast_to(np.asarray(kind), values.shape).tolist())
        ndof += values.size
        return start

    member_infos: list[MemberInfo] = []
    member_geom = {}
    for mem in scene.members.values():
        x, t, v1, v2 = member_geometry(mem, scene.nodes, scene.source)
        member_geom[mem.name] = (x, t, v1, v2)
        m = x.shape[0]
        ids = np.empty(m, dtype=np.int64)
        ids[0], ids[-1] = node_lookup[mem.start], node_lookup[mem.end]
        via_at = {}
        for v in mem.via:
            dist = np.linalg.norm(x - np.asarray(scene.nodes[v]), axis=1)
            k = int(np.argmin(dist))
            if dist[k] > 1e-9 * member_length(x) or k in (0, m - 1):
                raise SceneError(f"{scene.source}:members.{mem.name}.via",
                                 f"node '{v}' is not at an interior element node of the member (closest "
                                 f"node {dist[k]:.3g} m away); choose 'elements' so that an element "
                                 "boundary falls on it")
            via_at[k] = node_lookup[v]
        for k, n in via_at.items():
            ids[k] = n
        interior = [k for k in range(1, m - 1) if k not in via_at]
        names = [f"{mem.name}/{k}" for k in interior]
        clash = node_lookup.keys() & set(names)
        if clash:
            name = min(clash, key=lambda c: int(c.rsplit("/", 1)[1]))
            k = int(name.rsplit("/", 1)[1])
            raise SceneError(f"{scene.source}:nodes.{name}", f"the name '{name}' is taken by interior node {k} "
                             f"of member '{mem.name}'; rename the scene node (names 'member/k' are generated)")
        first = len(node_names)
        node_lookup.update(zip(names, range(first, first + len(names))))
        node_names.extend(names)
        node_x.extend(x[interior])
        ydof.extend([-1] * len(names))
        ids[interior] = np.arange(first, first + len(names))
        is_frame = mem.kind == "frame" or (mem.kind == "actuator" and mem.actuator.variant == "frame")
        yd, vd = _number_member_dofs(ids, ydof, node_x, x, v1, v2, is_frame, take)
        if mem.kind == "actuator" and mem.arc_center is not None:
            raise SceneError(f"{scene.source}:members.{mem.name}", "actuators must be straight (no 'arc')")
        member_infos.append(MemberInfo(mem.name, mem.kind, ids, yd, vd, member_length(x)))
    drafts = number_shell_nodes(scene, node_lookup, node_names, node_x, ydof,
                                {mi.name: mi.nodes for mi in member_infos}, take)
    corners: list[tuple[str, str, str]] = []
    hinges: list[tuple[str, str, str, tuple]] = []
    if scene.joints:
        remap = _joint_dof_map(scene, ndof, member_infos, member_geom, node_lookup, corners, hinges)
        keep = np.unique(remap)
        q0 = [q0[i] for i in keep]
        scale_kind = [scale_kind[i] for i in keep]
        ndof = keep.size
        compact = np.searchsorted(keep, remap)
        ydof = [int(compact[y]) if y >= 0 else -1 for y in ydof]
        member_infos = [MemberInfo(mi.name, mi.kind, mi.nodes, compact[mi.ydofs],
                                   np.where(mi.vdofs >= 0, compact[np.maximum(mi.vdofs, 0)], -1), mi.length)
                        for mi in member_infos]
        compact_drafts(drafts, compact)
    unused = [n for i, n in enumerate(scene.nodes) if ydof[i] < 0]
    if unused:
        raise SceneError(f"{scene.source}:nodes", f"node(s) {name_list(unused)} are not used by any member or shell "
                                                  f"({thousands(len(unused))} in all)")

    q0_arr = np.asarray(q0, dtype=float)
    nodes_xyz = np.asarray(node_x)
    l_char = max(float(np.linalg.norm(nodes_xyz.max(0) - nodes_xyz.min(0))),
                 max((mi.length for mi in member_infos), default=0.0))
    dof_scale = np.where(np.asarray(scale_kind) == 0, l_char, 1.0)
    node_ydofs = np.asarray(ydof, dtype=np.int64)[:, None] + np.arange(3)
    member_lookup = {mi.name: i for i, mi in enumerate(member_infos)}
    shells = shell_infos(drafts, node_ydofs)

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

    # -- rigid corners (multipliers) ---------------------------------------------------------
    nfree = free.size
    infos_by_name = {mi.name: mi for mi in member_infos}
    corner_dofs, corner_alpha, corner_sys = [], [], []
    for ci, (ma, mb, node) in enumerate(corners):
        n = node_lookup[node]
        ka = int(np.nonzero(infos_by_name[ma].nodes == n)[0][0])
        kb = int(np.nonzero(infos_by_name[mb].nodes == n)[0][0])
        _, _, v1a, v2a = member_geom[ma]
        _, _, v1b, v2b = member_geom[mb]
        w0 = np.array([v1a[ka], v2a[ka], np.cross(v1a[ka], v2a[ka])])
        corner_alpha.append(np.array([w0 @ v1b[kb], w0 @ v2b[kb]]))
        ids = np.concatenate((infos_by_name[mb].vdofs[kb], infos_by_name[ma].vdofs[ka]))
        corner_dofs.append(ids)
        corner_sys.append(np.concatenate((free_index[ids], nfree + 6 * ci + np.arange(6))))
    hinge_dofs, hinge_alpha, hinge_beta, hinge_sys = [], [], [], []
    base = nfree + 6 * len(corners)
    for hi, (ma, mb, node, axis) in enumerate(hinges):
        n = node_lookup[node]
        ka = int(np.nonzero(infos_by_name[ma].nodes == n)[0][0])
        kb = int(np.nonzero(infos_by_name[mb].nodes == n)[0][0])
        _, _, v1a, v2a = member_geom[ma]
        _, _, v1b, v2b = member_geom[mb]
        axis = _unit(axis)
        wa = np.array([v1a[ka], v2a[ka], np.cross(v1a[ka], v2a[ka])])
        wb = np.array([v1b[kb], v2b[kb], np.cross(v1b[kb], v2b[kb])])
        seed = np.eye(3)[int(np.argmin(np.abs(axis)))]
        b1 = _unit(seed - (seed @ axis) * axis)
        b2 = np.cross(axis, b1)
        hinge_alpha.append(wa @ axis)
        hinge_beta.append(np.array([wb @ b1, wb @ b2]))
        ids = np.concatenate((infos_by_name[ma].vdofs[ka], infos_by_name[mb].vdofs[kb]))
        hinge_dofs.append(ids)
        hinge_sys.append(np.concatenate((free_index[ids], base + 2 * hi + np.arange(2))))
    tie_dofs, tie_alpha, tie_sys = _shell_frame_ties(scene, shells, infos_by_name, member_geom, node_lookup,
                                                     free_index, base + 2 * len(hinges))
    nsys = base + 2 * len(hinges) + 3 * len(tie_dofs)

    # -- sparse pattern over the system (free DOFs, then multipliers) ----------------------
    # Keys r·nsys + c of every element block, built block by block (no repeat/tile copies: a
    # 10⁴-element frame scene has 1.3·10⁷ pairs). The mass adds no pair: every mass entry lies in
    # the block of an element (frames, bars, shells) or on the diagonal of a node that has one.
    def block_keys(idx: np.ndarray) -> np.ndarray:
        """Keys of the (row, col) pairs of system indices ``idx (ne, k)`` where both are ≥ 0."""
        k = (idx[:, :, None] * nsys + idx[:, None, :]).ravel()
        both = ((idx[:, :, None] >= 0) & (idx[:, None, :] >= 0)).ravel()
        return k[both]

    key_parts = [block_keys(free_index[ed]) for b in frame_build.values() for ed in b["edofs"]]
    if truss_build:
        key_parts.append(block_keys(free_index[np.asarray(truss_build["edofs"], dtype=np.int64)]))
    key_parts += [block_keys(free_index[ed][None, :]) for ed in shell_element_pairs(shells)]
    key_parts += [block_keys(idx[None, :]) for idx in corner_sys + hinge_sys + tie_sys]
    keys = _sorted_unique(np.concatenate(key_parts))
    del key_parts
    rows = keys // nsys
    indices = (keys % nsys).astype(np.int64)
    indptr = np.zeros(nsys + 1, dtype=np.int64)
    np.add.at(indptr, rows + 1, 1)
    indptr = np.cumsum(indptr).astype(np.int64)

    def scatter_map_sys(idx: np.ndarray) -> np.ndarray:
        """CSR position of every (row, col) pair of system indices ``idx`` (−1 outside)."""
        r = np.repeat(idx, idx.size)
        c = np.tile(idx, idx.size)
        out = np.full(r.size, -1, dtype=np.int64)
        ok_ = (r >= 0) & (c >= 0)
        out[ok_] = np.searchsorted(keys, r[ok_] * nsys + c[ok_])
        return out

    def scatter_map(ed: np.ndarray) -> np.ndarray:
        return scatter_map_sys(free_index[ed])

    def scatter_maps(edofs: np.ndarray) -> np.ndarray:
        """:func:`scatter_map` of every row of ``edofs (ne, k)`` at once: ``(ne, k²)``."""
        idx = free_index[edofs]
        ne, k = idx.shape
        out = (idx[:, :, None] * nsys + idx[:, None, :]).reshape(ne, k * k)
        ok_ = ((idx[:, :, None] >= 0) & (idx[:, None, :] >= 0)).reshape(ne, k * k)
        out[ok_] = np.searchsorted(keys, out[ok_])
        out[~ok_] = -1
        return out

    groups = []
    for (order, _, nsec), b in sorted(frame_build.items()):
        edofs = np.ascontiguousarray(np.concatenate(b["edofs"]), dtype=np.int64)
        g = FrameGroup(order, nsec, edofs, np.ascontiguousarray(np.concatenate(b["dax"])),
                       np.ascontiguousarray(np.concatenate(b["dsec"])), np.ascontiguousarray(np.concatenate(b["w"])),
                       np.ascontiguousarray(np.concatenate(b["mat"]), dtype=float),
                       np.ascontiguousarray(np.concatenate(b["act"]), dtype=np.int64),
                       np.ascontiguousarray(scatter_maps(edofs), dtype=np.int64),
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
    for i, pattern in enumerate(edge_patterns):
        load_vectors[len(scene.forces) + i] = pattern
    gravity_vector = np.zeros(ndof)
    gravity_signal = Signal()
    if scene.gravity is not None:
        gravity_vector = mfull @ (u_trans @ np.asarray(scene.gravity.acceleration, dtype=float))
        gravity_signal = scene.gravity.signal
    moments = _moment_loads(scene, member_infos, member_lookup, member_geom, node_lookup, scatter_map, edge_moments)

    corner_arrays = (np.asarray(corner_dofs, dtype=np.int64).reshape(-1, 12),
                     np.asarray(corner_alpha, dtype=float).reshape(-1, 2, 3),
                     np.asarray([scatter_map_sys(idx) for idx in corner_sys], dtype=np.int64).reshape(-1, 324))
    hinge_arrays = (np.asarray(hinge_dofs, dtype=np.int64).reshape(-1, 12),
                    np.asarray(hinge_alpha, dtype=float).reshape(-1, 3),
                    np.asarray(hinge_beta, dtype=float).reshape(-1, 2, 3),
                    np.asarray([scatter_map_sys(idx) for idx in hinge_sys], dtype=np.int64).reshape(-1, 196))
    tie_arrays = (np.asarray(tie_dofs, dtype=np.int64).reshape(-1, 9),
                  np.asarray(tie_alpha, dtype=float).reshape(-1, 3),
                  np.asarray([scatter_map_sys(idx) for idx in tie_sys], dtype=np.int64).reshape(-1, 144))
    _freeze(*corner_arrays, *hinge_arrays, *tie_arrays)
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
                 scene.mass_damping, total_mass, drives, program, program_index, nsys, *corner_arrays,
                 *hinge_arrays, node_lookup, member_lookup, shell_groups, shells, *tie_arrays)


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


def _sorted_unique(a: np.ndarray) -> np.ndarray:
    """``np.unique`` of an int64 array by sort and compare (numpy's hash-based default is several
    times slower on the 10⁷ CSR keys of a 10⁴-element frame scene); the same values."""
    a = np.sort(a, kind="stable")
    keep = np.empty(a.size, dtype=bool)
    keep[:1] = True
    np.not_equal(a[1:], a[:-1], out=keep[1:])
    return a[keep]


def _member_geometry(where: str, *args, **kw):
    """:func:`frame_member_geometry` with its ValueError (a degenerate element) as a SceneError."""
    try:
        return frame_member_geometry(*args, **kw)
    except ValueError as exc:
        raise SceneError(where, str(exc)) from None


def _axis_offset(where: str, member: str, node: str, v1: np.ndarray, v2: np.ndarray, axis: np.ndarray) -> int:
    """0 if V1 lies on ``axis``, 3 if V2 does (same sense); otherwise a SceneError with a hint."""
    for off, v in ((0, v1), (3, v2)):
        if v @ axis > 1.0 - 1e-9:
            return off
    raise SceneError(where, f"member '{member}' has no section vector along the axis {axis.tolist()} at node "
                            f"'{node}' (V1 = {np.round(v1, 6).tolist()}, V2 = {np.round(v2, 6).tolist()}); "
                            "set the member's 'up' to the axis so that V2 lies on it")


def _joint_dof_map(scene: Scene, ndof: int, member_infos, member_geom, node_lookup, corners: list,
                   hinges: list) -> np.ndarray:
    """For every DOF, the DOF it is merged into by the scene's joints (union–find roots).

    Rigid joints between members with different section frames cannot be expressed by sharing;
    they are appended to ``corners`` as (member a, member b, node) for Lagrange multipliers;
    revolute joints whose axis is not a section vector of every member go to ``hinges``.
    """
    parent = np.arange(ndof)

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    infos = {mi.name: mi for mi in member_infos}
    for j_idx, j in enumerate(scene.joints):
        where = f"{scene.source}:joints[{j_idx}]"
        if j.type == "spherical":
            continue                                   # shared nodes already share positions
        n = node_lookup[j.node]
        first = None
        if j.type == "revolute":
            axis = np.asarray(j.axis)
            aligned = []
            for name in j.members:
                k = int(np.nonzero(infos[name].nodes == n)[0][0])
                _, _, v1, v2 = member_geom[name]
                aligned.append(abs(v1[k] @ axis) > 1.0 - 1e-9 or abs(v2[k] @ axis) > 1.0 - 1e-9)
            if not all(aligned):
                # the axis lies in no common section plane: hold the hinge by multipliers
                for name in j.members[1:]:
                    hinges.append((j.members[0], name, j.node, tuple(j.axis)))
                continue
        for name in j.members:
            mi = infos[name]
            k = int(np.nonzero(mi.nodes == n)[0][0])
            _, _, v1, v2 = member_geom[name]
            if j.type == "rigid":
                ids = mi.vdofs[k]
                frame = np.concatenate((v1[k], v2[k]))
            else:
                off = _axis_offset(where, name, j.node, v1[k], v2[k], axis)
                ids = mi.vdofs[k, off:off + 3]
                frame = axis
            if first is None:
                first = (name, ids, frame)
                continue
            if j.type == "rigid" and not np.allclose(frame, first[2], atol=1e-9):
                corners.append((first[0], name, j.node))       # held by multipliers, not by sharing
                continue
            for a, b in zip(first[1], ids):
                parent[find(int(b))] = find(int(a))
    return np.array([find(i) for i in range(ndof)], dtype=np.int64)


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


def _shell_frame_ties(scene: Scene, shells, infos_by_name, member_geom, node_lookup, free_index: np.ndarray,
                      first_multiplier: int) -> tuple[list, list, list]:
    """``shell_rigid`` joints: the shell director G at a corner node tied to the frame member's
    section vectors, G = α1 V1 + α2 V2 + α3 V1 × V2 with α from the reference geometry (3
    multipliers each, numbered from ``first_multiplier``). Returns (dofs [G, V1, V2] (9,), α (3,),
    system ids (12,)) per tie."""
    dofs, alpha, sys_ids = [], [], []
    by_shell = {i.name: i for i in shells}
    for j in scene.shell_joints:
        if j.type != "shell_rigid":
            continue
        n = node_lookup[j.node]
        info = by_shell[j.shell]
        ks = int(np.nonzero(info.nodes == n)[0][0])
        mi = infos_by_name[j.member]
        km = int(np.nonzero(mi.nodes == n)[0][0])
        _, _, v1, v2 = member_geom[j.member]
        frame = np.array([v1[km], v2[km], np.cross(v1[km], v2[km])])
        alpha.append(frame @ info.normal0[ks])
        ids = np.concatenate((info.gdofs[ks], mi.vdofs[km]))
        dofs.append(ids)
        sys_ids.append(np.concatenate((free_index[ids], first_multiplier + 3 * len(sys_ids) + np.arange(3))))
    return dofs, alpha, sys_ids
