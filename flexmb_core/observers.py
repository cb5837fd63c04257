"""Pure observer functions: (model, state) → the values a scene declares as outputs.

The ROS node and the recorders publish exactly these; ``flexmb run`` writes their final values.
"""

from __future__ import annotations

import numpy as np

from .model.assembly import actuator_dudlam
from .model.model import Model
from .model.workspace import State, Workspace
from .scene.schema import Output


def actuator_lengths(model: Model, q: np.ndarray) -> np.ndarray:
    """Current end-to-end length of every actuator (m), shape (na,)."""
    e = model.actuators.end_ydofs
    return np.linalg.norm(q[e[:, 3:]] - q[e[:, :3]], axis=1)


def actuator_forces(model: Model, ws: Workspace, state: State) -> np.ndarray:
    """Axial force of every actuator (N, tension positive): the work conjugate of the commanded
    length, ``N = −∂U/∂L_cmd = −(∂U/∂λ)/L0``."""
    return -actuator_dudlam(model, ws, state.q, state.lam) / model.actuators.l0


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
    if out.kind == "energy":
        return dict(energy or {})
    i = model.actuators.names.index(out.actuator)
    if out.kind == "actuator_length":
        return float(actuator_lengths(model, q)[i])
    if out.kind == "actuator_command":
        return float(state.lam[i] * model.actuators.l0[i])
    return float(actuator_forces(model, ws, state)[i])
