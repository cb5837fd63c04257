"""Log a twin into rerun: :class:`TwinRerunLogger`.

One logger serves a live node, ``flexmb run --rrd`` and ``flexmb view`` (a recording): samples
(:class:`~flexmb_core.report.TwinSample`) go through :meth:`TwinRerunLogger.log_sample`, recorded
messages through the per-topic methods it is made of (:meth:`~TwinRerunLogger.log_members`,
:meth:`~TwinRerunLogger.log_shells`, :meth:`~TwinRerunLogger.log_actuators`,
:meth:`~TwinRerunLogger.log_pose`, ...), so both produce
the same entities (see :mod:`flexmb_io.viz.blueprint`) on the timeline ``sim_time``.

Rows are buffered per entity and sent with ``send_columns`` every ``flush_rows`` rows: in rerun
0.41 one ``log`` call costs 60 µs (scalars) to 240 µs (a line strip), a buffered row 7–30 µs, so
the 20-s Stewart run logged at 100 Hz costs ≈1 s instead of ≈6 s. A live viewer wants
``flush_rows`` small (latency) and a low logging rate.
"""

from __future__ import annotations

import numpy as np

from flexmb_core.errors import writable_file

from . import blueprint as bp
from .layout import PLATFORM_RGBA, SUPPORT_RGBA, TwinLayout, rgba8

