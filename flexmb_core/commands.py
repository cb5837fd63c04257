"""Command programs: generators of actuator lengths that a scene names (``commands:`` block).

A program drives several actuators together (e.g. the six legs of the Stewart appendix law) and
is evaluated once per step for all of them. Per-actuator ``command`` signals cover the simple cases;
an external source (the ROS node, ``Simulator.set_commands``) overrides both.
"""

from __future__ import annotations

import numpy as np

from numba import njit

from .errors import SceneError
from .jit import KERNEL
from .scene.schema import CommandProgramSpec


@njit(**KERNEL)
def hermite_row(values, rate_right, rate_left, h, t, out):
    """Cubic Hermite interpolation of a table on the uniform grid k·h (one row per grid point,
    one-sided rates per interval), held constant outside; result into ``out``."""
    n = values.shape[0]
    if t <= 0.0 or t >= (n - 1) * h:
        k = 0 if t <= 0.0 else n - 1
        for j in range(values.shape[1]):    # a loop, not out[:] = …: a slice copy allocates
            out[j] = values[k, j]
        return
    i = min(int(t / h), n - 2)
    s = (t - i * h) / h
    s2 = s * s
    s3 = s2 * s
    h00 = 2 * s3 - 3 * s2 + 1
    h10 = (s3 - 2 * s2 + s) * h
    h01 = -2 * s3 + 3 * s2
    h11 = (s3 - s2) * h
    for j in range(values.shape[1]):
        out[j] = (h00 * values[i, j] + h10 * rate_right[i, j] + h01 * values[i + 1, j]
                  + h11 * rate_left[i, j])


class StewartAppendixProgram:
    """Leg lengths of Siqueira & Coda (2019), appendix Eqs. 52–60, held after 20 s.

    The law is tabulated once on a 1 ms grid with one-sided rates at both ends of every interval
    and evaluated by cubic Hermite interpolation: error ≈ h⁴·max|L⁗|/384 ≈ 1e-15 m, exact at the
    grid points, and the rate jump of the exact law at t = 10 s falls on a grid point. Evaluating the
    vectorized law for one time costs ~200 µs of numpy overhead; the table costs ~2 µs.

    ``spec.switch_blend = T > 0`` blends the t = 10 s branch switch (over [10 − T/2, 10 + T/2], see
    :mod:`flexmb_core.mechanisms.stewart`); 0 keeps the exact law's rate jump. ``spec.blend_continuity``
    (2, 3, 4) makes both blends C^k. With the window ends on the grid (T/2 a multiple of 1 ms) the
    table stays within 1e-11 m of the law (~1e-10 m otherwise).
    """

    n_actuators = 6
    grid_step = 1e-3

    def __init__(self, spec: CommandProgramSpec):
        from .mechanisms import stewart

        self._stewart = stewart
        self._law_options = dict(start=spec.start, blend_time=spec.blend_time, switch_blend=spec.switch_blend,
                                 blend_continuity=spec.blend_continuity)
        self.start = spec.start
        self.blend_time = spec.blend_time
        self.switch_blend = spec.switch_blend
        self.geometry = stewart.StewartGeometry.default()
        self.lengths0 = self.geometry.layout().lengths0
        self.t_end = stewart.T_END
        n = int(round(self.t_end / self.grid_step))
        self._grid = np.linspace(0.0, self.t_end, n + 1)
        eps = 1e-9
        law = lambda t: stewart.appendix_leg_lengths(np.clip(t, 0.0, self.t_end), self.geometry,  # noqa: E731
                                                     **self._law_options)
        self._values, _ = law(self._grid)                          # (n+1, 6)
        _, self._rate_right = law(self._grid[:-1] + eps)           # rate at the start of interval i
        _, self._rate_left = law(self._grid[1:] - eps)             # rate at the end of interval i
        self._rate_right = np.ascontiguousarray(self._rate_right)
        self._rate_left = np.ascontiguousarray(self._rate_left)
        self._values = np.ascontiguousarray(self._values)
        self._t = np.zeros(1)

    def lengths(self, t: float, out: np.ndarray | None = None) -> np.ndarray:
        """Commanded lengths (m) of the six legs at ``t`` (s), into ``out`` if given."""
        out = np.empty(6) if out is None else out
        hermite_row(self._values, self._rate_right, self._rate_left, self.grid_step, t, out)
        return out

    def exact_lengths(self, t: float) -> np.ndarray:
        """The law evaluated directly (reference for the table)."""
        self._t[0] = min(max(t, 0.0), self.t_end)
        lengths, _ = self._stewart.appendix_leg_lengths(self._t, self.geometry, **self._law_options)
        return lengths[0]

    def exact_rates(self, t: float) -> np.ndarray:
        """Leg-length rates (m/s) of the law at ``t`` (zero after the law ends)."""
        if t > self.t_end:
            return np.zeros(6)
        self._t[0] = min(max(t, 0.0), self.t_end)
        _, rates = self._stewart.appendix_leg_lengths(self._t, self.geometry, **self._law_options)
        return rates[0]

    def reference_pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Commanded platform centroid (m) and orientation (w, x, y, z) at ``t`` (s)."""
        self._t[0] = min(max(t, 0.0), self.t_end)
        p, quat = self._stewart.appendix_platform_outputs(self._t, self.geometry, **self._law_options)
        return p[0], quat[0]

    def reference_poses(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`reference_pose` at many times in one call: ``t`` shape (n,) s → centroids (n, 3) m
        and orientations (n, 4) (w, x, y, z). One call costs about what one time does (~0.1 ms of
        NumPy overhead), so a client that checks poses as they come keeps them and compares them at
        the end."""
        ts = np.clip(np.asarray(t, dtype=float).ravel(), 0.0, self.t_end)
        return self._stewart.appendix_platform_outputs(ts, self.geometry, **self._law_options)


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
