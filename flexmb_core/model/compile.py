"""Scene → :class:`Model`: DOF numbering, element groups (only the kinds present), constant mass,
free–free sparse pattern and the scatter maps that let kernels add into CSR data directly.

:func:`compile_scene` runs the stages in order, each a function of its own: sections
(:func:`_sections`), DOF numbering (:func:`~flexmb_core.model.dof_numbering.number_dofs`),
prescribed DOFs and drives (:func:`_prescribed`), actuators (:func:`_actuators`), element blocks
and their mass entries (:func:`_element_blocks`), multiplier constraints
(:func:`~flexmb_core.model.constraints.build_constraints`),
the sparsity pattern (:func:`_sparsity`, :class:`~flexmb_core.model.pattern.Pattern`), element
groups with their scatter maps (:func:`_frame_groups`, :func:`_truss_group`), mass
(:func:`_mass`) and loads (:func:`_loads`). Errors are raised in the same order as the stages.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .. import sections as secmod
from ..errors import SceneError
from ..scene.limits import Limits, check_size
from ..scene.schema import Member, Scene, Signal
from ..servo import ServoParams
from .constraints import Constraints, build_constraints
from .dof_numbering import DofTable, _axis_offset, member_geometry, number_dofs
from .frame_geometry import frame_member_geometry, frame_member_mass
from .model import Actuators, Drives, FrameGroup, MemberInfo, Model, MomentLoads, TrussGroup
from .pattern import Pattern
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
    secs = _sections(scene)
    dofs = number_dofs(scene)
    bc = _prescribed(scene, dofs)
    actuators, act_lookup = _actuators(scene, dofs)
    blocks = _element_blocks(scene, dofs, secs, act_lookup)
    cons = build_constraints(scene, dofs, bc.free_index, bc.free.size)
    pattern = _sparsity(blocks, dofs, cons, bc.free_index)
    groups = _frame_groups(blocks.frames, pattern)
    truss = _truss_group(blocks.truss, pattern)
    shell_groups = build_shell_groups(scene, dofs.shells, pattern.map, blocks.mass_rows, blocks.mass_cols,
                                      blocks.mass_vals)
    _check_outputs(scene, dofs)
    mass = _mass(blocks, dofs, pattern)
    loads = _loads(scene, dofs, pattern, mass)
    program, program_index = _command_program(scene, act_lookup, actuators.l0)
    return Model(scene=scene, ndof=dofs.ndof, q0=dofs.q0_array, dof_scale=dofs.dof_scale, free=bc.free,
                 free_index=bc.free_index, indptr=pattern.indptr, indices=pattern.indices, mass_kdata=mass.kdata,
                 mass_csr=mass.csr, frame_groups=tuple(groups), truss=truss, moments=loads.moments,
                 load_vectors=loads.vectors, load_signals=loads.signals, gravity_vector=loads.gravity_vector,
                 gravity_signal=loads.gravity_signal, actuators=actuators, members=tuple(dofs.member_infos),
                 node_names=tuple(dofs.node_names), node_ydofs=dofs.node_ydofs, mass_damping=scene.mass_damping,
                 total_mass=mass.total, drives=bc.drives, program=program, program_index=program_index,
                 nsys=cons.nsys, **cons.arrays(pattern), node_lookup=dofs.node_lookup,
                 member_lookup=dofs.member_lookup, shell_groups=shell_groups, shells=dofs.shells)


# -- materials and sections -------------------------------------------------------------------

def _sections(scene: Scene) -> dict[str, secmod.SectionProperties]:
    """Section properties per section name (SI: m², m⁴), with the Poisson ratio of the first
    member's material that uses the section (0 if none does) for the shear factor; a SceneError
    naming ``file:sections.NAME`` for dimensions whose properties leave floating point."""
    mats = scene.materials
    secs: dict[str, secmod.SectionProperties] = {}
    for name, spec in scene.sections.items():
        used_nu = [mats[m.material].nu for m in scene.members.values() if m.section == name]
        nu = used_nu[0] if used_nu else 0.0
        p = _section_properties(spec, nu)
        if p is None or not all(math.isfinite(x) and x > 0.0 for x in (p.area, p.i1, p.i2, p.torsion)):
            # r⁴ of r = 1e300 m overflows, of r = 1e-300 m underflows to 0 (then divides by zero)
            raise SceneError(f"{scene.source}:sections.{name}",
                             f"the {spec.shape} {list(spec.dims)} m has no positive, finite area, second moments "
                             f"and torsion constant in double precision; expected the dimensions of a real section")
        secs[name] = secmod.with_overrides(p, spec.torsion_constant, spec.shear_factor)
    return secs


def _section_properties(spec, nu: float) -> secmod.SectionProperties | None:
    """The computed properties of a section spec, None when they overflow or divide by zero (the
    caller checks them finite: numpy's overflow is no warning printed to the user)."""
    make = {"rectangle": secmod.rectangle, "circle": secmod.circle, "tube": secmod.tube}[spec.shape]
    try:
        with np.errstate(all="ignore"):
            return make(*spec.dims, nu)
    except ArithmeticError:
        return None


# -- prescribed DOFs and drives ---------------------------------------------------------------

@dataclass
class Prescribed:
    """``free (nfree,)`` ids of the free DOFs, ``free_index (ndof,)`` DOF → row among them (−1:
    prescribed), ``drives`` the prescribed motions (None: no driven support). All read-only."""

    free: np.ndarray
    free_index: np.ndarray
    drives: Drives | None


def _prescribed(scene: Scene, dofs: DofTable) -> Prescribed:
    """Prescribed DOFs of the supports (shell edges, then nodes in scene order) and the drives of
    the driven ones; a SceneError naming ``file:supports[i].axis`` for a revolute axis that is no
    section vector, or the shells' edge-support errors."""
    fixed = np.zeros(dofs.ndof, dtype=bool)
    drive_rows: list[tuple] = []
    drive_vectors: list[tuple] = []
    for ids in edge_support_dofs(scene, dofs.shells):
        fixed[ids] = True
    for i, s in enumerate(scene.supports):
        if s.edge is None:
            _node_support(scene, s, f"{scene.source}:supports[{i}]", dofs, fixed, drive_rows, drive_vectors)
    free = np.nonzero(~fixed)[0].astype(np.int64)
    free_index = np.full(dofs.ndof, -1, dtype=np.int64)
    free_index[free] = np.arange(free.size)
    _freeze(free, free_index)
    return Prescribed(free, free_index, _drives(drive_rows, drive_vectors))


def _node_support(scene: Scene, s, where: str, dofs: DofTable, fixed: np.ndarray, drive_rows: list,
                  drive_vectors: list) -> None:
    """Mark the DOFs support ``s`` (at a node; ``file:supports[i]`` for errors) prescribes in
    ``fixed (ndof,)``; a driven support appends (position ids (3,), Y⁰ (m), direction, distance
    signal, axis, angle signal) to ``drive_rows`` and, per frame section vector it turns, (ids (3,),
    V⁰, drive row) to ``drive_vectors``."""
    n = dofs.node_lookup[s.node]
    node_ydofs = dofs.node_ydofs
    if s.type == "clamp" and s.member is None:      # a member's clamp leaves a hinged shell free
        for ids in clamp_node_gdofs(dofs.shells, n):
            fixed[ids] = True
    if s.type in ("clamp", "ball", "driven"):
        fixed[node_ydofs[n]] = True
    if s.type == "roller":                          # the position along the axis 'normal' only
        fixed[node_ydofs[n][int(np.argmax(np.abs(s.normal)))]] = True
    if s.type == "driven":
        drive_rows.append((node_ydofs[n], np.asarray(dofs.node_x[n], dtype=float),   # a shell point too
                           s.direction or (0.0, 0.0, 0.0), s.distance, s.axis or (0.0, 0.0, 1.0), s.angle))
    if s.type == "revolute":
        fixed[node_ydofs[n]] = True
        mi = dofs.member_infos[dofs.member_lookup[s.member]]
        k = int(np.nonzero(mi.nodes == n)[0][0])
        _, _, v1, v2 = dofs.member_geom[s.member]
        off = _axis_offset(f"{where}.axis", s.member, s.node, v1[k], v2[k], np.asarray(s.axis))
        fixed[mi.vdofs[k, off:off + 3]] = True
    if s.type in ("clamp", "fixed_vector", "driven"):
        for mi in dofs.member_infos:
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
                            drive_vectors.append((ids, dofs.q0[ids[0]:ids[0] + 3], len(drive_rows) - 1))
                else:
                    off = 0 if s.vector == "v1" else 3
                    fixed[mi.vdofs[k, off:off + 3]] = True


def _drives(drive_rows: list[tuple], drive_vectors: list[tuple]) -> Drives | None:
    """The driven supports as arrays (:class:`Drives`), None when there is none."""
    if not drive_rows:
        return None
    drives = Drives(np.array([r[0] for r in drive_rows], dtype=np.int64), np.array([r[1] for r in drive_rows]),
                    np.array([r[2] for r in drive_rows], dtype=float), tuple(r[3] for r in drive_rows),
                    np.array([r[4] for r in drive_rows], dtype=float), tuple(r[5] for r in drive_rows),
                    np.array([v[0] for v in drive_vectors], dtype=np.int64).reshape(-1, 3),
                    np.array([v[1] for v in drive_vectors], dtype=float).reshape(-1, 3),
                    np.array([v[2] for v in drive_vectors], dtype=np.int64))
    _freeze(drives.y_ids, drives.y0, drives.direction, drives.axis, drives.v_ids, drives.v0, drives.v_drive)
    return drives


# -- actuators --------------------------------------------------------------------------------

def _actuators(scene: Scene, dofs: DofTable) -> tuple[Actuators, dict[str, int]]:
    """The actuator members in scene order: :class:`Actuators` (reference length l0 (m), command
    signals, stroke (na, 2) (m, [0, inf] when undeclared), end position ids (na, 6), servos) and
    the lookup actuator name → actuator id."""
    act_names = [m.name for m in scene.members.values() if m.kind == "actuator"]
    act_lookup = {n: i for i, n in enumerate(act_names)}
    infos = [dofs.member_infos[dofs.member_lookup[n]] for n in act_names]
    act_l0 = np.array([mi.length for mi in infos], dtype=float)
    act_cmd = tuple(scene.members[n].actuator.command for n in act_names)
    act_stroke = np.array([scene.members[n].actuator.stroke or (0.0, math.inf) for n in act_names],
                          dtype=float).reshape(-1, 2)
    act_ends = np.array([np.concatenate((mi.ydofs[0], mi.ydofs[-1])) for mi in infos],
                        dtype=np.int64).reshape(-1, 6)
    actuators = Actuators(tuple(act_names), np.array([dofs.member_lookup[n] for n in act_names], dtype=np.int64),
                          act_l0, act_cmd, act_stroke, act_ends, _servo_params(scene, act_names, act_stroke))
    _freeze(act_l0, act_stroke, act_ends, actuators.member)
    return actuators, act_lookup


def _command_program(scene: Scene, act_lookup: dict[str, int], act_l0: np.ndarray) -> tuple[object | None, np.ndarray]:
    """The scene's command program (:func:`flexmb_core.commands.build_program`) and the actuator
    ids it commands; (None, empty) without one."""
    if scene.commands is None:
        return None, np.zeros(0, dtype=np.int64)
    from ..commands import build_program
    program_index = np.array([act_lookup[a] for a in scene.commands.actuators], dtype=np.int64)
    return build_program(scene.commands, act_l0[program_index], f"{scene.source}:commands"), program_index


# -- elements ---------------------------------------------------------------------------------

@dataclass
class ElementBlocks:
    """Element data per member before the pattern exists.

    ``frames``: (order, n_axial, n_section_points) → lists per member of ``edofs (ne, 9n)``,
    ``dax, dsec (ne, nip, 3n, 3)``, ``w (ne, nip)`` (m³), ``mat (ne, 7)``, ``act, member (ne,)``;
    ``truss``: lists per bar of ``edofs (6,)``, ``l0`` (m), ``ea`` (N), ``tau`` (s), ``act``,
    ``member``; ``mass_rows, mass_cols, mass_vals``: the element and point masses as (DOF, DOF,
    kg or kg·m²) entries, one array each per block (duplicates add).
    """

    frames: dict[tuple[int, int, int], dict[str, list]] = field(default_factory=dict)
    truss: dict[str, list] = field(default_factory=lambda: defaultdict(list))
    mass_rows: list[np.ndarray] = field(default_factory=list)
    mass_cols: list[np.ndarray] = field(default_factory=list)
    mass_vals: list[np.ndarray] = field(default_factory=list)


def _element_blocks(scene: Scene, dofs: DofTable, secs: dict[str, secmod.SectionProperties],
                    act_lookup: dict[str, int]) -> ElementBlocks:
    """Every member's elements (frame blocks or bars) with their mass, then the point masses; a
    SceneError naming ``file:members.NAME`` for a degenerate frame element."""
    blocks = ElementBlocks()
    for mi_id, mem in enumerate(scene.members.values()):
        info = dofs.member_infos[mi_id]
        act = act_lookup.get(mem.name, -1)
        if info.vdofs[0, 0] >= 0:
            _frame_block(scene, mem, mi_id, info, dofs.member_geom[mem.name], secs[mem.section], act, blocks)
        else:
            _bars(scene, mem, mi_id, info, dofs.member_geom[mem.name], secs[mem.section], act, blocks)
    for pm in scene.point_masses:
        d = dofs.node_ydofs[dofs.node_lookup[pm.node]]
        blocks.mass_rows.append(d)
        blocks.mass_cols.append(d)
        blocks.mass_vals.append(np.full(3, pm.mass))
    return blocks


def _frame_block(scene: Scene, mem: Member, mi_id: int, info: MemberInfo, geom: tuple,
                 sec: secmod.SectionProperties, act: int, blocks: ElementBlocks) -> None:
    """All elements of a frame member at once (one numba call: a 10⁵-element scene compiles in
    seconds) into ``blocks.frames`` under its (order, axial rule, section rule), and their
    consistent mass (exact rule) into the mass entries."""
    mat = scene.materials[mem.material]
    x, _, v1, v2 = geom
    # Reduced rule (p Gauss points) is free of shear and membrane locking: thin members
    # bent into arcs converge with few elements; "full" (p + 2) is kept for comparison.
    n_axial = mem.order if mem.integration == "reduced" else mem.order + 2
    key = (mem.order, n_axial, sec.points.shape[0])
    row = np.array([mat.E, mat.E, mat.G, mat.G, sec.torsion / sec.polar, sec.shear_factor,
                    mat.eta / mat.E])
    iscale = _inertia_scale(mem, mat, sec)
    ne = mem.elements
    where = f"{scene.source}:members.{mem.name}"
    dax, dsec, w, _ = _member_geometry(where, x, v1, v2, mem.order, n_axial, sec.points, ne)
    # The mass needs an exact rule whatever the stiffness rule: φℓφm has degree 2p.
    _, _, w_m, psi = _member_geometry(where, x, v1, v2, mem.order, mem.order + 1, sec.points, ne,
                                      mass_only=True)
    node_dofs = np.concatenate((info.ydofs, info.vdofs), axis=1)          # (nodes, 9)
    local = np.arange(ne)[:, None] * mem.order + np.arange(mem.order + 1)[None, :]
    edofs = node_dofs[local].reshape(ne, -1)                                 # (ne, 9n)
    b = blocks.frames.setdefault(key, defaultdict(list))
    b["edofs"].append(edofs)
    b["dax"].append(dax)
    b["dsec"].append(dsec)
    b["w"].append(w)
    b["mat"].append(np.tile(row, (ne, 1)))
    b["act"].append(np.full(ne, act, dtype=np.int64))
    b["member"].append(np.full(ne, mi_id, dtype=np.int64))
    me = frame_member_mass(psi, w_m, mat.rho, iscale)
    k9 = edofs.shape[1]
    blocks.mass_rows.append(np.repeat(edofs, k9, axis=1).ravel())
    blocks.mass_cols.append(np.tile(edofs, (1, k9)).ravel())
    blocks.mass_vals.append(me.ravel())


def _inertia_scale(mem: Member, mat, sec: secmod.SectionProperties) -> np.ndarray | None:
    """Per-node factors ``(3 (order + 1),)`` [translation, rotary about V1, about V2] that turn
    the section's own mass into the member's declared ``mass`` override; None without one."""
    if mem.mass is None:
        return None
    iscale = np.ones(3)
    if mem.mass.per_length is not None:
        iscale[0] = mem.mass.per_length / (mat.rho * sec.area)
    if mem.mass.rotary_inertia is not None:
        iscale[1] = mem.mass.rotary_inertia[0] / (mat.rho * sec.i1)
        iscale[2] = mem.mass.rotary_inertia[1] / (mat.rho * sec.i2)
    return np.tile(iscale, mem.order + 1)


def _bars(scene: Scene, mem: Member, mi_id: int, info: MemberInfo, geom: tuple, sec: secmod.SectionProperties,
          act: int, blocks: ElementBlocks) -> None:
    """The 2-node bars of a truss or bar-actuator member into ``blocks.truss``, with their
    consistent mass (ρA l0 / 6 · [[2, 1], [1, 2]] ⊗ I₃, kg)."""
    mat = scene.materials[mem.material]
    x = geom[0]
    ea = mat.E * sec.area
    rho_a = mem.mass.per_length if (mem.mass and mem.mass.per_length) else mat.rho * sec.area
    truss = blocks.truss
    for e in range(mem.elements):
        edofs = np.concatenate((info.ydofs[e], info.ydofs[e + 1]))
        l0 = float(np.linalg.norm(x[e + 1] - x[e]))
        truss["edofs"].append(edofs)
        truss["l0"].append(l0)
        truss["ea"].append(ea)
        truss["tau"].append(mat.eta / mat.E)
        truss["act"].append(act)
        truss["member"].append(mi_id)
        me = rho_a * l0 / 6.0 * np.kron(np.array([[2.0, 1.0], [1.0, 2.0]]), np.eye(3))
        blocks.mass_rows.append(np.repeat(edofs, 6))
        blocks.mass_cols.append(np.tile(edofs, 6))
        blocks.mass_vals.append(me.ravel())


def _frame_groups(frames: dict[tuple[int, int, int], dict[str, list]], pattern: Pattern) -> list[FrameGroup]:
    """One read-only :class:`FrameGroup` per (order, axial rule, section rule), in key order, with
    its scatter maps ``(ne, (9n)²)``; each block is cleared once copied into its group."""
    groups = []
    for (order, _, nsec), b in sorted(frames.items()):
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
    return groups


def _truss_group(truss: dict[str, list], pattern: Pattern) -> TrussGroup | None:
    """The bars as one read-only :class:`TrussGroup` with scatter maps ``(ne, 36)``; None if none."""
    if not truss:
        return None
    edofs = np.asarray(truss["edofs"], dtype=np.int64)
    group = TrussGroup(edofs, np.asarray(truss["l0"], dtype=float), np.asarray(truss["ea"], dtype=float),
                       np.asarray(truss["act"], dtype=np.int64),
                       np.ascontiguousarray([pattern.map(ed) for ed in edofs], dtype=np.int64),
                       np.asarray(truss["member"], dtype=np.int64), np.asarray(truss["tau"], dtype=float))
    _freeze(group.edofs, group.l0, group.ea, group.act, group.smap, group.member, group.tau)
    return group


def _check_outputs(scene: Scene, dofs: DofTable) -> None:
    """A SceneError naming ``file:outputs.NAME.at`` for a shell-point output at no mesh node, and
    ``file:outputs.NAME.nodes`` for a platform pose whose three nodes span no triangle (its frame,
    and the pose, would be NaN)."""
    for out in scene.outputs:
        if out.kind == "shell_point":
            shell_point_node(next(i for i in dofs.shells if i.name == out.shell), out.at,
                             f"{scene.source}:outputs.{out.name}.at", out.edge and out.edge[1])
        elif out.kind == "platform_pose" and all(n in dofs.node_lookup for n in out.nodes):
            p = np.array([dofs.q0_array[dofs.node_ydofs[dofs.node_lookup[n]]] for n in out.nodes])
            area2 = float(np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0])))
            span = max(float(np.linalg.norm(p[i] - p[j])) for i, j in ((0, 1), (0, 2), (1, 2)))
            if not area2 > 1e-9 * span * span:
                raise SceneError(f"{scene.source}:outputs.{out.name}.nodes",
                                 f"nodes {list(out.nodes)} at {p.tolist()} m span no triangle (coincident or "
                                 "collinear); expected three nodes of the platform that do")