# Series colours (matplotlib tab10), one per actuator / joint / energy instance, cycled.
_PALETTE = ((31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
            (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207))

_SCALARS, _STRIP, _TRANSFORM, _MESH = "scalars", "strip", "transform", "mesh"


def _ns(t: float) -> int:
    """Seconds → integer nanoseconds (the stamps' own resolution)."""
    return int(round(float(t) * 1e9))


def _colors(n: int) -> list[tuple[int, int, int]]:
    return [_PALETTE[i % len(_PALETTE)] for i in range(n)]


class TwinRerunLogger:
    """Logs one twin into its own :class:`rerun.RecordingStream` (never the global one).

    Parameters
    ----------
    model
        A compiled :class:`~flexmb_core.model.model.Model`, a ready
        :class:`~flexmb_io.viz.layout.TwinLayout`, or None (names are learnt from what is logged).
    rrd_path
        Write the recording to this ``.rrd`` file (``rr.save``-style sink); without it, attach a
        sink yourself through :attr:`recording` (``connect_grpc``, ``spawn``, ...).
    recording_id, application_id
        Passed to :class:`rerun.RecordingStream`.
    flush_rows
        Send buffered rows once this many are pending (1: every call goes out at once).

    Notes
    -----
    Call :meth:`log_static` once (it is called by the first sample otherwise), then
    :meth:`log_sample` per reported state, and :meth:`close` at the end (the file is complete only
    then).
    """

    def __init__(self, model, *, rrd_path: str | None = None, recording_id=None,
                 application_id: str = "flexmb", flush_rows: int = 2048):
        import rerun as rr

        self._rr = rr
        if isinstance(model, TwinLayout):
            self.layout = model
        elif model is None:
            self.layout = TwinLayout()
        else:
            self.layout = TwinLayout.from_model(model)
        self.recording = rr.RecordingStream(application_id, recording_id=recording_id)
        # sim_time is the only clock: wall-clock log_time/log_tick columns would make two loggings
        # of the same recording differ and double the timelines the viewer offers
        self.recording.set_log_time_enabled(False)
        self.recording.set_log_tick_enabled(False)
        self.rrd_path = None if rrd_path is None else str(rrd_path)
        if self.rrd_path is not None:
            writable_file(self.rrd_path, "--rrd")   # rerun's own refusal is a RuntimeError with a traceback
            self.recording.save(self.rrd_path)
        self.flush_rows = max(1, int(flush_rows))
        self.samples = 0                       # log_sample calls
        self._buf: dict[str, tuple[str, list[int], list]] = {}
        self._pending = 0
        self._styled: dict[str, object] = {}   # entity → the static style last logged
        self._static_done = False
        self._closed = False

    # -- static ------------------------------------------------------------------------------
    def log_static(self) -> None:
        """World frame and axes, fixed supports, the blueprint; logged once (static)."""
        rr, rec, lay = self._rr, self.recording, self.layout
        self._static_done = True
        rec.log(bp.WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        size = lay.size()
        origin = np.zeros(3) if lay.bounds is None else np.array([lay.bounds[0][0], lay.bounds[0][1], 0.0])
        rec.log(bp.AXES, rr.Arrows3D(vectors=0.2 * size * np.eye(3), origins=np.tile(origin, (3, 1)),
                                     colors=[(220, 60, 60), (60, 180, 60), (60, 90, 220)],
                                     labels=["x", "y", "z"], radii=0.004 * size), static=True)
        if len(lay.support_points):
            rec.log(bp.SUPPORTS, rr.Points3D(lay.support_points, radii=0.015 * size,
                                             colors=[rgba8(SUPPORT_RGBA)] * len(lay.support_points),
                                             labels=lay.support_labels, show_labels=False), static=True)
        self.send_blueprint()

    def send_blueprint(self) -> None:
        """(Re)send the default blueprint, e.g. once a recording's bounds are known."""
        self.recording.send_blueprint(bp.build_blueprint(self.layout), make_active=True, make_default=True)

    # -- one reported state ------------------------------------------------------------------
    def log_sample(self, sample, status: dict | None = None, shells=None) -> None:
        """Log a :class:`~flexmb_core.report.TwinSample` at ``sample.t`` (s) on ``sim_time``.

        ``status`` adds what the sample does not know: ``step_wall_time`` (s), ``real_time_factor``
        and ``message`` (overrides the solver's), as in ``flexmb_msgs/TwinStatus``. ``shells``
        (:class:`~flexmb_io.shells.ShellShapes`, read at the sample's state) adds the shells.
        """
        if not self._static_done:
            self.log_static()
        st = status or {}
        t = sample.t
        self.log_members(t, sample.member_names, sample.member_points, sample.member_widths)
        if shells is not None and len(shells):
            self.log_shells(t, shells.names, shells.points, shells.triangles)
        if sample.actuator_names:
            self.log_actuators(t, sample.actuator_names, sample.actuator_lengths, sample.actuator_velocities,
                               sample.actuator_commands, sample.actuator_forces)
        if sample.joint_names:
            self.log_joints(t, sample.joint_names, sample.joint_positions, sample.joint_velocities)
        for p in sample.poses:
            self.log_pose(t, p.name, p.position, p.orientation_wxyz)
        self.log_solver(t, converged=sample.converged, newton_iterations=sample.newton_iterations,
                        residual=sample.residual, message=st.get("message") or sample.message,
                        energies=(sample.kinetic_energy, sample.strain_energy, sample.total_energy),
                        step_wall_time=st.get("step_wall_time"), real_time_factor=st.get("real_time_factor"))
        self.samples += 1

    # -- the parts (one per recorded topic) --------------------------------------------------
    def log_members(self, t: float, names, points, widths=None, colors=None) -> None:
        """Deformed members: ``points[k] (m_k, 3)`` (m) of member ``names[k]``, drawn ``widths[k]``
        wide (m) in ``colors[k]`` (RGBA in [0, 1]; default: by member kind). Platforms whose nodes
        lie on these members get their outline and mesh at the same time."""
        rr, lay, ns = self._rr, self.layout, _ns(t)
        index = {}
        for k, name in enumerate(names):
            i = lay.member_index(name, None if colors is None else colors[k])
            index[i] = k
            path = self._member_path(name)
            radius = 0.5 * float(widths[k]) if widths is not None else 0.005 * lay.size()
            color = lay.member_colors[i]
            self._style(path, (radius, color),
                        lambda r=radius, c=color: rr.LineStrips3D.from_fields(radii=[r], colors=[rgba8(c)]))
            self._push(path, _STRIP, ns, np.array(points[k], dtype=np.float64, copy=True))
        for p in lay.platforms:
            if p.locators and all(i in index for i, _ in p.locators):
                corners = np.array([points[index[i]][j] for i, j in p.locators], dtype=np.float64)
                self._log_platform_shape(p.name, ns, corners)
        self._maybe_flush()

    def log_shells(self, t: float, names, points, triangles=None, colors=None) -> None:
        """Deformed shells as meshes ``world/shells/<name>``: triangle indices static, vertex
        positions at ``t`` (s).

        Parameters
        ----------
        names : sequence of str
        points : sequence of (n_k, 3) arrays
            Shell ``names[k]``'s node positions (m) with ``triangles``; without them, a triangle
            list (3 points per triangle: a TRIANGLE_LIST marker's points).
        triangles : sequence of (nt_k, 3) int arrays, optional
            Node indices of each flat triangle (:func:`flexmb_io.shells.shell_triangles`).
        colors : sequence of RGBA in [0, 1], optional
            Default: the layout's (the shell colour).

        Notes
        -----
        A triangle list whose shell the layout knows from a model (same triangle count) is folded
        back onto the mesh nodes, so a recording viewed with its scene logs the same entity as the
        live run; otherwise each triplet of points is one triangle.
        """
        rr, lay, ns = self._rr, self.layout, _ns(t)
        for k, name in enumerate(names):
            shell = lay.shell(name, None if colors is None else colors[k])
            pts = np.asarray(points[k], dtype=np.float64).reshape(-1, 3)
            if triangles is not None:
                tri, row = triangles[k], pts.copy()                  # the sample's buffers are reused
            elif (shell.triangles is not None and shell.first is not None
                  and 3 * shell.triangles.shape[0] == pts.shape[0]):
                tri, row = shell.triangles, pts[shell.first]          # a gather: already a copy
            else:
                tri, row = np.arange(pts.shape[0] - pts.shape[0] % 3).reshape(-1, 3), pts.copy()
            path = self._entity(bp.SHELLS, name)
            color = shell.color
            self._style(path, (tri.shape, row.shape, color), lambda tri=tri, c=color: rr.Mesh3D.from_fields(
                triangle_indices=np.asarray(tri, dtype=np.uint32), albedo_factor=rgba8(c),
                face_rendering="DoubleSided"))
            self._push(path, _MESH, ns, row)
        self._maybe_flush()

    def log_actuators(self, t: float, names, lengths, velocities=None, commands=None, forces=None) -> None:
        """Actuator lengths (m), rates (m/s), commanded lengths (m), axial forces (N), by name."""
        names = tuple(names)
        cols = self._by_name(self.layout.actuator_names, names)
        ns = _ns(t)
        for path, values in ((bp.ACT_LENGTH, lengths), (bp.ACT_VELOCITY, velocities),
                             (bp.ACT_COMMAND, commands), (bp.ACT_FORCE, forces)):
            if values is None or len(values) == 0:
                continue
            suffix = " cmd" if path == bp.ACT_COMMAND else ""
            self._series(path, self.layout.actuator_names, ns, cols, values, suffix=suffix,
                         width=1.0 if suffix else 2.0)
        self._maybe_flush()

    def log_inputs(self, t: float, names, lengths) -> None:
        """Commanded lengths (m) as the twin received them (a recording's input topics)."""
        cols = self._by_name(self.layout.actuator_names, tuple(names))
        self._series(bp.ACT_INPUT, self.layout.actuator_names, _ns(t), cols, lengths, suffix=" input", width=1.0)
        self._maybe_flush()

    def log_joints(self, t: float, names, angles, rates=None) -> None:
        """Passive joint angles (rad) and rates (rad/s), by name."""
        first = not self.layout.joint_names
        cols = self._by_name(self.layout.joint_names, tuple(names))
        if first and self._static_done:
            self.send_blueprint()              # the joint-angle tab exists only once joints are known
        ns = _ns(t)
        self._series(bp.JOINT_ANGLE, self.layout.joint_names, ns, cols, angles)
        if rates is not None and len(rates):
            self._series(bp.JOINT_RATE, self.layout.joint_names, ns, cols, rates)
        self._maybe_flush()

    def log_pose(self, t: float, name: str, position, wxyz) -> None:
        """A platform pose: centroid (m) and orientation quaternion (w, x, y, z) → ``Transform3D``
        of ``world/platforms/<name>/frame`` with its axes drawn."""
        rr = self._rr
        self.layout.platform(name)
        path = f"{self._platform_path(name)}/frame"
        length = 0.15 * self.layout.size()
        self._style(path, length, lambda: rr.TransformAxes3D(axis_length=length))
        q = np.asarray(wxyz, dtype=np.float64)
        row = (np.array(position, dtype=np.float64), np.array([q[1], q[2], q[3], q[0]]))   # rerun: xyzw
        self._push(path, _TRANSFORM, _ns(t), row)
        self._maybe_flush()

    def log_solver(self, t: float, *, converged: bool = True, newton_iterations=None, residual=None,
                   message: str = "", energies=None, step_wall_time=None, real_time_factor=None) -> None:
        """Solver health (Newton iterations, relative residual, step wall time in s, real-time
        factor), energies (kinetic, strain, total; J) and, when not converged or noted, a text log."""
        ns = _ns(t)
        for path, value in ((bp.NEWTON, newton_iterations), (bp.RESIDUAL, residual),
                            (bp.STEP_WALL, step_wall_time), (bp.RTF, real_time_factor)):
            if value is not None:
                self._series(path, (path.rsplit("/", 1)[1],), ns, None, [value])
        if energies is not None:
            self._series(bp.ENERGY, bp.ENERGY_NAMES, ns, None, energies)
        if message or not converged:
            rr = self._rr
            self.recording.set_time(bp.TIMELINE, duration=np.timedelta64(ns, "ns"))
            self.recording.log(bp.SOLVER_LOG, rr.TextLog(message or "step did not converge",
                                                         level="INFO" if converged else "WARN"))
        self._maybe_flush()

    # -- end ---------------------------------------------------------------------------------
    def flush(self) -> None:
        """Send every buffered row."""
        rr = self._rr
        for path, (kind, times, rows) in self._buf.items():
            if not times:
                continue
            n = len(times)
            index = [rr.TimeColumn(bp.TIMELINE, duration=np.array(times, dtype="timedelta64[ns]"))]
            if kind == _SCALARS:
                data = np.stack(rows)                                  # (n, k)
                cols = rr.Scalars.columns(scalars=data.ravel())
                if data.shape[1] > 1:
                    cols = cols.partition(np.full(n, data.shape[1]))
            elif kind == _STRIP:
                cols = rr.LineStrips3D.columns(strips=rows)            # one strip (m, 3) per row
            elif kind == _TRANSFORM:
                cols = rr.Transform3D.columns(translation=np.stack([r[0] for r in rows]),
                                              quaternion=np.stack([r[1] for r in rows]))
            else:                                                      # _MESH: (nv, 3) per row
                data = np.stack(rows)
                cols = rr.Mesh3D.columns(vertex_positions=data.reshape(-1, 3)).partition(np.full(n, data.shape[1]))
            self.recording.send_columns(path, indexes=index, columns=cols)
            times.clear()
            rows.clear()
        self._pending = 0

    def close(self) -> None:
        """Flush and finish the recording (the ``.rrd`` is complete after this)."""
        if self._closed:
            return
        if not self._static_done:
            self.log_static()
        self.flush()
        self.recording.flush()
        self.recording.disconnect()
        self._closed = True

    def __enter__(self) -> "TwinRerunLogger":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- internals ---------------------------------------------------------------------------
    def _entity(self, base: str, name: str) -> str:
        # scene names are hierarchical ("legs/leg3/actuator"): keep the hierarchy, escape each part
        parts = [self._rr.escape_entity_path_part(p) for p in name.split("/") if p]
        return "/".join([base] + parts)

    def _member_path(self, name: str) -> str:
        return self._entity(bp.MEMBERS, name)

    def _platform_path(self, name: str) -> str:
        return self._entity(bp.PLATFORMS, name)

    def _log_platform_shape(self, name: str, ns: int, corners: np.ndarray) -> None:
        """Outline through the platform's nodes and a fan of triangles around their centroid."""
        rr = self._rr
        n = len(corners)
        base = self._platform_path(name)
        self._style(f"{base}/outline", n, lambda: rr.LineStrips3D.from_fields(
            radii=[0.004 * self.layout.size()], colors=[rgba8(PLATFORM_RGBA[:3] + (1.0,))]))
        self._push(f"{base}/outline", _STRIP, ns, np.vstack([corners, corners[:1]]))
        if n >= 3:
            tri = np.array([[n, i, (i + 1) % n] for i in range(n)], dtype=np.uint32)
            self._style(f"{base}/mesh", n, lambda: rr.Mesh3D.from_fields(
                triangle_indices=tri, albedo_factor=rgba8(PLATFORM_RGBA), face_rendering="DoubleSided"))
            self._push(f"{base}/mesh", _MESH, ns, np.vstack([corners, corners.mean(axis=0)]))

    def _by_name(self, known: list[str], names: tuple[str, ...]) -> np.ndarray | None:
        """Columns of ``names`` among ``known`` (appending new names); None when they are equal."""
        if tuple(known) == names:
            return None
        for n in names:
            if n not in known:
                known.append(n)
        return np.array([known.index(n) for n in names], dtype=np.int64)

    def _series(self, path: str, names, ns: int, cols, values, *, suffix: str = "", width: float = 2.0) -> None:
        """One row of a multi-instance scalar entity (instances = ``names``; NaN where not given)."""
        rr = self._rr
        k = len(names)
        if cols is None and len(values) == k:
            row = np.array(values, dtype=np.float64)
        else:
            row = np.full(k, np.nan)
            row[np.arange(len(values)) if cols is None else cols] = np.asarray(values, dtype=np.float64)
        labels = tuple(f"{n}{suffix}" for n in names)
        self._style(path, labels, lambda: rr.SeriesLines(names=list(labels), colors=_colors(k), widths=[width] * k))
        self._push(path, _SCALARS, ns, row)

    def _style(self, path: str, key, make) -> None:
        """Log an entity's static style once, and again when ``key`` changes (new names)."""
        if self._styled.get(path) != key:
            self.recording.log(path, make(), static=True)
            self._styled[path] = key

    def _push(self, path: str, kind: str, ns: int, row) -> None:
        entry = self._buf.get(path)
        if entry is None:
            entry = self._buf[path] = (kind, [], [])
        elif kind == _SCALARS and entry[2] and entry[2][0].shape != row.shape:
            self.flush()                       # more instances than before: send the narrower rows first
        entry[1].append(ns)
        entry[2].append(row)
        self._pending += 1

    def _maybe_flush(self) -> None:
        if self._pending >= self.flush_rows:
            self.flush()
