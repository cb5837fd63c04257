"""``flexmb run SCENE --rrd OUT``: log the offline run into a rerun recording.

The hook reads the solver through :class:`~flexmb_core.report.TwinReporter` (as the ROS node and
the MCAP recorder do) every ``period`` of simulated time, and always at the first and last state.
"""

from __future__ import annotations

import math

from flexmb_core.errors import FlexmbError

DEFAULT_PERIOD = 0.01     # s of simulated time between logged states (100 frames per simulated second)


class RerunRunHook:
    """A ``flexmb run`` hook: ``start(sim)``, ``step(sim, result)``, ``close(sim, summary)``.

    Parameters
    ----------
    model
        The compiled model being run.
    path
        The ``.rrd`` file to write.
    period
        Simulated time between logged states (s); ≤ 0 logs every step.
    """

    def __init__(self, model, path: str, period: float = DEFAULT_PERIOD):
        from flexmb_core.report import TwinReporter

        from ..shells import ShellShapes
        from .rerun_log import TwinRerunLogger

        self.path = str(path)
        self.period = float(period)
        self.reporter = TwinReporter(model)
        self.shells = ShellShapes(model)
        self.logger = TwinRerunLogger(model, rrd_path=self.path)
        self._next = 0.0
        self._t_last = 0.0             # sim time of the last logged state (s)
        self._wall_last = 0.0          # solver wall time at that state (s)
        self._solver_wall = 0.0        # solver wall time after the previous step (s)
        self._logged_t = None
        self._step_wall: float | None = None   # wall time of the newest step (s)

    def start(self, sim) -> None:
        self.logger.log_static()
        self._log(sim, None)

    def step(self, sim, res) -> None:
        wall = sim.stats.wall_time_s
        step_wall = wall - self._solver_wall           # this step alone: the solver's own clock
        self._solver_wall = wall
        self._step_wall = step_wall
        t = sim.state.t
        # a relative tolerance keeps 0.01, 0.02, ... from being missed by one ulp of summed dt
        if self.period <= 0 or t >= self._next - 1e-9 * max(1.0, abs(self._next)):
            self._log(sim, step_wall)

    def close(self, sim, summary: dict) -> None:
        # always the final state, even after a failed or interrupted run
        if self._logged_t != sim.state.t:
            self._log(sim, self._step_wall)
        self.logger.close()
        summary["rrd"] = self.path

    def _log(self, sim, step_wall: float | None) -> None:
        t = sim.state.t
        wall = sim.stats.wall_time_s
        status = {}
        if step_wall is not None:
            status["step_wall_time"] = step_wall
        if wall > self._wall_last and t > self._t_last:
            status["real_time_factor"] = (t - self._t_last) / (wall - self._wall_last)
        sample = self.reporter.read(sim)
        self.shells.read(sim.state.q)
        self.logger.log_sample(sample, status, self.shells)
        self._t_last, self._wall_last, self._logged_t = t, wall, t
        if self.period > 0:
            # next multiple of the period after t (a product, not a running sum: no drift)
            self._next = (math.floor(t / self.period + 1e-6) + 1) * self.period


def make_hook(args, scene, model) -> RerunRunHook | None:
    """``add_run_hook`` factory: a hook when ``--rrd`` is given, else None."""
    path = getattr(args, "rrd", None)
    if not path:
        return None
    period = getattr(args, "rrd_period", DEFAULT_PERIOD)
    if not (math.isfinite(period) and period >= 0):
        raise FlexmbError(f"--rrd-period must be a time ≥ 0 s (0: every step), got {period}")
    return RerunRunHook(model, path, period)