# -- sparsity ---------------------------------------------------------------------------------

def _sparsity(blocks: ElementBlocks, dofs: DofTable, cons: Constraints, free_index: np.ndarray) -> Pattern:
    """The pattern over the system (free DOFs, then multipliers): every frame, bar and shell
    element block and every constraint block. The mass adds no pair: every mass entry lies in the
    block of an element (frames, bars, shells) or on the diagonal of a node that has one."""
    parts = [free_index[ed] for b in blocks.frames.values() for ed in b["edofs"]]
    if blocks.truss:
        parts.append(free_index[np.asarray(blocks.truss["edofs"], dtype=np.int64)])
    parts += [free_index[ed][None, :] for ed in shell_element_pairs(dofs.shells)]
    parts += [idx[None, :] for idx in cons.system_blocks()]
    return Pattern.from_blocks(parts, cons.nsys, free_index)


# -- mass -------------------------------------------------------------------------------------

@dataclass
class Mass:
    """The constant mass: ``full`` (ndof, ndof) CSR (kg, kg·m² on vectors), ``csr`` its read-only
    (indptr, indices, data), ``kdata (nnz,)`` its free–free part on the tangent pattern,
    ``u_trans (ndof, 3)`` the rigid translations and ``total`` the total mass (kg)."""

    full: sp.csr_matrix
    csr: tuple[np.ndarray, np.ndarray, np.ndarray]
    kdata: np.ndarray
    u_trans: np.ndarray
    total: float


