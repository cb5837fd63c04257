"""DOF numbering, the first stage of :func:`flexmb_core.model.compile.compile_scene`: scene nodes,
member interior nodes, shell mesh nodes → global nodes; positions (3 per node) and section vectors
(6 per frame node) and shell unknowns → DOF ids; joints merge DOFs (union–find) and the vector is
compacted. The result is a :class:`DofTable`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import SceneError, excerpt, name_list, thousands
from ..scene.schema import Member, Scene
from .model import MemberInfo, ShellInfo
from .shell_compile import ShellDraft, compact_drafts, number_shell_nodes, shell_infos


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


@dataclass
class DofTable:
    """Global nodes and DOFs of a scene, filled by :func:`number_dofs`.

    While numbering: ``node_names``, ``node_x`` (3,) positions (m), ``node_lookup`` name → node id
    (shell points included), ``ydof`` node → first position DOF (−1: none yet), ``q0`` reference
    values and ``scale_kind`` (0 position, 1 vector or scalar) per DOF, ``ndof``;
    ``member_infos`` in scene order and ``member_geom`` name → (x, t, v1, v2) each ``(m, 3)``
    (:func:`member_geometry`); ``drafts`` the shells; ``corners`` (member a, member b, node) of
    rigid joints held by multipliers and ``hinges`` (a, b, node, axis) of off-plane revolute joints.

    Set by :meth:`finish`: ``q0_array (ndof,)``, ``dof_scale (ndof,)`` (m for positions, 1 for
    vectors), ``node_ydofs (nnodes, 3)``, ``member_lookup`` name → member id, ``shells``.
    """

    node_names: list[str]
    node_x: list[np.ndarray]
    node_lookup: dict[str, int]
    ydof: list[int]
    q0: list[float] = field(default_factory=list)
    scale_kind: list[int] = field(default_factory=list)
    ndof: int = 0
    member_infos: list[MemberInfo] = field(default_factory=list)
    member_geom: dict[str, tuple] = field(default_factory=dict)
    drafts: list[ShellDraft] = field(default_factory=list)
    corners: list[tuple[str, str, str]] = field(default_factory=list)
    hinges: list[tuple[str, str, str, tuple]] = field(default_factory=list)
    q0_array: np.ndarray | None = None
    dof_scale: np.ndarray | None = None
    node_ydofs: np.ndarray | None = None
    member_lookup: dict[str, int] = field(default_factory=dict)
    shells: tuple[ShellInfo, ...] = ()

    @classmethod
    def of_scene_nodes(cls, scene: Scene) -> DofTable:
        """A table holding the scene's named nodes, none of them numbered yet."""
        names = list(scene.nodes)
        return cls(names, [np.asarray(scene.nodes[n], dtype=float) for n in names],
                   {n: i for i, n in enumerate(names)}, [-1] * len(names))

    def take(self, values, kind) -> int:
        """Append reference values (their kind: 0 position, 1 vector; one for all or one each);
        returns the first new DOF id."""
        start = self.ndof
        values = np.asarray(values, dtype=float).ravel()
        self.q0.extend(values.tolist())
        self.scale_kind.extend(np.broadcast_to(np.asarray(kind), values.shape).tolist())
        self.ndof += values.size
        return start

    def add_nodes(self, names: list[str], x: np.ndarray) -> int:
        """Register new (unnumbered) nodes ``names`` at ``x (k, 3)`` (m); returns the first id."""
        first = len(self.node_names)
        self.node_lookup.update(zip(names, range(first, first + len(names))))
        self.node_names.extend(names)
        self.node_x.extend(x)
        self.ydof.extend([-1] * len(names))
        return first

    def compact(self, remap: np.ndarray) -> None:
        """Merge DOFs by ``remap (ndof,)`` (each DOF → the DOF it merges into) and renumber the kept
        ones consecutively, in every id this table holds."""
        keep = np.unique(remap)
        self.q0 = [self.q0[i] for i in keep]
        self.scale_kind = [self.scale_kind[i] for i in keep]
        self.ndof = keep.size
        compact = np.searchsorted(keep, remap)
        self.ydof = [int(compact[y]) if y >= 0 else -1 for y in self.ydof]
        self.member_infos = [MemberInfo(mi.name, mi.kind, mi.nodes, compact[mi.ydofs],
                                        np.where(mi.vdofs >= 0, compact[np.maximum(mi.vdofs, 0)], -1), mi.length)
                             for mi in self.member_infos]
        compact_drafts(self.drafts, compact)

    def finish(self) -> None:
        """The arrays of a numbered table: q0, the convergence scale (positions by the model's
        characteristic length, m), node → position ids, member lookup, shell infos."""
        self.q0_array = np.asarray(self.q0, dtype=float)
        nodes_xyz = np.asarray(self.node_x)
        l_char = max(float(np.linalg.norm(nodes_xyz.max(0) - nodes_xyz.min(0))),
                     max((mi.length for mi in self.member_infos), default=0.0))
        self.dof_scale = np.where(np.asarray(self.scale_kind) == 0, l_char, 1.0)
        self.node_ydofs = np.asarray(self.ydof, dtype=np.int64)[:, None] + np.arange(3)
        self.member_lookup = {mi.name: i for i, mi in enumerate(self.member_infos)}
        self.shells = shell_infos(self.drafts, self.node_ydofs)
        for a in (self.q0_array, self.dof_scale, self.node_ydofs):
            a.setflags(write=False)


