"""Per-field comparison of recorded twin outputs with a replay (tolerances: :mod:`.tolerances`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flexmb_core.report import TwinSample

from .. import messages as M
from ..shells import ShellShapes
from .tolerances import RELATIVE


@dataclass
class FieldStat:
    """The worst deviation of one field of one topic over the replay."""

    topic: str
    field: str
    kind: str                      # a tolerance key
    worst: float = 0.0
    t: float = 0.0                 # s, where the worst deviation occurred
    element: str = ""              # actuator / joint / frame / marker name
    peak: float = 0.0              # max |recorded value| (relative kinds)
    samples: int = 0
    identical: bool = True         # every compared value equal bit for bit

    def add(self, dev: float, t: float, element: str, peak: float = 0.0) -> None:
        self.samples += 1
        if peak > self.peak:
            self.peak = peak
        if dev != dev:                                           # NaN: always the worst
            dev, element = math.inf, element + " (NaN)"
        if dev != 0.0:
            self.identical = False
        if self.samples == 1 or dev > self.worst:
            self.worst, self.t, self.element = dev, t, element

    def limit(self, tol: dict) -> float:
        v = tol[self.kind]
        if self.kind in RELATIVE:
            return v * self.peak if self.peak > 0 else v
        return v

    def ok(self, tol: dict) -> bool:
        return self.worst <= self.limit(tol)


@dataclass
class Comparison:
    """Every field's statistics plus structural mismatches (names, counts) found on the way."""

    stats: dict[tuple[str, str], FieldStat] = field(default_factory=dict)
    mismatches: list[str] = field(default_factory=list)

    def stat(self, topic: str, name: str, kind: str) -> FieldStat:
        key = (topic, name)
        s = self.stats.get(key)
        if s is None:
            s = self.stats[key] = FieldStat(topic, name, kind)
        return s

    def mismatch(self, text: str) -> None:
        if len(self.mismatches) < 50:
            self.mismatches.append(text)

    # -- per type ----------------------------------------------------------------------------------
    def joint_states(self, topic: str, rec, s: TwinSample, t: float) -> None:
        ref = M.joint_state(s)
        names = list(rec.name)
        if names != ref.name:
            self.mismatch(f"{topic} t = {t:.9g} s: joint names {names} differ from the replay's {ref.name}")
            return
        na = len(s.actuator_names)
        pos, vel, eff = np.asarray(rec.position), np.asarray(rec.velocity), np.asarray(rec.effort)
        if not (len(pos) == len(vel) == len(eff) == len(names)):
            self.mismatch(f"{topic} t = {t:.9g} s: position/velocity/effort sizes {len(pos)}/{len(vel)}/{len(eff)} "
                          f"for {len(names)} names")
            return
        rp, rv, re = np.asarray(ref.position), np.asarray(ref.velocity), np.asarray(ref.effort)
        if na:
            self._vec(topic, "position (actuators)", "length", pos[:na], rp[:na], names[:na], t)
            self._vec(topic, "effort", "force", eff[:na], re[:na], names[:na], t)
        if len(names) > na:
            d = np.abs(np.angle(np.exp(1j * (pos[na:] - rp[na:]))))        # angles modulo 2π
            self._dev(topic, "position (joints)", "angle", d, names[na:], t)
        self._vec(topic, "velocity", "velocity", vel, rv, names, t)

    def actuator_states(self, topic: str, rec, s: TwinSample, t: float) -> None:
        ref = M.actuator_state(s)
        names = list(rec.names)
        if names != ref.names:
            self.mismatch(f"{topic} t = {t:.9g} s: actuator names {names} differ from the replay's {ref.names}")
            return
        for fname, kind in (("lengths", "length"), ("commanded_lengths", "length"), ("velocities", "velocity"),
                            ("axial_forces", "force")):
            a = np.asarray(getattr(rec, fname))
            if a.size != len(names):
                self.mismatch(f"{topic} t = {t:.9g} s: {fname} has {a.size} values for {len(names)} names")
                continue
            self._vec(topic, fname, kind, a, np.asarray(getattr(ref, fname)), names, t)

    def pose(self, topic: str, rec, s: TwinSample, index: int, t: float) -> None:
        p = s.poses[index]
        self._pose(topic, "", rec.pose.position, rec.pose.orientation, p.position, p.orientation_wxyz,
                   p.name, t)

    def tf(self, topic: str, rec, s: TwinSample, t: float, frame_prefix: str = "") -> None:
        by_name = {frame_prefix + p.name: p for p in s.poses}
        for tr in rec.transforms:
            p = by_name.get(tr.child_frame_id)
            if p is None:
                self.mismatch(f"{topic} t = {t:.9g} s: frame {tr.child_frame_id!r} is not a platform of the replay "
                              f"({sorted(by_name)})")
                continue
            self._pose(topic, "transform ", tr.transform.translation, tr.transform.rotation, p.position,
                       p.orientation_wxyz, p.name, t)

    def shape(self, topic: str, rec, s: TwinSample, t: float, shells: ShellShapes | None = None) -> None:
        """Every recorded marker against the replay: a LINE_STRIP's points against its member's
        nodes, a TRIANGLE_LIST's against its shell's triangle vertices (``shells`` read at the
        sample's state), by ``ns``; one field ``points`` (m, the largest point distance)."""
        strips = dict(zip(s.member_names, s.member_points))
        shell_index = {} if shells is None else {name: i for i, name in enumerate(shells.names)}
        st = self.stat(topic, "points", "position")
        for mk in rec.markers:
            if mk.type == M.MARKER_TRIANGLE_LIST:
                i = shell_index.get(mk.ns)
                pts, what = (None if i is None else shells.vertices(i)), "shell"
            else:
                pts, what = strips.get(mk.ns), "member"
            if pts is None:
                self.mismatch(f"{topic} t = {t:.9g} s: marker ns {mk.ns!r} is not a {what} of the replay")
                continue
            got = np.array([[q.x, q.y, q.z] for q in mk.points]).reshape(-1, 3)
            if got.shape != pts.shape:
                self.mismatch(f"{topic} t = {t:.9g} s: {what} {mk.ns} has {len(got)} points, replay {len(pts)}")
                continue
            st.add(float(np.sqrt(((got - pts) ** 2).sum(axis=1)).max()) if len(got) else 0.0, t, mk.ns)

    def status(self, topic: str, rec, s: TwinSample, t: float) -> None:
        self.stat(topic, "converged", "converged").add(float(bool(rec.converged) != bool(s.converged)), t, "")
        for fname in ("kinetic_energy", "strain_energy", "total_energy"):
            a, b = float(getattr(rec, fname)), float(getattr(s, fname))
            self.stat(topic, fname, "energy").add(abs(a - b), t, "", abs(a))

    # -- helpers -------------------------------------------------------------------------------------
    def _vec(self, topic, name, kind, rec, ref, names, t) -> None:
        d = np.abs(rec - ref)
        peak = float(np.abs(rec).max()) if rec.size else 0.0
        self._dev(topic, name, kind, d, names, t, peak)

    def _dev(self, topic, name, kind, d, names, t, peak: float = 0.0) -> None:
        st = self.stat(topic, name, kind)
        if d.size == 0:
            return
        nan = np.isnan(d)
        k = int(np.flatnonzero(nan)[0]) if nan.any() else int(np.argmax(d))
        st.add(float(d[k]), t, names[k], peak)

    def _pose(self, topic, prefix, pos, q, ref_pos, ref_wxyz, name, t) -> None:
        dp = math.dist((pos.x, pos.y, pos.z), tuple(ref_pos))
        self.stat(topic, prefix + "position", "position").add(dp, t, name)
        got = (q.w, q.x, q.y, q.z)
        same = all(a == float(b) for a, b in zip(got, ref_wxyz))
        self.stat(topic, prefix + "orientation", "angle").add(0.0 if same else rotation_angle(got, ref_wxyz), t, name)


def rotation_angle(a_wxyz, b_wxyz) -> float:
    """Angle (rad, in [0, π]) of the rotation between two unit quaternions (w, x, y, z); accurate
    for tiny angles (no arccos of a number near 1)."""
    aw, ax, ay, az = a_wxyz
    bw, bx, by, bz = (float(v) for v in b_wxyz)
    # r = conj(a) ⊗ b
    rw = aw * bw + ax * bx + ay * by + az * bz
    rx = aw * bx - ax * bw - ay * bz + az * by
    ry = aw * by + ax * bz - ay * bw - az * bx
    rz = aw * bz - ax * by + ay * bx - az * bw
    return 2.0 * math.atan2(math.sqrt(rx * rx + ry * ry + rz * rz), abs(rw))
