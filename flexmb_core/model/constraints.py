"""Multiplier constraints, a compile stage of :func:`flexmb_core.model.compile.compile_scene`:
rigid corners and off-plane hinges between frame members (from the joints the DOF numbering could
not express by sharing DOFs) and shell–frame ties, each with its reference coefficients and system
ids (DOF rows among the free DOFs, then its own Lagrange multipliers)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..scene.schema import Scene
from .dof_numbering import DofTable, _unit
from .model import MemberInfo
from .pattern import Pattern


@dataclass
class Constraints:
    """Multiplier constraints, their multipliers numbered after the ``nfree`` free DOFs: 6 per
    rigid corner, then 2 per off-plane hinge, then 3 per shell–frame tie; ``nsys`` the system size.

    Per corner ``dofs (12,)`` [V1b, V2b, V1a, V2a], ``alpha (2, 3)``; per hinge ``dofs (12,)``
    [V1a, V2a, V1b, V2b], ``alpha (3,)``, ``beta (2, 3)``; per tie ``dofs (9,)`` [G, V1, V2],
    ``alpha (3,)``; each with its system ids ``*_sys`` (DOF rows, then its multipliers).
    """

    corner_dofs: list = field(default_factory=list)
    corner_alpha: list = field(default_factory=list)
    corner_sys: list = field(default_factory=list)
    hinge_dofs: list = field(default_factory=list)
    hinge_alpha: list = field(default_factory=list)
    hinge_beta: list = field(default_factory=list)
    hinge_sys: list = field(default_factory=list)
    tie_dofs: list = field(default_factory=list)
    tie_alpha: list = field(default_factory=list)
    tie_sys: list = field(default_factory=list)
    nsys: int = 0

    def system_blocks(self) -> list[np.ndarray]:
        """System ids of every constraint (corners, hinges, ties), for the sparsity pattern."""
        return self.corner_sys + self.hinge_sys + self.tie_sys

    def arrays(self, pattern: Pattern) -> dict[str, np.ndarray]:
        """Read-only corner (dofs, alpha, smap (·, 324)), hinge (dofs, alpha, beta, smap (·, 196))
        and tie (dofs, alpha, smap (·, 144)) arrays by :class:`Model` field name."""
        out = {"corner_dofs": np.asarray(self.corner_dofs, dtype=np.int64).reshape(-1, 12),
               "corner_alpha": np.asarray(self.corner_alpha, dtype=float).reshape(-1, 2, 3),
               "corner_smap": np.asarray([pattern.map_sys(idx) for idx in self.corner_sys],
                                         dtype=np.int64).reshape(-1, 324),
               "hinge_dofs": np.asarray(self.hinge_dofs, dtype=np.int64).reshape(-1, 12),
               "hinge_alpha": np.asarray(self.hinge_alpha, dtype=float).reshape(-1, 3),
               "hinge_beta": np.asarray(self.hinge_beta, dtype=float).reshape(-1, 2, 3),
               "hinge_smap": np.asarray([pattern.map_sys(idx) for idx in self.hinge_sys],
                                        dtype=np.int64).reshape(-1, 196),
               "tie_dofs": np.asarray(self.tie_dofs, dtype=np.int64).reshape(-1, 9),
               "tie_alpha": np.asarray(self.tie_alpha, dtype=float).reshape(-1, 3),
               "tie_smap": np.asarray([pattern.map_sys(idx) for idx in self.tie_sys], dtype=np.int64).reshape(-1, 144)}
        for a in out.values():
            a.setflags(write=False)
        return out


def build_constraints(scene: Scene, dofs: DofTable, free_index: np.ndarray, nfree: int) -> Constraints:
    """Rigid corners and off-plane hinges (from the joints, :attr:`DofTable.corners`/``hinges``)
    and shell–frame ties (``shell_rigid`` joints) with α from the reference geometry."""
    cons = Constraints()
    infos_by_name = {mi.name: mi for mi in dofs.member_infos}
    _rigid_corners(dofs, infos_by_name, free_index, nfree, cons)
    base = nfree + 6 * len(dofs.corners)
    _multiplier_hinges(dofs, infos_by_name, free_index, base, cons)
    cons.tie_dofs, cons.tie_alpha, cons.tie_sys = _shell_frame_ties(scene, dofs.shells, infos_by_name,
                                                                    dofs.member_geom, dofs.node_lookup, free_index,
                                                                    base + 2 * len(dofs.hinges))
    cons.nsys = base + 2 * len(dofs.hinges) + 3 * len(cons.tie_dofs)
    return cons


def _rigid_corners(dofs: DofTable, infos_by_name: dict[str, MemberInfo], free_index: np.ndarray, nfree: int,
                   cons: Constraints) -> None:
    """Rigid joints between members of different section frames: member b's (V1, V2) equal member
    a's frame (V1a, V2a, V1a × V2a) times α (2, 3) of the reference; 6 multipliers each."""
    for ci, (ma, mb, node) in enumerate(dofs.corners):
        n = dofs.node_lookup[node]
        ka = int(np.nonzero(infos_by_name[ma].nodes == n)[0][0])
        kb = int(np.nonzero(infos_by_name[mb].nodes == n)[0][0])
        _, _, v1a, v2a = dofs.member_geom[ma]
        _, _, v1b, v2b = dofs.member_geom[mb]
        w0 = np.array([v1a[ka], v2a[ka], np.cross(v1a[ka], v2a[ka])])
        cons.corner_alpha.append(np.array([w0 @ v1b[kb], w0 @ v2b[kb]]))
        ids = np.concatenate((infos_by_name[mb].vdofs[kb], infos_by_name[ma].vdofs[ka]))
        cons.corner_dofs.append(ids)
        cons.corner_sys.append(np.concatenate((free_index[ids], nfree + 6 * ci + np.arange(6))))


def _multiplier_hinges(dofs: DofTable, infos_by_name: dict[str, MemberInfo], free_index: np.ndarray, base: int,
                       cons: Constraints) -> None:
    """Revolute joints whose axis is no section vector of every member: the axis, fixed in
    member a's frame (α (3,)), stays normal to two vectors fixed in member b's frame (β (2, 3));
    2 multipliers each, numbered from ``base``."""
    for hi, (ma, mb, node, axis) in enumerate(dofs.hinges):
        n = dofs.node_lookup[node]
        ka = int(np.nonzero(infos_by_name[ma].nodes == n)[0][0])
        kb = int(np.nonzero(infos_by_name[mb].nodes == n)[0][0])
        _, _, v1a, v2a = dofs.member_geom[ma]
        _, _, v1b, v2b = dofs.member_geom[mb]
        axis = _unit(axis)
        wa = np.array([v1a[ka], v2a[ka], np.cross(v1a[ka], v2a[ka])])
        wb = np.array([v1b[kb], v2b[kb], np.cross(v1b[kb], v2b[kb])])
        seed = np.eye(3)[int(np.argmin(np.abs(axis)))]
        b1 = _unit(seed - (seed @ axis) * axis)
        b2 = np.cross(axis, b1)
        cons.hinge_alpha.append(wa @ axis)
        cons.hinge_beta.append(np.array([wb @ b1, wb @ b2]))
        ids = np.concatenate((infos_by_name[ma].vdofs[ka], infos_by_name[mb].vdofs[kb]))
        cons.hinge_dofs.append(ids)
        cons.hinge_sys.append(np.concatenate((free_index[ids], base + 2 * hi + np.arange(2))))


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
