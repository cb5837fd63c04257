"""Pure observer functions: (model, state) → the values a scene declares as outputs.

The ROS node and the recorders publish exactly these; ``flexmb run`` writes their final values.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .jit import KERNEL
from .model.assembly import actuator_dudlam
from .model.model import Model
from .model.shell_compile import shell_point_node
from .model.workspace import State, Workspace
from .scene.schema import Output


@njit(**KERNEL)
def _actuator_kinematics(q, v, end_ydofs, lengths, rates):
    """End-to-end length (m) and its rate (m/s) of every actuator, into ``lengths, rates (na,)``;
    ``end_ydofs (na, 6)`` the ids of the two end positions."""
    for i in range(end_ydofs.shape[0]):
        s = 0.0
        w = 0.0
        for k in range(3):
            d = q[end_ydofs[i, k + 3]] - q[end_ydofs[i, k]]
            s += d * d
            w += d * (v[end_ydofs[i, k + 3]] - v[end_ydofs[i, k]])
        length = np.sqrt(s)
        lengths[i] = length
        rates[i] = w / length


def actuator_kinematics(model: Model, q: np.ndarray, v: np.ndarray, lengths: np.ndarray,
                        rates: np.ndarray) -> None:
    """Length (m) and rate (m/s) of every actuator into ``lengths, rates (na,)`` (one call, no
    temporaries: the node reports them at every step that answers a command)."""
    _actuator_kinematics(q, v, model.actuators.end_ydofs, lengths, rates)


def actuator_lengths(model: Model, q: np.ndarray) -> np.ndarray:
    """Current end-to-end length of every actuator (m), shape (na,)."""
    lengths = np.zeros(model.actuators.l0.size)
    actuator_kinematics(model, q, np.zeros_like(q), lengths, np.zeros_like(lengths))
    return lengths


def actuator_forces(model: Model, ws: Workspace, state: State) -> np.ndarray:
    """Axial force of every actuator (N, tension positive): the work conjugate of the commanded
    length, ``N = −∂(U + D)/∂L_cmd``, elastic plus the viscous (Kelvin–Voigt) part of damped
    materials."""
    return -actuator_dudlam(model, ws, state.q, state.lam, v=state.v, lam_rate=state.lam_rate) / model.actuators.l0


def _triangle_frame(p: np.ndarray) -> np.ndarray:
    """Orthonormal frame (columns) of a triangle p (3, 3): x along p1→p2, z its normal."""
    ex = p[2] - p[1]
    ex = ex / np.linalg.norm(ex)
    ez = np.cross(p[1] - p[0], p[2] - p[0])
    ez = ez / np.linalg.norm(ez)
    return np.column_stack((ex, np.cross(ez, ex), ez))


@njit(cache=True)
def _pose_kernel(q, ids, frame0, pos, quat):  # pragma: no cover - numba
    """Centroid ``pos (3,)`` and quaternion ``quat (4,)`` (w ≥ 0) of the triangle ``q[ids]`` (3, 3),
    relative to its reference frame ``frame0`` (3, 3) (columns ex, ey, ez)."""
    p = np.empty((3, 3))
    for i in range(3):
        for k in range(3):
            p[i, k] = q[ids[i, k]]
    for k in range(3):
        pos[k] = (p[0, k] + p[1, k] + p[2, k]) / 3.0
    ex = p[2] - p[1]
    ex /= np.sqrt(ex @ ex)
    ez = np.cross(p[1] - p[0], p[2] - p[0])
    ez /= np.sqrt(ez @ ez)
    ey = np.cross(ez, ex)
    frame = np.empty((3, 3))
    frame[:, 0], frame[:, 1], frame[:, 2] = ex, ey, ez
    rot = frame @ frame0.T
    tr = rot[0, 0] + rot[1, 1] + rot[2, 2]
    if tr > 0.0:
        w = 2.0 * np.sqrt(tr + 1.0)
        quat[0] = 0.25 * w
        quat[1] = (rot[2, 1] - rot[1, 2]) / w
        quat[2] = (rot[0, 2] - rot[2, 0]) / w
        quat[3] = (rot[1, 0] - rot[0, 1]) / w
    else:
        i = 0
        if rot[1, 1] > rot[i, i]:
            i = 1
        if rot[2, 2] > rot[i, i]:
            i = 2
        j, k = (i + 1) % 3, (i + 2) % 3
        w = 2.0 * np.sqrt(1.0 + rot[i, i] - rot[j, j] - rot[k, k])
        quat[0] = (rot[k, j] - rot[j, k]) / w
        quat[1 + i] = 0.25 * w
        quat[1 + j] = (rot[j, i] + rot[i, j]) / w
        quat[1 + k] = (rot[k, i] + rot[i, k]) / w
    quat /= np.sqrt(quat @ quat)
    if quat[0] < 0.0:
        quat *= -1.0


class PlatformObserver:
    """:func:`platform_pose` with the node ids and the reference frame computed once: a few µs
    per call (what the node and ``flexmb run``'s tracking call every step)."""

    def __init__(self, model: Model, nodes: tuple[str, ...]):
        self.ids = np.ascontiguousarray([model.node_ydofs[model.node(n)] for n in nodes], dtype=np.int64)
        self.frame0 = np.ascontiguousarray(_triangle_frame(model.q0[self.ids]))

    def __call__(self, q: np.ndarray, pos: np.ndarray, quat: np.ndarray) -> None:
        _pose_kernel(q, self.ids, self.frame0, pos, quat)


def platform_pose(model: Model, q: np.ndarray, nodes: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Centroid (m) and orientation (w, x, y, z) of a platform given by three of its nodes.

    The orientation is the rotation taking the triangle's reference frame to its current frame
    (identity at t = 0), so a rigid platform's pose is recovered exactly.
    """
    pos, quat = np.empty(3), np.empty(4)
    PlatformObserver(model, tuple(nodes))(q, pos, quat)
    return pos, quat


def actuator_velocities(model: Model, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rate of change of every actuator's end-to-end length (m/s), shape (na,)."""
    rates = np.zeros(model.actuators.l0.size)
    actuator_kinematics(model, q, v, np.zeros_like(rates), rates)
    return rates


def _section_frame(model: Model, q: np.ndarray, member: str, node: str) -> tuple[np.ndarray, np.ndarray]:
    info = model.member(member)
    k = int(np.nonzero(info.nodes == model.node(node))[0][0])
    v = q[info.vdofs[k]]
    return v[:3], v[3:]


def joint_angle(model: Model, q: np.ndarray, node: str, members: tuple[str, ...]) -> float:
    """Rotation (rad) about a hinge at ``node``: of member b relative to member a, or of a single
    member relative to its reference orientation. The hinge axis is the section vector the members
    share (the one whose direction the joint keeps); the angle is that of the other vector."""
    a1, a2 = _section_frame(model, q, members[0], node)
    r1, r2 = _section_frame(model, model.q0, members[0], node)
    if len(members) == 2:
        b1, b2 = _section_frame(model, q, members[1], node)
        s1, s2 = _section_frame(model, model.q0, members[1], node)
        # axis: the vector of a that b shares (identical ids after the joint merge)
        shared_v2 = np.allclose(a2, b2) and not np.allclose(a1, b1)
        axis = a2 if shared_v2 else a1
        u_a, u_b = (a1, b1) if shared_v2 else (a2, b2)
        u_a0, u_b0 = (r1, s1) if shared_v2 else (r2, s2)
        axis0 = r2 if shared_v2 else r1
        cur = _signed_angle(u_a, u_b, axis)
        ref = _signed_angle(u_a0, u_b0, axis0)
        return float(cur - ref)
    # single member: the axis is the vector that kept its direction (fixed by a revolute support)
    use_v2 = np.allclose(a2 / np.linalg.norm(a2), r2 / np.linalg.norm(r2), atol=1e-6)
    axis = a2 if use_v2 else a1
    return float(_signed_angle(r1 if use_v2 else r2, a1 if use_v2 else a2, axis))


def _signed_angle(u: np.ndarray, w: np.ndarray, axis: np.ndarray) -> float:
    n = axis / np.linalg.norm(axis)
    u = u - (u @ n) * n
    w = w - (w @ n) * n
    return float(np.arctan2(np.cross(u, w) @ n, u @ w))


def evaluate_output(model: Model, ws: Workspace, state: State, out: Output, energy: dict | None = None):
    """Value of one declared output (float, list or dict; JSON-ready)."""
    q = state.q
    if out.kind in ("node_position", "node_displacement"):
        d = model.node_ydofs[model.node(out.node)]
        val = q[d] if out.kind == "node_position" else q[d] - model.q0[d]
        return val.tolist()
    if out.kind == "section_vectors":
        info = model.member(out.member)
        k = int(np.nonzero(info.nodes == model.node(out.node))[0][0])
        return q[info.vdofs[k]].reshape(2, 3).tolist()
    if out.kind == "member_shape":
        info = model.member(out.member)
        return q[info.ydofs].tolist()
    if out.kind == "shell_point":
        info = model.shell(out.shell)
        d = info.ydofs[shell_point_node(info, out.at, f"outputs.{out.name}", out.edge and out.edge[1])]
        return {"position": q[d].tolist(), "displacement": (q[d] - model.q0[d]).tolist()}
    if out.kind == "shell_shape":
        return q[model.shell(out.shell).ydofs].tolist()
    if out.kind == "energy":
        return dict(energy or {})
    if out.kind == "joint_angle":
        return joint_angle(model, q, out.node, out.nodes)
    if out.kind == "platform_pose":
        pos, quat = platform_pose(model, q, out.nodes)
        return {"position": pos.tolist(), "orientation_wxyz": quat.tolist()}
    i = model.actuators.names.index(out.actuator)
    if out.kind == "actuator_length":
        return float(actuator_lengths(model, q)[i])
    if out.kind == "actuator_velocity":
        return float(actuator_velocities(model, q, state.v)[i])
    if out.kind == "actuator_command":
        return float(state.lam[i] * model.actuators.l0[i])
    return float(actuator_forces(model, ws, state)[i])
