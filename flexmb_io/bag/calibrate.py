"""``flexmb calibrate BAG --fit KEY[=LO:HI] ...``: identify scene parameters so the twin reproduces
a recording.

The bag's commands drive the twin (in lockstep, as ``flexmb replay`` does: :mod:`.lockstep`); its
recorded outputs are the measurements. Each run of the twin at trial parameter values is a Dask
task (:func:`residuals`); the fit itself is :func:`flexmb_core.study.calibrate.fit` (bounded
nonlinear least squares, Jacobian columns in parallel, per-channel noise weights, standard errors).

Measured channels (``--outputs`` picks by name or by the part after the dot):

==========================  =====  ======================================================
channel                     unit   from
==========================  =====  ======================================================
``actuators.length``        m      ``~/actuator_states`` lengths (else ``/joint_states``)
``actuators.force``         N      ``~/actuator_states`` axial_forces (else efforts)
``actuators.velocity``      m/s    ``~/actuator_states`` velocities (else velocities)
``joints.angle``            rad    ``/joint_states`` positions of the passive joints
``<pose>.position``         m      ``~/platform_pose`` (and ``~/<pose>/pose``) positions
``<pose>.orientation``      rad    the rotation from the recorded to the simulated orientation
==========================  =====  ======================================================

Works on bags of ``flexmb run --mcap`` and of ``flexmb node --mcap``; a bag recorded elsewhere
needs the same topics and a scene (``--scene``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flexmb_core.errors import FlexmbError
from flexmb_core.study.calibrate import CalibrationError, FitResult

from .. import topics as T
from .lockstep import input_kinds, run_lockstep
from .reader import BagReader
from .replay import TwinSetup, build_twin, read_setup

UNITS = {"length": "m", "force": "N", "velocity": "m/s", "angle": "rad", "position": "m", "orientation": "rad"}


@dataclass(frozen=True)
class Channel:
    """A measured series: ``values[k]`` (columns named ``columns``) recorded at ``times_ns[k]``."""

    name: str                      # actuators.force, platform.position, ...
    times_ns: np.ndarray           # (m,) int64
    values: np.ndarray             # (m, ncol); orientations: (m, 4) as w, x, y, z
    columns: tuple[str, ...]

    @property
    def kind(self) -> str:
        return self.name.rsplit(".", 1)[-1]

    @property
    def unit(self) -> str:
        return UNITS[self.kind]


@dataclass(frozen=True)
class Measurements:
    """Everything a trial run needs, as plain data (shipped once to every Dask worker)."""

    setup: TwinSetup
    overrides: tuple[str, ...]     # --override edits of the scene (before the fitted values)
    keys: tuple[str, ...]          # the fitted scene keys, in theta's order
    commands: list                 # (log ns, topic, kind, plain-dict message, arrival s or None)
    channels: tuple[Channel, ...]
    last_ns: int


def _pose_topics(twin, setup: TwinSetup) -> dict[str, str]:
    """Resolved pose topic → platform_pose output name."""
    poses = [o for o in twin.scene.outputs if o.kind == "platform_pose"]
    return {T.pose_topic(o.name, i).resolved(setup.node_name, setup.namespace): o.name for i, o in enumerate(poses)}


_UNTIL_SLACK_NS = 10_000_000


def read_measurements(bag, fit_keys: list[str], *, outputs: list[str] | None = None, until: float | None = None,
                      scene_path: str | None = None, overrides: list[str] | None = None) -> Measurements:
    """The commands and measured channels of ``bag`` (up to ``until`` s of simulated time).

    Raises
    ------
    CalibrationError
        When the bag holds no commands or none of the chosen channels.
    ReplayError, flexmb_core.errors.SceneError
        When the bag has no usable scene or settings.
    """
    from .reader import obj_to_dict

    reader = BagReader(bag)
    setup = read_setup(reader, scene_path)
    overrides = tuple(overrides or ())
    kinds = input_kinds(setup.node_name, setup.namespace)
    act_topic = T.ACTUATOR_STATES.resolved(setup.node_name, setup.namespace)
    twin = build_twin(setup, list(overrides))        # compiled once: pose topics, actuator names
    poses = _pose_topics(twin, setup)
    acts = set(twin.model.actuators.names)
    stop = None if until is None else int(round(until * 1e9))
    commands, rows = [], {}                       # rows: channel → (times, values, columns)

    def add(name: str, t: int, vals, cols) -> None:
        times, values, _ = rows.setdefault(name, ([], [], tuple(cols)))
        times.append(t)
        values.append(np.asarray(vals, dtype=float))

    have_act = act_topic in reader.topics()
    end_ns, cut = 0, False
    for m in reader.messages():
        if stop is not None and m.log_time_ns > stop:
            cut = True
            break
        end_ns = max(end_ns, m.log_time_ns)
        if m.topic in kinds:
            commands.append((m.log_time_ns, m.topic, kinds[m.topic], obj_to_dict(m.decode()), m.arrival))
        elif m.topic == act_topic:
            r = m.decode()
            add("actuators.length", m.log_time_ns, r.lengths, r.names)
            add("actuators.force", m.log_time_ns, r.axial_forces, r.names)
            add("actuators.velocity", m.log_time_ns, r.velocities, r.names)
        elif m.type == "sensor_msgs/msg/JointState" and not have_act:
            _joint_state_rows(add, m.log_time_ns, m.decode(), acts)
        elif m.topic in poses:
            p = m.decode().pose
            add(f"{poses[m.topic]}.position", m.log_time_ns, (p.position.x, p.position.y, p.position.z), "xyz")
            q = p.orientation
            add(f"{poses[m.topic]}.orientation", m.log_time_ns, (q.w, q.x, q.y, q.z), "xyz")
    if stop is not None and not cut and stop > end_ns + _UNTIL_SLACK_NS:
        # a horizon past the recording would fit nothing it names: say so instead of fitting less
        # (within one 100 Hz output period of its last message it is the recording's end)
        raise CalibrationError(f"--until {until:g} s is beyond the recording {bag}, which ends at "
                               f"{end_ns * 1e-9:.6g} s of simulated time")
    if not commands:
        raise CalibrationError(f"{bag}: no recorded commands on {sorted(kinds)}: nothing drives the twin")
    channels = [Channel(name, np.asarray(t, dtype=np.int64), np.vstack(v), cols)
                for name, (t, v, cols) in rows.items()]
    chosen = _select(channels, outputs, bag)
    commands.sort(key=lambda c: c[0])
    last = max(int(c.times_ns[-1]) for c in chosen)
    return Measurements(setup, overrides, tuple(fit_keys), commands, tuple(chosen), last)


def _joint_state_rows(add, t: int, r, acts: set[str]) -> None:
    """``/joint_states`` as channels when the bag has no ``~/actuator_states``."""
    names = list(r.name)
    a = [i for i, n in enumerate(names) if n in acts]
    j = [i for i, n in enumerate(names) if n not in acts]
    pos, vel, eff = (np.asarray(x, dtype=float) for x in (r.position, r.velocity, r.effort))
    cols = [names[i] for i in a]
    if a:
        add("actuators.length", t, pos[a], cols)
        if eff.size == len(names):
            add("actuators.force", t, eff[a], cols)
        if vel.size == len(names):
            add("actuators.velocity", t, vel[a], cols)
    if j:
        add("joints.angle", t, pos[j], [names[i] for i in j])


def _select(channels: list[Channel], outputs: list[str] | None, bag) -> list[Channel]:
    if not channels:
        raise CalibrationError(f"{bag}: no recorded outputs to calibrate against (actuator states, joint states "
                               "or platform poses)")
    if not outputs:
        return channels
    names = [c.name for c in channels]
    chosen = []
    for o in outputs:
        hit = [c for c in channels if o in (c.name, c.kind, c.name.split(".", 1)[0])]
        if not hit:
            raise CalibrationError(f"--outputs {o!r}: no such measured channel in {bag} (channels: {', '.join(names)})")
        chosen += [c for c in hit if c not in chosen]
    return chosen


def start_values(meas_setup: TwinSetup, overrides: list[str] | None, keys: list[str]) -> np.ndarray:
    """The scene's values at ``keys`` after ``overrides`` (the fit starts there).

    Raises
    ------
    CalibrationError
        When a key is missing or not a number.
    """
    from flexmb_core.scene.loader import parse_yaml
    from flexmb_core.scene.overrides import apply_overrides, split_key

    data = parse_yaml(meas_setup.scene_text)
    solver = apply_overrides(data, overrides)
    out = []
    for key in keys:
        node: Any = data
        path = split_key(key)
        if path[0] == "solver" and len(path) == 2 and path[1] in solver:
            node = solver[path[1]]
            path = []
        for part in path:
            if isinstance(node, list) and part.lstrip("-").isdigit() and -len(node) <= int(part) < len(node):
                node = node[int(part)]
            elif isinstance(node, dict) and part in node:
                node = node[part]
            else:
                raise CalibrationError(f"--fit {key}: the scene has no such key ({meas_setup.scene_source})")
        if isinstance(node, bool) or not isinstance(node, (int, float)):
            raise CalibrationError(f"--fit {key}: not a number in the scene (got {str(node)[:60]!r})")
        out.append(float(node))
    return np.asarray(out)


def _rotation_vectors(q_meas: np.ndarray, q_sim: np.ndarray) -> np.ndarray:
    """(m, 3) rotation vectors (rad) from the recorded to the simulated orientation (w, x, y, z)."""
    from scipy.spatial.transform import Rotation

    a = Rotation.from_quat(q_meas[:, [1, 2, 3, 0]])
    b = Rotation.from_quat(q_sim[:, [1, 2, 3, 0]])
    return (a.inv() * b).as_rotvec()


def residuals(meas: Measurements, theta: np.ndarray) -> dict[str, np.ndarray]:
    """Replay the bag's commands with the fitted keys set to ``theta``; simulated − measured per
    channel (orientations: the rotation vector between them). A Dask task.

    Raises
    ------
    flexmb_core.errors.FlexmbError
        When the scene does not validate at ``theta`` or the replay fails or stops early.
    """
    from ..twin import TwinRunner

    values = dict(zip(meas.keys, (float(x) for x in theta)))
    twin = build_twin(meas.setup, list(meas.overrides), values=values)
    runner = TwinRunner(twin.model, options=twin.options)
    index = {c.name: {int(t): k for k, t in enumerate(c.times_ns)} for c in meas.channels}
    sim = {c.name: np.full(c.values.shape, np.nan) for c in meas.channels}
    pose_of = {o.name: i for i, o in enumerate(o for o in twin.scene.outputs if o.kind == "platform_pose")}
    remaining = sum(len(c.times_ns) for c in meas.channels)

    def at(ns: int) -> bool:
        nonlocal remaining
        s = None
        for c in meas.channels:
            k = index[c.name].get(ns)
            if k is None:
                continue
            if s is None:
                s = runner.sample()
            sim[c.name][k] = _simulated(c, s, pose_of)
            remaining -= 1
        return remaining > 0

    runner.start()
    done = run_lockstep(runner, meas.commands, last_ns=meas.last_ns, until=twin.until, at=at)
    if done.failure:
        raise FlexmbError(f"the replay failed at {values}: {done.failure}")
    if remaining:
        raise FlexmbError(f"the replay at {values} stopped at t = {done.t_end:.6g} s before the last measurement")
    out = {}
    for c in meas.channels:
        if c.kind == "orientation":
            out[c.name] = _rotation_vectors(c.values, sim[c.name])
        else:
            out[c.name] = sim[c.name] - c.values
    return out


def _simulated(c: Channel, s, pose_of: dict[str, int]) -> np.ndarray:
    group, kind = c.name.split(".", 1)
    if group == "actuators":
        src = {"length": s.actuator_lengths, "force": s.actuator_forces, "velocity": s.actuator_velocities}[kind]
        return src[[s.actuator_names.index(n) for n in c.columns]]
    if group == "joints":
        return s.joint_positions[[s.joint_names.index(n) for n in c.columns]]
    p = s.poses[pose_of[group]]
    return p.position if kind == "position" else p.orientation_wxyz


def measured_rms(meas: Measurements) -> dict[str, float]:
    """RMS of each channel's measured values about their mean (orientations: 1 rad)."""
    out = {}
    for c in meas.channels:
        if c.kind == "orientation":
            out[c.name] = 1.0
        else:
            d = c.values - c.values.mean(axis=0)
            out[c.name] = float(np.sqrt(np.mean(d * d))) or float(np.sqrt(np.mean(c.values ** 2))) or 1.0
    return out


def calibrated_scene_text(setup: TwinSetup, overrides: list[str] | None, result: FitResult, header: str) -> str:
    """The scene with the overrides and the identified values applied, as YAML with ``header``."""
    import yaml

    from flexmb_core.scene.loader import parse_yaml
    from flexmb_core.scene.overrides import apply_overrides, set_path, split_key

    data = parse_yaml(setup.scene_text)
    solver = apply_overrides(data, overrides)
    for key, value in zip(result.keys, result.values):
        path = split_key(key)
        if path[0] == "solver" and len(path) == 2:
            solver[path[1]] = float(value)
        else:
            set_path(data, path, float(value), item=key, flag="--fit")
    if solver:
        data.setdefault("solver", {})
        data["solver"] = {**data["solver"], **solver}
    return header + yaml.safe_dump(data, sort_keys=False, allow_unicode=True)

