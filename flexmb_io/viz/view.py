"""``flexmb view``: a recording → :class:`~flexmb_io.viz.rerun_log.TwinRerunLogger`.

Each recorded topic maps to one logger method, at the message's header stamp (simulated time):

===================================  =====================================================
``.../shape`` MarkerArray            deformed members (LINE_STRIP per member, ns = name) and
                                     shells (TRIANGLE_LIST per shell → a mesh)
``.../actuator_states``              actuator lengths, rates, commanded lengths, forces
``/joint_states``                    passive joints (and actuators when no ActuatorState)
``...platform_pose`` PoseStamped     platform poses (``/tf`` only when no pose topic)
``.../status`` TwinStatus            solver health and energies
command inputs                       commanded lengths as received (``plots/actuators/input``)
===================================  =====================================================

The geometry comes from the markers alone; the ``scene.yaml`` attachment, when present, adds the
member kinds, the shells' mesh connectivity (their triangle lists fold back onto the mesh nodes),
supports, platform outlines and the camera.
"""

from __future__ import annotations

import warnings
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from .layout import TwinLayout
from .. import topics as T
from ..bag.recorder import METADATA_NAME
from ..messages import MARKER_ADD, MARKER_LINE_STRIP, MARKER_TRIANGLE_LIST
from .recording import Recording

# message types by the topic contract (flexmb_io.topics)
T_JOINT_STATE = T.JOINT_STATES.type
T_ACTUATOR_STATE = T.ACTUATOR_STATES.type
T_POSE = T.PLATFORM_POSE.type
T_SHAPE = T.SHAPE.type
T_STATUS = T.STATUS.type
T_TF = T.TF.type
T_CLOCK = T.CLOCK.type
T_COMMANDS = T.COMMANDS.type
T_ACTUATOR_COMMAND = T.ACTUATOR_COMMANDS.type
T_TRAJECTORY = T.TRAJECTORY.type


@dataclass
class ViewReport:
    """What :func:`view_recording` logged."""

    path: str
    rrd: str | None
    scene: str | None                 # scene name when the recording carried its scene
    messages: Counter = field(default_factory=Counter)     # logged messages per topic
    skipped: Counter = field(default_factory=Counter)      # unused or decimated, per topic
    t_first: float = float("inf")     # s, first and last stamp logged
    t_last: float = float("-inf")
    truncated: bool = False
    layout: TwinLayout | None = None  # what was drawn (for a PNG's camera)


def layout_from_scene(text: str, where: str) -> TwinLayout | None:
    """Compile an attached scene into a layout; None (with a warning) if it does not load."""
    from flexmb_core.errors import FlexmbError
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene.loader import parse_yaml, scene_from_dict

    try:
        return TwinLayout.from_model(compile_scene(scene_from_dict(parse_yaml(text), source=where)))
    except (FlexmbError, ValueError, KeyError) as exc:
        warnings.warn(f"{where}: the attached scene does not load ({exc}); drawing from the markers only",
                      stacklevel=2)
        return None


