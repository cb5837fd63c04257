"""``flexmb replay BAG``: re-run a recording's commands through the twin and compare its outputs.

The twin is rebuilt from the bag alone: the scene attached as ``scene.yaml`` (or ``--scene``),
the solver settings of the ``flexmb`` metadata record (``solver``: the effective ``SolverSpec``,
so ``--dt``/``--integrator`` given to the recorded run are honoured), the runner options
(``runner_options``) and the node name. It then steps in lockstep with the recording
(:mod:`flexmb_io.twin`'s timing rule):

1. before the step from ``t_n``, apply every recorded command (``~/commands``,
   ``~/actuator_commands``, ``~/joint_trajectory``) logged at ≤ ``t_n`` (ns), in file order, with
   its recorded arrival (a realtime node records an unstamped command's wall-clock arrival, mapped
   to twin time, as the message's publish time: it sets the command's sample clock);
2. step (an offline run's last step is shortened to land on its ``until``, as ``flexmb run`` does);
3. compare every output recorded at the new time (same ns) with what the replay reports, field by
   field (:mod:`flexmb_io.bag.compare` lists the fields and the default tolerances).

No ROS is needed. Exit codes of the verb: 0 every field within tolerance; 3 a field beyond its
tolerance, a structural mismatch (names, sizes), a replay step that failed, or recorded outputs the
replay never reached; 1 bad input (not a bag, no scene, unknown tolerance key, bad override).
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flexmb_core.errors import FlexmbError
from flexmb_core.scene.overrides import apply_overrides, set_path, split_key

from .. import topics as T
from .compare import Comparison, FieldStat
from .lockstep import input_kinds, run_lockstep
from .reader import BagReader
from .tolerances import RELATIVE, REPORT_UNITS, parse_tolerances

EXIT_OK, EXIT_BAD_INPUT, EXIT_DEVIATION = 0, 1, 3

_OUTPUT_TYPES = {"sensor_msgs/msg/JointState", "flexmb_msgs/msg/ActuatorState", "geometry_msgs/msg/PoseStamped",
                 "tf2_msgs/msg/TFMessage", "visualization_msgs/msg/MarkerArray", "flexmb_msgs/msg/TwinStatus",
                 "rosgraph_msgs/msg/Clock"}


class ReplayError(FlexmbError):
    """A bag that cannot be replayed as asked (bad input: exit code 1)."""


@dataclass
class Twin:
    """A twin rebuilt from a bag."""

    scene: Any
    model: Any
    options: Any
    node_name: str
    until: float | None            # offline runs: where the last step lands
    scene_sha256: str
    scene_source: str
    namespace: str = "/"
    frame_prefix: str = ""


@dataclass(frozen=True)
class TwinSetup:
    """Everything a bag says about the twin that recorded it, as plain data (picklable: a
    calibration ships it to Dask workers): the scene text and the ``flexmb`` metadata settings."""

    scene_text: str
    scene_source: str
    solver: dict                   # the effective SolverSpec keys of the recorded run
    runner_options: dict
    node_name: str
    until: float | None            # offline runs: where the last step lands
    namespace: str = "/"           # the recording node's namespace (its topics resolve under it)
    frame_prefix: str = ""         # prepended to the platforms' tf child frames


def read_setup(reader: BagReader, scene_path: str | None = None) -> TwinSetup:
    """The :class:`TwinSetup` of a bag (``scene_path``: a scene file instead of the attached one).

    Raises
    ------
    ReplayError
        When the bag has no scene (and none is given) or its settings are unreadable.
    """
    if scene_path is not None:
        from flexmb_core.scene.loader import read_scene_text

        text, source = read_scene_text(Path(scene_path)), str(scene_path)    # SceneError names the file
    else:
        text, source = reader.scene_text(), f"{reader.file}:scene.yaml"
        if text is None:
            raise ReplayError(f"{reader.path}: no scene.yaml attachment (not recorded by flexmb?); "
                              "give the scene with --scene PATH")
    try:
        solver = reader.setting("solver", {}, as_json=True)
        opts = reader.setting("runner_options", {}, as_json=True)
        until = reader.setting("until")
    except json.JSONDecodeError as exc:
        raise ReplayError(f"{reader.path}: unreadable settings in the 'flexmb' metadata ({exc})") from None
    if not solver:                              # older bags / other writers: the scalar keys
        solver = {k: json.loads(reader.setting(k)) if k == "dt" else reader.setting(k)
                  for k in ("dt", "integrator") if reader.setting(k) is not None}
    try:
        frames = reader.setting("frames", {}, as_json=True) or {}
    except json.JSONDecodeError:
        frames = {}
    return TwinSetup(text, source, solver, opts, reader.setting("node_name") or T.DEFAULT_NODE_NAME,
                     float(until) if until is not None else None, reader.setting("node_namespace") or "/",
                     str(frames.get("prefix", "")) if isinstance(frames, dict) else "")


def load_twin(reader: BagReader, scene_path: str | None = None, overrides: list[str] | None = None) -> Twin:
    """Scene, compiled model and runner options of a bag (see the module docstring).

    Raises
    ------
    ReplayError
        When the bag has no scene (and none is given) or its settings are unreadable.
    flexmb_core.errors.SceneError
        When the (modified) scene does not validate.
    """
    return build_twin(read_setup(reader, scene_path), overrides, where=str(reader.path))


def _recorded_solver(recorded: dict) -> dict:
    """The recorded solver settings minus those equal to this flexmb's defaults.

    A bag stores the whole effective ``SolverSpec``; handed back to the strict loader, keys that
    apply to another analysis (the statics path-following keys of a dynamic run) would be refused
    although nobody set them. A key equal to today's default changes nothing when dropped, and a
    recorded value that differs from today's default is kept, so an old bag still replays with the
    settings it was recorded with.
    """
    from flexmb_core.scene.schema import SolverSpec

    defaults = {f.name: f.default for f in dataclasses.fields(SolverSpec) if f.default is not dataclasses.MISSING}
    return {k: v for k, v in recorded.items() if not (k in defaults and v == defaults[k])}


def build_twin(setup: TwinSetup, overrides: list[str] | None = None, *, where: str = "",
               values: dict[str, Any] | None = None) -> Twin:
    """Compile the twin of a :class:`TwinSetup` with ``KEY=VALUE`` scene edits (``solver.X`` keys win
    over the recorded solver settings), then ``values`` (dotted key → number, as parsed values: a
    calibration's trial point).

    Raises
    ------
    ReplayError
        When the recorded runner options are unknown to this flexmb.
    flexmb_core.errors.SceneError
        When the (modified) scene does not validate.
    """
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene.loader import parse_yaml, scene_from_dict

    from ..twin import RunnerOptions
    from .recorder import scene_sha256

    data = parse_yaml(setup.scene_text)
    if not isinstance(data, dict):
        raise ReplayError(f"{setup.scene_source}: not a scene mapping")
    solver = _recorded_solver(setup.solver)
    solver.update(apply_overrides(data, overrides))
    for key, value in (values or {}).items():
        set_path(data, split_key(key), value, item=f"{key}={value!r}", flag="--fit")
    scene = scene_from_dict(data, source=setup.scene_source, overrides=solver)
    opts = dict(setup.runner_options)
    fields = {f.name: f for f in dataclasses.fields(RunnerOptions)}
    unknown = sorted(set(opts) - set(fields))
    if unknown:
        raise ReplayError(f"{where or setup.scene_source}: runner_options {unknown} unknown to this flexmb "
                          f"(has {sorted(fields)})")
    # bags from before command holds existed applied every command as a step from its step on
    opts.setdefault("command_hold", "step")
    options = RunnerOptions(**{k: (float(v) if isinstance(fields[k].default, float) and isinstance(v, int)
                                   and not isinstance(v, bool) else v) for k, v in opts.items()})
    return Twin(scene, compile_scene(scene), options, setup.node_name, setup.until,
                scene_sha256(setup.scene_text), setup.scene_source, setup.namespace, setup.frame_prefix)


@dataclass
class ReplayReport:
    """What ``flexmb replay`` found (``exit_code`` per the module docstring)."""

    bag: str
    scene: str
    scene_source: str
    tolerances: dict
    fields: list[FieldStat]
    mismatches: list[str]
    steps: int = 0
    failed_steps: int = 0
    commands_applied: int = 0
    commands_rejected: int = 0
    rejections: list[str] = field(default_factory=list)
    samples_compared: int = 0
    samples_unmatched: int = 0
    first_unmatched_t: float | None = None
    t_end: float = 0.0
    truncated: bool = False
    wall_time_s: float = 0.0
    failure: str = ""

    def beyond(self) -> list[FieldStat]:
        return [f for f in self.fields if not f.ok(self.tolerances)]

    @property
    def ok(self) -> bool:
        return (not self.beyond() and not self.mismatches and not self.failure and self.samples_unmatched == 0
                and self.samples_compared > 0)

    @property
    def exit_code(self) -> int:
        return EXIT_OK if self.ok else EXIT_DEVIATION

    def as_dict(self) -> dict:
        def fs(f: FieldStat) -> dict:
            return {"topic": f.topic, "field": f.field, "kind": f.kind, "worst": f.worst, "t": f.t,
                    "element": f.element, "peak": f.peak, "limit": f.limit(self.tolerances),
                    "samples": f.samples, "identical": f.identical, "ok": f.ok(self.tolerances)}
        d = {k: v for k, v in dataclasses.asdict(self).items() if k != "fields"}
        d.update(fields=[fs(f) for f in self.fields], ok=self.ok, exit_code=self.exit_code)
        return d

    def format(self) -> str:
        """A readable table: one line per topic/field with its worst deviation."""
        tol = self.tolerances
        lines = [f"replay of {self.bag} (scene '{self.scene}' from {self.scene_source}): {self.steps} steps to "
                 f"t = {self.t_end:.6g} s, {self.commands_applied} commands applied"
                 + (f" ({self.commands_rejected} rejected)" if self.commands_rejected else "")
                 + f", {self.samples_compared} recorded messages compared in {self.wall_time_s:.2f} s"
                 + (" — the bag ends early (read up to its last complete chunk)" if self.truncated else "")]
        w = max([len(f.topic) for f in self.fields] + [5])
        lines.append(f"  {'topic':{w}s}  {'field':24s} {'worst':>11s}  {'at t (s)':>10s}  {'where':22s} "
                     f"{'limit':>10s}  {'unit':9s} result")
        for f in self.fields:
            flag = "ok" if f.ok(tol) else "BEYOND"
            unit = REPORT_UNITS[f.kind]
            note = f" ({tol[f.kind]:g} × peak {f.peak:.4g})" if f.kind in RELATIVE else ""
            lines.append(f"  {f.topic:{w}s}  {f.field:24s} {f.worst:11.3e}  {f.t:10.4f}  {f.element[:22]:22s} "
                         f"{f.limit(tol):10.3e}  {unit:9s} {flag:6s}{note}".rstrip())
        for m in self.mismatches:
            lines.append(f"  MISMATCH {m}")
        if self.failure:
            lines.append(f"  FAILED {self.failure}")
        if self.samples_unmatched:
            lines.append(f"  UNMATCHED {self.samples_unmatched} recorded output messages at times the replay never "
                         f"reached (first at t = {self.first_unmatched_t:.9g} s)")
        for r in self.rejections[:5]:
            lines.append(f"  rejected command: {r}")
        bad = self.beyond()
        if self.ok:
            exact = all(f.identical for f in self.fields)
            lines.append("result: every field within tolerance (exit 0)"
                         + ("; the replay is bit-identical to the recording" if exact else ""))
        else:
            why = []
            if bad:
                why.append(f"{len(bad)} field(s) beyond tolerance: "
                           + ", ".join(f"{f.topic} {f.field} {f.worst:.3e} > {f.limit(tol):.3e} at t = {f.t:.4f} s"
                                       + (f" ({f.element})" if f.element else "") for f in bad[:6]))
            if self.mismatches:
                why.append(f"{len(self.mismatches)} structural mismatch(es)")
            if self.failure:
                why.append("the replay failed")
            if self.samples_unmatched:
                why.append("recorded outputs not reproduced")
            if self.samples_compared == 0:
                why.append("nothing was compared")
            lines.append("result: REGRESSION — " + "; ".join(why) + f" (exit {EXIT_DEVIATION})")
        return "\n".join(lines)


def replay(bag, *, tolerances: list[str] | dict | None = None, scene_path: str | None = None,
           overrides: list[str] | None = None) -> ReplayReport:
    """Replay ``bag`` and compare (see the module docstring).

    Parameters
    ----------
    bag
        A rosbag2 directory or ``.mcap`` recorded by ``flexmb run --mcap`` or ``flexmb node --mcap``.
    tolerances
        ``KEY=VALUE`` strings or a mapping (:mod:`flexmb_io.bag.compare`); defaults otherwise.
    scene_path
        Replay against this scene file instead of the attached one.
    overrides
        ``KEY.PATH=VALUE`` edits of the scene (``materials.steel.E=2.2e11``, ``solver.tolerance=1e-6``).

    Raises
    ------
    ReplayError, flexmb_core.errors.SceneError
        On bad input.
    """
    from .tolerances import ToleranceError
    from ..twin import TwinRunner

    try:
        tol = (parse_tolerances(None, tolerances) if isinstance(tolerances, dict)
               else parse_tolerances(tolerances))
    except ToleranceError as exc:
        raise ReplayError(str(exc)) from None
    reader = BagReader(bag)
    twin = load_twin(reader, scene_path, overrides)
    runner = TwinRunner(twin.model, options=twin.options)
    if runner.sim.spec.analysis != "dynamic":
        raise ReplayError(f"{bag}: scene analysis '{runner.sim.spec.analysis}' cannot be replayed")
    kinds = input_kinds(twin.node_name, twin.namespace)
    pose_index = {T.pose_topic(o.name, i).resolved(twin.node_name, twin.namespace): i
                  for i, o in enumerate(o for o in twin.scene.outputs if o.kind == "platform_pose")}

    commands: list[tuple[int, str, str, Any, float | None]] = []
    outputs: dict[int, list[tuple[str, str, Any]]] = {}
    for m in reader.messages():
        if m.topic in kinds:
            commands.append((m.log_time_ns, m.topic, kinds[m.topic], m.decode(), m.arrival))
        elif m.type in _OUTPUT_TYPES:
            outputs.setdefault(m.log_time_ns, []).append((m.topic, m.type, m))
    if not outputs:
        raise ReplayError(f"{bag}: no recorded outputs to compare (topics: {sorted(reader.topics())})")
    commands.sort(key=lambda c: c[0])              # stable: file order within one time
    last_ns = max(outputs)
    cmp = Comparison()
    report = ReplayReport(str(bag), twin.scene.name, twin.scene_source, tol, [], cmp.mismatches,
                          truncated=reader.truncated)

    def compare_at(ns: int) -> None:
        batch = outputs.pop(ns, None)
        if not batch:
            return
        s = runner.sample()
        t = s.t
        for topic, typ, m in batch:
            rec = m.decode()
            report.samples_compared += 1
            if typ == "sensor_msgs/msg/JointState":
                cmp.joint_states(topic, rec, s, t)
            elif typ == "flexmb_msgs/msg/ActuatorState":
                cmp.actuator_states(topic, rec, s, t)
            elif typ == "geometry_msgs/msg/PoseStamped":
                if topic in pose_index:
                    cmp.pose(topic, rec, s, pose_index[topic], t)
                else:
                    cmp.mismatch(f"{topic}: no platform_pose output of the replayed scene publishes here "
                                 f"(expected one of {sorted(pose_index)})")
            elif typ == "tf2_msgs/msg/TFMessage":
                cmp.tf(topic, rec, s, t, twin.frame_prefix)
            elif typ == "visualization_msgs/msg/MarkerArray":
                cmp.shape(topic, rec, s, t, runner.shells)
            elif typ == "flexmb_msgs/msg/TwinStatus":
                cmp.status(topic, rec, s, t)
            elif typ == "rosgraph_msgs/msg/Clock":
                c = rec.clock
                if c.sec * 1_000_000_000 + c.nanosec != ns:
                    cmp.mismatch(f"{topic}: clock {c.sec}.{c.nanosec:09d} logged at {ns} ns")

    def at(ns: int) -> bool:
        compare_at(ns)
        return bool(outputs)

    wall0 = time.perf_counter()
    runner.start()
    done = run_lockstep(runner, commands, last_ns=last_ns, until=twin.until, at=at)
    report.steps, report.failed_steps, report.failure = done.steps, done.failed_steps, done.failure
    report.commands_applied, report.commands_rejected = done.commands_applied, done.commands_rejected
    report.rejections = done.rejections
    report.t_end = done.t_end
    report.wall_time_s = time.perf_counter() - wall0
    if outputs:
        report.samples_unmatched = sum(len(v) for v in outputs.values())
        report.first_unmatched_t = min(outputs) * 1e-9
    report.fields = sorted(cmp.stats.values(), key=lambda f: (f.topic, f.field))
    return report