def _mass(blocks: ElementBlocks, dofs: DofTable, pattern: Pattern) -> Mass:
    """Assemble the mass entries of ``blocks`` (its lists are emptied: a 10⁴-element frame scene
    holds ~10⁸ bytes per copy of them) into the full CSR mass and its free–free part."""
    ndof, nsys, keys, free_index = dofs.ndof, pattern.nsys, pattern.keys, pattern.free_index
    mr, mc, mv = np.concatenate(blocks.mass_rows), np.concatenate(blocks.mass_cols), np.concatenate(blocks.mass_vals)
    mfull = sp.csr_matrix((mv, (mr, mc)), shape=(ndof, ndof))
    mfull.sum_duplicates()
    mfull.sort_indices()
    fr, fc = free_index[mr], free_index[mc]
    ok = (fr >= 0) & (fc >= 0)
    kdata = np.zeros(keys.size)
    mkeys = fr[ok] * nsys + fc[ok]
    pos = np.minimum(np.searchsorted(keys, mkeys), keys.size - 1)
    if not np.array_equal(keys[pos], mkeys):      # the pattern holds every mass entry (see _sparsity)
        raise AssertionError("compile_scene: a mass entry outside the element blocks' sparsity pattern")
    np.add.at(kdata, pos, mv[ok])
    # free the per-entry temporaries before the rest is built
    for entries in (blocks.mass_rows, blocks.mass_cols, blocks.mass_vals):
        entries.clear()
    del mr, mc, mv, fr, fc, ok, mkeys, pos
    u_trans = np.zeros((ndof, 3))
    u_trans[dofs.node_ydofs, np.arange(3)] = 1.0
    total = float((mfull @ u_trans)[:, 0].sum())
    csr = (mfull.indptr.astype(np.int64), mfull.indices.astype(np.int64), mfull.data.astype(float))
    _freeze(kdata, *csr)
    return Mass(mfull, csr, kdata, u_trans, total)