def _quat_rotate(wxyz: np.ndarray, pts: np.ndarray) -> np.ndarray:
    w, x, y, z = wxyz
    rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                    [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                    [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    return pts @ rot.T


def _marker_points(m) -> np.ndarray:
    """A marker's points (n, 3) in the world: through its pose (the twin leaves it at identity)."""
    pts = np.array([[p.x, p.y, p.z] for p in m.points], dtype=np.float64).reshape(-1, 3)
    o, p = m.pose.orientation, m.pose.position
    q = np.array([o.w, o.x, o.y, o.z])
    if np.linalg.norm(q) > 0 and not np.allclose(q, [1.0, 0.0, 0.0, 0.0]):
        pts = _quat_rotate(q / np.linalg.norm(q), pts)
    pts += np.array([p.x, p.y, p.z])
    return pts


def _marker_rgba(m) -> tuple:
    return (m.color.r, m.color.g, m.color.b, m.color.a if m.color.a > 0 else 1.0)


def markers_to_members(msg) -> tuple[list[str], list[np.ndarray], list[float], list[tuple]]:
    """Names, points (m_k, 3), widths and colours of the LINE_STRIP markers of a MarkerArray."""
    names, points, widths, colors = [], [], [], []
    for m in msg.markers:
        if m.type != MARKER_LINE_STRIP or m.action != MARKER_ADD or not m.points:
            continue
        names.append(m.ns or f"marker{m.id}")
        points.append(_marker_points(m))
        widths.append(float(m.scale.x))
        colors.append(_marker_rgba(m))
    return names, points, widths, colors


def markers_to_shells(msg) -> tuple[list[str], list[np.ndarray], list[tuple]]:
    """Names, triangle-list points (3 nt_k, 3) (three per triangle, through the marker's pose;
    RViz's per-marker scale is not applied: the twin writes 1) and colours of the TRIANGLE_LIST
    markers of a MarkerArray."""
    names, points, colors = [], [], []
    for m in msg.markers:
        if m.type != MARKER_TRIANGLE_LIST or m.action != MARKER_ADD or len(m.points) < 3:
            continue
        names.append(m.ns or f"marker{m.id}")
        points.append(_marker_points(m))
        colors.append(_marker_rgba(m))
    return names, points, colors


class Exaggeration:
    """Magnifies the bending of members: each polyline's deviation from its chord, beyond the
    deviation it had in the first shape seen, is multiplied by ``factor``.

    A point of a member at chord fraction ``s`` (from the first shape: its projection on the chord
    there) is drawn at ``c(s) + d₀ + factor·(d − d₀)``, ``c(s) = p_first + s (p_last − p_first)``
    the chord now, ``d`` its deviation from it now and ``d₀`` at first sight. The member's ends, its
    rigid motion and its stretch stay as computed, so the legs still meet their joints; the
    transverse deflection of a straight member (``d₀ = 0``) is what grows. ``d₀`` is kept in world
    axes: a curved member that turns far from its first pose is drawn with its initial curvature
    misplaced (the Stewart legs and the shipped frames are straight)."""

    def __init__(self, factor: float):
        self.factor = float(factor)
        self._first: dict[str, tuple[np.ndarray, np.ndarray]] = {}      # name → (s (m,), d₀ (m, 3))

    @staticmethod
    def _chord(pts: np.ndarray, s: np.ndarray) -> np.ndarray:
        return pts[0] + s[:, None] * (pts[-1] - pts[0])

    def apply(self, name: str, pts: np.ndarray) -> np.ndarray:
        """The magnified polyline ``(m, 3)`` of member ``name`` (``pts`` as computed)."""
        if self.factor == 1.0 or pts.shape[0] < 3:
            return pts
        first = self._first.get(name)
        if first is None or first[0].size != pts.shape[0]:
            axis = pts[-1] - pts[0]
            length2 = float(axis @ axis)
            if not length2 > 0.0:
                return pts                       # a closed loop: no chord to measure from
            s = (pts - pts[0]) @ axis / length2
            first = (s, pts - self._chord(pts, s))
            self._first[name] = first
        s, d0 = first
        chord = self._chord(pts, s)
        return chord + d0 + self.factor * (pts - chord - d0)


class _Router:
    """Decides which logger call a recorded topic feeds (by type, and by name for poses)."""

    def __init__(self, channels: dict[str, str], layout: TwinLayout):
        self.layout = layout
        # the node's namespace, from the topics only the twin publishes ("/flexmb_twin" by default)
        self.prefix = None
        for topic, typ in channels.items():
            for t, suffix in ((T_STATUS, "/status"), (T_ACTUATOR_STATE, "/actuator_states"), (T_SHAPE, "/shape")):
                if typ == t and topic.endswith(suffix):
                    self.prefix = topic[: -len(suffix)]
        self.has_actuator_state = T_ACTUATOR_STATE in channels.values()
        self.has_pose = any(typ == T_POSE and top.endswith("platform_pose") for top, typ in channels.items())
        self.exaggeration = Exaggeration(1.0)

    def platform_name(self, topic: str) -> str:
        """``<prefix>/platform_pose`` is the first platform; ``<prefix>/<output>/platform_pose`` names it."""
        head = topic[: -len("platform_pose")].rstrip("/")
        if self.prefix is not None:
            rest = head[len(self.prefix):].strip("/") if head.startswith(self.prefix) else head.rsplit("/", 1)[-1]
        else:
            parts = head.strip("/").split("/")
            rest = parts[-1] if len(parts) >= 2 else ""
        if rest:
            return rest
        return self.layout.platforms[0].name if self.layout.platforms else "platform"


def view_recording(path, *, rrd_path: str | None = None, period: float = 0.0, recording_id=None,
                   logger=None, exaggerate: float = 1.0) -> ViewReport:
    """Log a recording into rerun.

    Parameters
    ----------
    path
        A rosbag2 directory or an ``.mcap`` file written with the twin's topics.
    rrd_path
        The ``.rrd`` to write (ignored when ``logger`` is given).
    period
        Keep, per topic, the first message at or after each multiple of ``period`` s of stamp time
        (0: every message).
    recording_id
        Passed to the logger (default: the recording's file name, so re-viewing replaces it).
    logger
        An open :class:`~flexmb_io.viz.rerun_log.TwinRerunLogger` to log into (not closed here).
    exaggerate
        Factor on the members' bending (:class:`Exaggeration`; 1: as computed).
    """
    from .rerun_log import TwinRerunLogger

    rec = Recording(path)
    text = rec.scene_text()
    layout = layout_from_scene(text, f"{path}:scene.yaml") if text else None
    report = ViewReport(str(path), None if logger is not None else rrd_path,
                        layout.name if layout is not None else None)
    channels = rec.channels()
    if layout is None:
        layout = TwinLayout(name=rec.metadata().get(METADATA_NAME, {}).get("scene", rec.path.stem))
        _prime(rec, channels, layout)
    own = logger is None
    if own:
        logger = TwinRerunLogger(layout, rrd_path=rrd_path, recording_id=recording_id or rec.path.stem)
    else:
        logger.layout = layout
    logger.log_static()
    router = _Router(channels, layout)
    router.exaggeration = Exaggeration(exaggerate)
    next_kept: dict[str, float] = {}        # per topic, the next grid time to keep (with period)
    sim_t = 0.0                             # newest simulated time seen: stamps unstamped inputs
    try:
        for m in rec.messages():
            t = m.stamp
            if m.type == T_COMMANDS or (m.type == T_ACTUATOR_COMMAND and t == 0.0):
                t = sim_t
            elif m.type in (T_STATUS, T_SHAPE, T_ACTUATOR_STATE, T_JOINT_STATE, T_POSE, T_CLOCK):
                sim_t = max(sim_t, t)
            # a grid of multiples of the period (not "period after the last kept"), so that every
            # topic keeps the same time points and the rounding of stamps cannot drift them
            if period > 0 and t < next_kept.get(m.topic, -np.inf) - 1e-9 * max(1.0, abs(t)):
                report.skipped[m.topic] += 1
                continue
            if not _dispatch(logger, router, m, t):
                report.skipped[m.topic] += 1
                continue
            if period > 0:
                next_kept[m.topic] = (np.floor(t / period + 1e-6) + 1) * period
            report.messages[m.topic] += 1
            report.t_first = min(report.t_first, t)
            report.t_last = max(report.t_last, t)
    finally:
        if own:
            logger.close()
        else:
            logger.flush()
    report.truncated = rec.truncated
    report.layout = layout
    return report


def _prime(rec: Recording, channels: dict[str, str], layout: TwinLayout) -> None:
    """Without a scene: actuator names from the first ActuatorState (so that ``/joint_states``
    entries can be told apart from the first message on) and the camera from the first shape."""
    wanted = {t: typ for t, typ in channels.items() if typ in (T_SHAPE, T_ACTUATOR_STATE)}
    seen: set[str] = set()
    for m in rec.messages(topics=set(wanted)) if wanted else ():
        if m.type == T_SHAPE and T_SHAPE not in seen:
            for pts in markers_to_members(m.msg)[1] + markers_to_shells(m.msg)[1]:
                layout.include_points(pts)
        elif m.type == T_ACTUATOR_STATE and T_ACTUATOR_STATE not in seen:
            layout.actuator_names.extend(n for n in m.msg.names if n not in layout.actuator_names)
        seen.add(m.type)
        if seen == set(wanted.values()):
            break


def _dispatch(logger, router: _Router, m, t: float) -> bool:
    """Feed one message to the logger; False when the topic is not one the view uses."""
    msg, typ = m.msg, m.type
    if typ == T_SHAPE:
        names, pts, widths, colors = markers_to_members(msg)
        pts = [router.exaggeration.apply(n, p) for n, p in zip(names, pts)]
        # colours from the markers only when no scene says the member kinds
        logger.log_members(t, names, pts, widths, None if logger.layout.from_scene else colors)
        names, pts, colors = markers_to_shells(msg)
        if names:
            logger.log_shells(t, names, pts, None, None if logger.layout.from_scene else colors)
    elif typ == T_ACTUATOR_STATE:
        logger.log_actuators(t, msg.names, msg.lengths, msg.velocities, msg.commanded_lengths, msg.axial_forces)
    elif typ == T_JOINT_STATE:
        return _joint_state(logger, router, msg, t)
    elif typ == T_POSE and m.topic.endswith("platform_pose"):
        p, o = msg.pose.position, msg.pose.orientation
        logger.log_pose(t, router.platform_name(m.topic), [p.x, p.y, p.z], [o.w, o.x, o.y, o.z])
    elif typ == T_TF:
        if router.has_pose:
            return False                      # the same poses arrive on the pose topics
        for tr in msg.transforms:
            p, o = tr.transform.translation, tr.transform.rotation
            logger.log_pose(t, tr.child_frame_id, [p.x, p.y, p.z], [o.w, o.x, o.y, o.z])
    elif typ == T_STATUS:
        logger.log_solver(t, converged=msg.converged, newton_iterations=msg.newton_iterations,
                          residual=msg.residual, message=msg.message,
                          energies=(msg.kinetic_energy, msg.strain_energy, msg.total_energy),
                          step_wall_time=msg.step_wall_time, real_time_factor=msg.real_time_factor)
    elif typ == T_COMMANDS:
        names = logger.layout.actuator_names
        if len(names) != len(msg.data):
            return False                      # positional commands need every actuator's name
        logger.log_inputs(t, names, msg.data)
    elif typ == T_ACTUATOR_COMMAND:
        logger.log_inputs(t, msg.names, msg.lengths)
    else:
        return False                          # /clock, trajectories, foreign topics
    return True


def _joint_state(logger, router: _Router, msg, t: float) -> bool:
    """``/joint_states`` holds the actuators (length, rate, axial force as effort), then the
    passive joints. Actuators are logged from it only when there is no ActuatorState topic."""
    names = list(msg.name)
    acts = set(logger.layout.actuator_names)
    if not acts and not router.has_actuator_state:
        acts = set(names)             # no scene, no ActuatorState: nothing says which are joints
    a_idx = [i for i, n in enumerate(names) if n in acts]
    j_idx = [i for i, n in enumerate(names) if n not in acts]
    used = False
    if a_idx and not router.has_actuator_state:
        _log_actuators_from_joint_state(logger, msg, a_idx, t)
        used = True
    if j_idx:
        vel = [msg.velocity[i] for i in j_idx] if len(msg.velocity) == len(names) else None
        logger.log_joints(t, [names[i] for i in j_idx], [msg.position[i] for i in j_idx], vel)
        used = True
    return used


def _log_actuators_from_joint_state(logger, msg, idx: list[int], t: float) -> None:
    if not idx:
        return
    n = len(msg.name)
    pick = (lambda arr: [arr[i] for i in idx] if len(arr) == n else None)
    logger.log_actuators(t, [msg.name[i] for i in idx], pick(msg.position), pick(msg.velocity), None,
                         pick(msg.effort))

