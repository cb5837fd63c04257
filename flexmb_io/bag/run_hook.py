"""``flexmb run SCENE --mcap OUT [--record-rate HZ]``: record an offline run as a twin bag.

The bag has the live node's topics and types (``flexmb run`` and ``flexmb node`` bags are
interchangeable) and is made for exact replay:

- **input**, every step: ``/flexmb_twin/commands`` (``std_msgs/Float64MultiArray``) logged at the
  step's start ``t_n`` with the actuator lengths in force during ``t_n → t_n+1`` (the solver's
  stretches × reference lengths), the twin's timing rule (:mod:`flexmb_io.twin`);
- **outputs**, at ``record_rate`` (default 100 Hz of simulated time) and always at the first and
  last state: ``/joint_states``, ``~/actuator_states``, ``~/platform_pose`` (one per
  ``platform_pose`` output, :func:`flexmb_io.topics.pose_topic`), ``/tf``, ``~/status``, ``/clock``;
  ``~/shape`` at most at ``shape_rate`` (20 Hz).

Samples come from :class:`~flexmb_core.report.TwinReporter`, messages from
:mod:`flexmb_io.messages` — the node's code. ``flexmb run`` defers SIGINT and SIGTERM to the end of
the step under way and then closes every hook, so the bag is closed complete (exit 130).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from .. import messages as M
from .. import topics as T
from .defaults import DEFAULT_RECORD_RATE, MAX_SHAPE_RATE
from .recorder import BagRecorder


def exact_lengths(lam: np.ndarray, l0: np.ndarray, out: np.ndarray) -> np.ndarray:
    """Lengths ``L`` with ``L / l0 == lam`` bit for bit (what a replay divides back): ``lam * l0``,
    nudged by one ulp where rounding breaks the round trip (rare)."""
    np.multiply(lam, l0, out=out)
    if np.array_equal(out / l0, lam):
        return out
    for i in np.flatnonzero(out / l0 != lam):
        for direction in (np.inf, -np.inf):
            x = out[i]
            for _ in range(4):
                x = np.nextafter(x, direction)
                if x / l0[i] == lam[i]:
                    out[i] = x
                    break
            if out[i] / l0[i] == lam[i]:
                break
    return out


def run_settings(scene, *, until: float, record_rate: float, shape_rate: float,
                 node_name: str = T.DEFAULT_NODE_NAME) -> dict:
    """The ``flexmb`` metadata of an offline run (see :mod:`flexmb_io.bag.recorder`)."""
    from ..twin import RunnerOptions

    spec = scene.solver
    return {"source": "flexmb run", "solver": dataclasses.asdict(spec),
            # an offline run applies each command (the scene's law, sampled per step) to its own
            # step: its replay holds them the same way, not through a stream hold
            "runner_options": dataclasses.asdict(RunnerOptions(command_hold="step")), "until": repr(float(until)),
            "dt": repr(float(spec.dt)), "integrator": spec.integrator, "tolerance": repr(float(spec.tolerance)),
            "record_rate": repr(float(record_rate)), "shape_rate": repr(float(shape_rate)), "node_name": node_name}


class _Every:
    """Due at multiples of ``period`` (s) of simulated time, by product (no summed drift)."""

    def __init__(self, period: float):
        self.period = period
        self.next = 0.0

    def due(self, t: float) -> bool:
        return self.period <= 0 or t >= self.next - 1e-9 * max(1.0, abs(self.next))

    def mark(self, t: float) -> None:
        if self.period > 0:
            self.next = (math.floor(t / self.period + 1e-6) + 1) * self.period


class McapRunHook:
    """A ``flexmb run`` hook (``start``, ``step``, ``close``) that records to a bag.

    Parameters
    ----------
    scene, model
        The loaded scene (with the run's overrides) and its compiled model.
    scene_path
        The scene file (its text is attached to the bag).
    out
        The bag directory to create.
    record_rate
        Output messages per second of simulated time (Hz, > 0).
    node_name
        Node name the private topics resolve under.
    """

    def __init__(self, scene, model, scene_path: str, out: str, *, record_rate: float = DEFAULT_RECORD_RATE,
                 node_name: str = T.DEFAULT_NODE_NAME):
        from flexmb_core.errors import FlexmbError
        from flexmb_core.report import TwinReporter

        from ..shells import ShellShapes

        if not (record_rate > 0 and math.isfinite(record_rate)):
            raise FlexmbError(f"--record-rate must be a positive number of Hz, got {record_rate}")
        self.model = model
        self.until = float(scene.solver.until)
        shape_rate = min(record_rate, MAX_SHAPE_RATE)
        text = Path(scene_path).read_text(encoding="utf-8")
        self.recorder = BagRecorder(out, scene_path=str(scene_path), scene_text=text, node_name=node_name,
                                    settings=run_settings(scene, until=self.until, record_rate=record_rate,
                                                          shape_rate=shape_rate, node_name=node_name))
        self.reporter = TwinReporter(model)
        self.kinds = tuple(m.kind for m in model.members)
        self.shells = ShellShapes(model)
        self.l0 = model.actuators.l0
        self._lengths = np.zeros_like(self.l0)
        n = node_name
        self.t_commands = T.COMMANDS.resolved(n)
        self.t_joint, self.t_act = T.JOINT_STATES.resolved(n), T.ACTUATOR_STATES.resolved(n)
        self.t_status, self.t_shape = T.STATUS.resolved(n), T.SHAPE.resolved(n)
        self.t_clock, self.t_tf = T.CLOCK.resolved(n), T.TF.resolved(n)
        poses = [o for o in scene.outputs if o.kind == "platform_pose"]
        self.t_poses = [T.pose_topic(o.name, i).resolved(n) for i, o in enumerate(poses)]
        rec = self.recorder
        for topic, type_name in ([(self.t_commands, T.COMMANDS.type)] if self.l0.size else []) + [
                (self.t_joint, T.JOINT_STATES.type)] + ([(self.t_act, T.ACTUATOR_STATES.type)] if self.l0.size else []) + [
                (p, T.PLATFORM_POSE.type) for p in self.t_poses] + ([(self.t_tf, T.TF.type)] if self.t_poses else []) + [
                (self.t_status, T.STATUS.type), (self.t_clock, T.CLOCK.type), (self.t_shape, T.SHAPE.type)]:
            rec.declare(topic, type_name)         # first-use costs (hashes, encoders) before the loop
        self._outputs = _Every(1.0 / record_rate)
        self._shapes = _Every(1.0 / shape_rate)
        self._t_prev = 0.0
        self._logged_t: float | None = None
        self._shape_t: float | None = None
        self._wall_prev = 0.0           # solver wall time after the previous step (s)
        self._step_wall = 0.0
        self._rtf_ref = (0.0, 0.0)      # (t, solver wall) at the last output

    # -- hook protocol -------------------------------------------------------------------------
    def start(self, sim) -> None:
        self._t_prev = float(sim.state.t)
        self._wall_prev = sim.stats.wall_time_s
        self._rtf_ref = (self._t_prev, self._wall_prev)
        self._write_outputs(sim, shape=True)

    def step(self, sim, res) -> None:
        rec = self.recorder
        t = float(sim.state.t)
        wall = sim.stats.wall_time_s
        self._step_wall, self._wall_prev = wall - self._wall_prev, wall
        if self.l0.size:
            # with servos the solver's stretches are the servos' outputs: record their input, which
            # a replay feeds through the same servos
            lengths = (exact_lengths(sim.state.lam, self.l0, self._lengths) if self.model.actuators.servo is None
                       else sim.last_commands)
            rec.write(self.t_commands, T.COMMANDS.type, M.float64_array(lengths), self._t_prev)
        self._t_prev = t
        if self._outputs.due(t):
            self._write_outputs(sim, shape=self._shapes.due(t))

    def close(self, sim, summary: dict) -> None:
        try:
            if self._logged_t != float(sim.state.t) or self._shape_t != float(sim.state.t):
                self._write_outputs(sim, shape=True)        # always the final state
        finally:
            self.recorder.close()
        summary["mcap"] = str(self.recorder.path)
        summary["mcap_messages"] = self.recorder.message_count

    # -- outputs -------------------------------------------------------------------------------
    def _write_outputs(self, sim, shape: bool) -> None:
        rec, s = self.recorder, self.reporter.read(sim)
        t = s.t
        if self._logged_t != t:
            rec.write(self.t_joint, T.JOINT_STATES.type, M.joint_state(s), t)
            if s.actuator_names:
                rec.write(self.t_act, T.ACTUATOR_STATES.type, M.actuator_state(s), t)
            for i, topic in enumerate(self.t_poses):
                rec.write(topic, T.PLATFORM_POSE.type, M.platform_pose(s, i), t)
            if self.t_poses:
                rec.write(self.t_tf, T.TF.type, M.tf(s), t)
            rec.write(self.t_status, T.STATUS.type, M.status(s, self._timing(sim, t)), t)
            rec.write(self.t_clock, T.CLOCK.type, M.clock(t), t)
            self._logged_t = t
            self._outputs.mark(t)
        if shape and self._shape_t != t:
            self.shells.read(sim.state.q)
            rec.write(self.t_shape, T.SHAPE.type, M.shape(s, self.kinds, self.shells), t)
            self._shape_t = t
            self._shapes.mark(t)

    def _timing(self, sim, t: float) -> M.StatusTiming:
        t_ref, w_ref = self._rtf_ref
        wall = sim.stats.wall_time_s
        rtf = (t - t_ref) / (wall - w_ref) if wall > w_ref and t > t_ref else 0.0
        self._rtf_ref = (t, wall)
        return M.StatusTiming(step_wall_time=self._step_wall, steps=sim.stats.steps,
                              unconverged_steps=sim.stats.unconverged_steps, real_time_factor=rtf)


def make_hook(args, scene, model) -> McapRunHook | None:
    """``add_run_hook`` factory: a recorder when ``--mcap`` is given, else None."""
    out = getattr(args, "mcap", None)
    if not out:
        return None
    return McapRunHook(scene, model, args.scene, out,
                       record_rate=getattr(args, "record_rate", DEFAULT_RECORD_RATE))