# -- loads ------------------------------------------------------------------------------------

@dataclass
class Loads:
    """``vectors (nl, ndof)`` nodal force patterns (N) with their ``signals``; ``gravity_vector
    (ndof,)`` = M · u_g (N) and its signal; ``moments`` through section vectors and directors."""

    vectors: np.ndarray
    signals: tuple[Signal, ...]
    gravity_vector: np.ndarray
    gravity_signal: Signal
    moments: MomentLoads


def _loads(scene: Scene, dofs: DofTable, pattern: Pattern, mass: Mass) -> Loads:
    """Node forces, then shell edge forces, as load patterns; gravity through the mass; member
    and shell edge moments (a SceneError for a drilling edge moment)."""
    edge_patterns, edge_signals, edge_moments = edge_load_patterns(scene, dofs.shells, dofs.ndof)
    vectors = np.zeros((len(scene.forces) + len(edge_patterns), dofs.ndof))
    for i, f in enumerate(scene.forces):
        vectors[i, dofs.node_ydofs[dofs.node_lookup[f.node]]] = f.force
    for i, p in enumerate(edge_patterns):
        vectors[len(scene.forces) + i] = p
    gravity_vector = np.zeros(dofs.ndof)
    gravity_signal = Signal()
    if scene.gravity is not None:
        gravity_vector = mass.full @ (mass.u_trans @ np.asarray(scene.gravity.acceleration, dtype=float))
        gravity_signal = scene.gravity.signal
    moments = _moment_loads(scene, dofs.member_infos, dofs.member_lookup, dofs.member_geom, dofs.node_lookup,
                            pattern.map, edge_moments)
    _freeze(vectors, gravity_vector)
    return Loads(vectors, tuple(f.signal for f in scene.forces) + tuple(edge_signals), gravity_vector,
                 gravity_signal, moments)


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
