"""What the twin reports after a step: one :class:`TwinSample`, filled by a :class:`TwinReporter`.

The ROS node, the MCAP recorder, ``flexmb run --mcap`` and ``flexmb replay`` all read the solver
through this one place, so a live run and an offline run of the same commands report the same
numbers. It is pure NumPy (no ROS): the adapters in ``flexmb_io`` and ``ros2_node`` turn a sample into messages.

What is reported is what the scene declares ("model only what a scene needs"):

- every actuator: length, rate, commanded length and axial force (``/joint_states`` position,
  velocity and effort);
- every ``joint_angle`` output: the passive joint's angle and its rate;
- every ``platform_pose`` output: position and orientation;
- every member's deformed polyline (node positions), for ``~/shape``;
- energies and the last step's solver health.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .model.model import Model
from .observers import PlatformObserver, actuator_forces, actuator_kinematics, joint_angle
from .simulator import Simulator

# Step for the central difference that gives a joint angle's rate along the velocity field
# (s; the angle is smooth, so the truncation error ~h² is far below the float noise).
_RATE_STEP = 1.0e-6


@dataclass
class PoseSample:
    """A platform pose: centroid (m) and orientation quaternion (w, x, y, z)."""

    name: str
    nodes: tuple[str, ...]
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    orientation_wxyz: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))


@dataclass
class TwinSample:
    """The twin's reported state at simulated time ``t`` (s). Arrays are reused between samples:
    copy what you keep.

    ``actuator_*`` have shape (na,), in scene order; ``joint_*`` (nj,); ``member_points[k]``
    (m_k, 3) the node positions of member ``member_names[k]`` along its axis (m).
    """

    t: float
    actuator_names: tuple[str, ...]
    actuator_lengths: np.ndarray
    actuator_velocities: np.ndarray
    actuator_commands: np.ndarray
    actuator_forces: np.ndarray
    joint_names: tuple[str, ...]
    joint_positions: np.ndarray
    joint_velocities: np.ndarray
    poses: list[PoseSample]
    member_names: tuple[str, ...]
    member_points: list[np.ndarray]          # views into member_xyz
    member_widths: np.ndarray
    member_xyz: np.ndarray                   # (Σ m_k, 3) every member's node positions, member by member
    # the actuator, joint and pose arrays above are views into this one buffer (one reduction
    # checks them all: is_finite runs on every published state, 9 → 3 µs measured)
    values: np.ndarray
    kinetic_energy: float = 0.0
    strain_energy: float = 0.0
    total_energy: float = 0.0
    converged: bool = True
    newton_iterations: int = 0
    residual: float = 0.0
    substeps: int = 1
    message: str = ""

    def is_finite(self) -> bool:
        """True when every reported number is finite (the node never publishes NaN)."""
        # a sum is finite iff its terms are (the magnitudes here are far from overflow)
        return bool(np.isfinite(self.values.sum() + self.member_xyz.sum() + self.total_energy))


def _member_width(model: Model, member: str) -> float:
    """Drawing width of a member (m): the section's outer diameter or its larger side."""
    spec = model.scene.members[member]
    sec = model.scene.sections.get(getattr(spec, "section", None) or "", None)
    if sec is None:
        return 0.01
    if sec.shape in ("circle", "tube"):
        return 2.0 * sec.dims[0]
    return float(max(sec.dims))


class TwinReporter:
    """Fills one preallocated :class:`TwinSample` from a :class:`Simulator` (no per-call allocation
    beyond the small observer arrays)."""

    def __init__(self, model: Model):
        self.model = model
        act = model.actuators
        na = act.l0.size
        outs = model.scene.outputs
        self._joints = [o for o in outs if o.kind == "joint_angle"]
        self._poses = [o for o in outs if o.kind == "platform_pose"]
        self._pose_observers = [PlatformObserver(model, tuple(o.nodes)) for o in self._poses]
        members = tuple(m.name for m in model.members)
        # every member's node positions in one gather: q[self._member_ids] → (Σ m_k, 3)
        self._member_ids = np.concatenate([m.ydofs for m in model.members]) if model.members else np.zeros((0, 3), int)
        xyz = np.zeros(self._member_ids.shape, dtype=float)
        bounds = np.cumsum([0] + [m.ydofs.shape[0] for m in model.members])
        nj, npose = len(self._joints), len(self._poses)
        values = np.zeros(4 * na + 2 * nj + 7 * npose)
        act_rows = values[:4 * na].reshape(4, na)
        joint_rows = values[4 * na:4 * na + 2 * nj].reshape(2, nj)
        pose_rows = values[4 * na + 2 * nj:].reshape(npose, 7)
        pose_rows[:, 3] = 1.0                      # identity orientation (w, x, y, z)
        self.sample = TwinSample(
            t=0.0, actuator_names=tuple(act.names),
            actuator_lengths=act_rows[0], actuator_velocities=act_rows[1],
            actuator_commands=act_rows[2], actuator_forces=act_rows[3],
            joint_names=tuple(o.name for o in self._joints),
            joint_positions=joint_rows[0], joint_velocities=joint_rows[1],
            poses=[PoseSample(o.name, tuple(o.nodes), pose_rows[k, :3], pose_rows[k, 3:])
                   for k, o in enumerate(self._poses)],
            member_names=members,
            member_points=[xyz[a:b] for a, b in zip(bounds[:-1], bounds[1:])],
            member_widths=np.array([_member_width(model, m) for m in members]),
            member_xyz=xyz,
            values=values,
        )

    def read(self, sim: Simulator, full: bool = True) -> TwinSample:
        """The sample at the simulator's current state (the same object every call).

        ``full=False`` refreshes the actuator and joint values and the solver health only (what
        ``/joint_states`` and the status need); poses and member shapes keep older values.
        """
        model, st, s = self.model, sim.state, self.sample
        q, v = st.q, st.v
        s.t = float(st.t)
        if s.actuator_names:
            actuator_kinematics(model, q, v, s.actuator_lengths, s.actuator_velocities)
            np.multiply(st.lam, model.actuators.l0, out=s.actuator_commands)
            s.actuator_forces[:] = actuator_forces(model, sim.ws, st)
        for k, o in enumerate(self._joints):
            s.joint_positions[k] = joint_angle(model, q, o.node, o.nodes)
            hi = joint_angle(model, q + _RATE_STEP * v, o.node, o.nodes)
            lo = joint_angle(model, q - _RATE_STEP * v, o.node, o.nodes)
            # unwrap across ±π before differencing
            s.joint_velocities[k] = np.angle(np.exp(1j * (hi - lo))) / (2.0 * _RATE_STEP)
        if full:
            for p, observe in zip(s.poses, self._pose_observers):
                observe(q, p.position, p.orientation_wxyz)
            np.take(q, self._member_ids, out=s.member_xyz)
        r = sim.last
        if r is not None:
            s.kinetic_energy, s.strain_energy, s.total_energy = r.kinetic, r.strain, r.total_energy
            s.converged, s.newton_iterations, s.residual = bool(r.converged), int(r.iterations), float(r.residual)
            s.substeps, s.message = int(r.substeps), r.message or ""
        return s