def number_dofs(scene: Scene) -> DofTable:
    """Stage 1 of the compile: number every node and DOF of ``scene`` (members in scene order,
    then shells), merge the DOFs joints share, and refuse nodes nothing uses.

    Returns a finished :class:`DofTable`; a :class:`SceneError` naming ``file:key`` for a ``via``
    node off the element boundaries, a generated node name taken by a scene node, a curved actuator,
    a shell or joint the geometry refuses, or unused scene nodes.
    """
    table = DofTable.of_scene_nodes(scene)
    for mem in scene.members.values():
        _number_member(scene, mem, table)
    table.drafts = number_shell_nodes(scene, table.node_lookup, table.node_names, table.node_x, table.ydof,
                                      {mi.name: mi.nodes for mi in table.member_infos}, table.take)
    if scene.joints:
        table.compact(_joint_dof_map(scene, table.ndof, table.member_infos, table.member_geom, table.node_lookup,
                                     table.corners, table.hinges))
    unused = [n for i, n in enumerate(scene.nodes) if table.ydof[i] < 0]
    if unused:
        raise SceneError(f"{scene.source}:nodes", f"node(s) {name_list(unused)} are not used by any member or shell "
                                                  f"({thousands(len(unused))} in all)")
    table.finish()
    return table


def _number_member(scene: Scene, mem: Member, table: DofTable) -> None:
    """Nodes and DOFs of one member: its end (and ``via``) scene nodes, new interior nodes named
    ``member/k``, then :func:`_number_member_dofs`; appends its :class:`MemberInfo` and geometry."""
    x, t, v1, v2 = member_geometry(mem, scene.nodes, scene.source)
    table.member_geom[mem.name] = (x, t, v1, v2)
    node_lookup = table.node_lookup
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
    first = table.add_nodes(names, x[interior])
    ids[interior] = np.arange(first, first + len(names))
    is_frame = mem.kind == "frame" or (mem.kind == "actuator" and mem.actuator.variant == "frame")
    yd, vd = _number_member_dofs(ids, table.ydof, table.node_x, x, v1, v2, is_frame, table.take)
    if mem.kind == "actuator" and mem.arc_center is not None:
        raise SceneError(f"{scene.source}:members.{mem.name}.arc", "actuators must be straight (no 'arc')")
    table.member_infos.append(MemberInfo(mem.name, mem.kind, ids, yd, vd, member_length(x)))


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


def _axis_offset(where: str, member: str, node: str, v1: np.ndarray, v2: np.ndarray, axis: np.ndarray) -> int:
    """0 if V1 lies on ``axis``, 3 if V2 does (same sense); otherwise a SceneError with a hint."""
    for off, v in ((0, v1), (3, v2)):
        if v @ axis > 1.0 - 1e-9:
            return off
    raise SceneError(where, f"member '{member}' has no section vector along the axis {axis.tolist()} at node "
                            f"'{node}' (V1 = {np.round(v1, 6).tolist()}, V2 = {np.round(v2, 6).tolist()}); "
                            "set the member's 'up' to the axis so that V2 lies on it")


def _find(parent: np.ndarray, i: int) -> int:
    """Union–find root of ``i`` in ``parent (ndof,)``, halving the path on the way (in place)."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


def _joint_dof_map(scene: Scene, ndof: int, member_infos, member_geom, node_lookup, corners: list,
                   hinges: list) -> np.ndarray:
    """For every DOF, the DOF it is merged into by the scene's joints (union–find roots).

    Rigid joints between members with different section frames cannot be expressed by sharing;
    they are appended to ``corners`` as (member a, member b, node) for Lagrange multipliers;
    revolute joints whose axis is not a section vector of every member go to ``hinges``.
    """
    parent = np.arange(ndof)
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
                parent[_find(parent, int(b))] = _find(parent, int(a))
    return np.array([_find(parent, i) for i in range(ndof)], dtype=np.int64)
