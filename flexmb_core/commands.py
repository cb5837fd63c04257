"""Command programs: generators of actuator lengths that a scene names (``commands:`` block).

A program drives several actuators together (e.g. the six legs of the Stewart appendix law) and
is evaluated once per step for all of them. Per-actuator ``command`` signals cover the simple cases;
an external source (the ROS node, ``Simulator.set_commands``) overrides both.
"""

from __future__ import annotations

import numpy as np

from .errors import SceneError
from .scene.schema import CommandProgramSpec


class StewartAppendixProgram:
    """Leg lengths of Siqueira & Coda (2019), appendix Eqs. 52–60, held after 20 s.

    The law is tabulated once on a 1 ms grid with one-sided rates at both ends of every interval
    and evaluated by cubic Hermite interpolation: error ≈ h⁴·max|L⁗|/384 ≈ 1e-15 m, exact at the
    grid points, and the rate jump of the law at t = 10 s falls on a grid point. Evaluating the
    vectorized law for one time costs ~200 µs of numpy overhead; the table costs ~2 µs.
    """

    n_actuators = 6
    grid_step = 1e-3

    def __init__(self, spec: CommandProgramSpec):
        from .mechanisms import stewart

        self._stewart = stewart
        self.start = spec.start
        self.blend_time = spec.blend_time
        self.geometry = stewart.StewartGeometry.default()
        self.lengths0 = self.geometry.layout().lengths0
        self.t_end = stewart.T_END
        n = int(round(self.t_end / self.grid_step))
        self._grid = np.linspace(0.0, self.t_end, n + 1)
        eps = 1e-9
        law = lambda t: stewart.appendix_leg_lengths(np.clip(t, 0.0, self.t_end), self.geometry,  # noqa: E731
                                                     start=self.start, blend_time=self.blend_time)
        self._values, _ = law(self._grid)                          # (n+1, 6)
        _, self._rate_right = law(self._grid[:-1] + eps)           # rate at the start of interval i
        _, self._rate_left = law(self._grid[1:] - eps)             # rate at the end of interval i
        self._t = np.zeros(1)

    def lengths(self, t: float) -> np.ndarray:
        """Commanded lengths (m) of the six legs at ``t`` (s)."""
        if t >= self.t_end:
            return self._values[-1].copy()
        if t <= 0.0:
            return self._values[0].copy()
        h = self.grid_step
        i = min(int(t / h), self._grid.size - 2)
        s = (t - self._grid[i]) / h
        s2, s3 = s * s, s * s * s
        return ((2 * s3 - 3 * s2 + 1) * self._values[i] + (s3 - 2 * s2 + s) * h * self._rate_right[i]
                + (-2 * s3 + 3 * s2) * self._values[i + 1] + (s3 - s2) * h * self._rate_left[i])

    def exact_lengths(self, t: float) -> np.ndarray:
        """The law evaluated directly (reference for the table)."""
        self._t[0] = min(max(t, 0.0), self.t_end)
        lengths, _ = self._stewart.appendix_leg_lengths(self._t, self.geometry, start=self.start,
                                                        blend_time=self.blend_time)
        return lengths[0]

    def reference_pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Commanded platform centroid (m) and orientation (w, x, y, z) at ``t`` (s)."""
        self._t[0] = min(max(t, 0.0), self.t_end)
        p, quat = self._stewart.appendix_platform_outputs(self._t, self.geometry, start=self.start,
                                                          blend_time=self.blend_time)
        return p[0], quat[0]


PROGRAMS = {"stewart_appendix": StewartAppendixProgram}


def build_program(spec: CommandProgramSpec, l0: np.ndarray, where: str):
    """Instantiate the program and check it against the scene's actuators (count, lengths)."""
    prog = PROGRAMS[spec.program](spec)
    if len(spec.actuators) != prog.n_actuators:
        raise SceneError(where, f"program '{spec.program}' drives {prog.n_actuators} actuators, "
                                f"got {len(spec.actuators)}: {list(spec.actuators)}")
    if not np.allclose(prog.lengths0, l0, rtol=1e-9, atol=0.0):
        raise SceneError(where, f"program '{spec.program}' starts from lengths {prog.lengths0.tolist()} m "
                                f"but the scene's actuators measure {l0.tolist()} m: the scene geometry "
                                "must match the program's")
    return prog
