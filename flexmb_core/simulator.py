"""The facade: ``Simulator(model)`` → ``initialize()`` → ``step()`` / ``run()``.

It owns the :class:`~flexmb_core.model.step_data.StepData` (the run's one mutable object; its
:class:`State` is ``sim.state``), the :class:`Workspace` and the integrator, evaluates actuator
commands (scene signals, or lengths set from outside with :meth:`set_commands`) and keeps
solver statistics. It never prints.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .errors import ConvergenceError, FlexmbError, SceneError
from .integrators.dynamic import DynamicIntegrator
from .integrators.fast import TABLE_STEPS
from .integrators.static import StaticSolver
from .model.assembly import assemble
from .model.model import Model
from .model.step_data import StepData
from .model.workspace import Workspace
from .observers import evaluate_output
from .scene.schema import SolverSpec
from .servo import Servo
from .signals import evaluate
from .solvers.result import StepResult


@dataclass
class RunStats:
    """Counters over a run (what ``flexmb run --json`` reports)."""

    steps: int = 0
    iterations_total: int = 0       # Newton iterations summed over the steps (a node runs for hours:
    iterations_max: int = 0         # counters, not a list that grows by one entry per step)
    unconverged_steps: int = 0
    substepped_steps: int = 0
    guard_rejected_steps: int = 0     # steps in which the step guard refused a Newton root
    wall_time_s: float = 0.0
    max_residual: float = 0.0


class Simulator:
    """Time stepping of one compiled model."""

    def __init__(self, model: Model, spec: SolverSpec | None = None):
        self.model = model
        self.spec = spec or model.scene.solver
        self.ws = Workspace(model)
        # the one mutable object of the run (state, stretch history, held tangent, guard ledger);
        # ``state`` is its view, what a rollback restores is ``data`` (StepData.copy / assign)
        self.data = StepData(model)
        self.state = self.data.state
        self._override: np.ndarray | None = None
        act = model.actuators
        driven = set(model.program_index.tolist())
        self._signal_actuators = [(i, s) for i, s in enumerate(act.commands) if s is not None and i not in driven]
        self._lengths = act.l0.copy()            # actuators with neither signal nor program hold L0
        self._program_buf = np.zeros(model.program_index.size)
        self._lam_table: np.ndarray | None = None    # (TABLE_STEPS, na): batched steps' stretches
        # actuator servos (flexmb_core.servo): dynamics only — a static solve takes their steady
        # state, the commanded length itself
        self._servo = Servo(act.servo) if act.servo is not None and self.spec.analysis != "static" else None
        self._servo_u = np.zeros(0 if act.servo is None else act.servo.size)
        self.last_commands = act.l0.copy()       # (na,) m: commanded lengths of the last step, before any servo
        self.stats = RunStats()
        self.last: StepResult | None = None
        if self.spec.analysis == "static":
            self._static = StaticSolver(model, self.ws, self.spec)
            self._dynamic = None
        else:
            self._dynamic = DynamicIntegrator(model, self.ws, self.spec, self.data)
            self._static = None

    # -- commands -------------------------------------------------------------------------
    def command_lengths(self, t: float) -> np.ndarray:
        """Commanded actuator lengths (m) at ``t``: the external override if set, else the scene."""
        if self._override is not None:
            return self._override.copy()
        return self._scene_lengths(t).copy()

    def _scene_lengths(self, t: float) -> np.ndarray:
        """The scene's commanded lengths (m) at ``t`` into the reused buffer ``_lengths`` (returned:
        copy it to keep it)."""
        lengths = self._lengths
        for i, s in self._signal_actuators:
            lengths[i] = evaluate(s, t)
        if self.model.program is not None:
            lengths[self.model.program_index] = self.model.program.lengths(t, self._program_buf)
        return lengths

    def set_commands(self, lengths: np.ndarray | None, check: bool = True) -> None:
        """Hold these lengths (m, one per actuator, scene order) from now on; ``None`` → scene signals.

        ``check=False`` skips the validation, for callers that validated already (the twin node's
        command schedule, at every step)."""
        if lengths is None:
            self._override = None
            return
        if not check and self._override is not None:
            self._override[:] = lengths
            return
        lengths = np.asarray(lengths, dtype=float)
        act = self.model.actuators
        if lengths.shape != act.l0.shape:
            raise FlexmbError(f"expected {act.l0.size} actuator lengths ({list(act.names)}), got shape {lengths.shape}")
        if not np.all(np.isfinite(lengths)) or np.any(lengths <= 0):
            raise FlexmbError(f"actuator lengths must be finite and positive, got {lengths.tolist()}")
        self._override = lengths.copy()

    # -- stepping -------------------------------------------------------------------------
    def warmup(self) -> float:
        """Compile (or load from cache) every kernel this model uses; returns seconds spent."""
        t0 = time.perf_counter()
        st = self.state.copy()
        assemble(self.model, self.ws, st.q, st.lam, True)
        assemble(self.model, self.ws, st.q, st.lam, False)
        from .observers import actuator_forces
        if self.model.actuators.l0.size:
            actuator_forces(self.model, self.ws, st)
        if self._dynamic is not None:
            self._dynamic.warmup(st)
        return time.perf_counter() - t0

    def initialize(self) -> StepResult:
        """Apply the commands at t = 0 and (dynamics) compute the initial acceleration.

        With ``initial_state: static`` a dynamic run starts from the static equilibrium at t0
        (gravity and loads carried, at rest) instead of the unloaded reference geometry, so the
        twin does not begin by dropping its own weight.
        """
        lengths = self.command_lengths(self.state.t)
        if self._override is None:
            self._check_scene_lengths(lengths, self.state.t)
        self.last_commands[:] = lengths
        servo = self.model.actuators.servo
        if servo is not None:             # servos start at rest on their commanded lengths
            self.state.servo_x[:] = lengths[servo.index]
            self.state.servo_v[:] = 0.0
        self.state.lam[:] = lengths / self.model.actuators.l0
        if self._dynamic is not None:
            if self.spec.initial_state == "static":
                pre = StaticSolver(self.model, self.ws, self.spec).solve_at(self.state, self.state.t,
                                                                             self.state.lam)
                if not pre.converged:
                    raise ConvergenceError(f"initial static equilibrium did not converge: {pre.message}", pre)
                self.state.v[:] = 0.0
            self.last = self._dynamic.initialize(self.state)
        else:
            self.last = self._static.solve_at(self.state, self.state.t, self.state.lam)
        return self.last

    def _check_scene_lengths(self, lengths: np.ndarray, t: float) -> None:
        """A scene whose commands give an actuator no positive finite length at the start is bad
        input naming the command's key (the elements divide by the length: a traceback otherwise)."""
        bad = np.flatnonzero(~(np.isfinite(lengths) & (lengths > 0.0)))
        if bad.size:
            i = int(bad[0])
            name = self.model.actuators.names[i]
            key = "commands" if i in set(self.model.program_index.tolist()) else f"members.{name}.actuator.command"
            raise SceneError(f"{self.model.scene.source}:{key}",
                             f"actuator '{name}' is commanded to {float(lengths[i]):.6g} m at t = {t:g} s; "
                             "expected a positive, finite length (m)")

    def step(self, dt: float | None = None) -> StepResult:
        """Advance by ``dt`` (default: the scene's). Raises :class:`ConvergenceError` when the
        step fails and the policy is ``stop`` or ``substep``; ``accept_flagged`` returns the flagged result."""
        dt = self.spec.dt if dt is None else dt
        t_new = self.state.t + dt
        if not self._lengths.size:
            lam = self._lengths
        elif self._servo is None:
            lam = self.command_lengths(t_new) / self.model.actuators.l0
        else:
            lam = self._servo_lengths(self.command_lengths(t_new), dt) / self.model.actuators.l0
        t0 = time.perf_counter()
        if self._dynamic is not None:
            res = self._dynamic.step(self.state, dt, lam)
        else:
            res = self._static.solve_at(self.state, t_new, lam)
        self.stats.wall_time_s += time.perf_counter() - t0
        return self._account(res, t_new)

    def _account(self, res: StepResult, t_new: float) -> StepResult:
        """Count the step to ``t_new`` (s) that gave ``res`` in the statistics; raise as
        :meth:`step` documents when it failed."""
        self.stats.steps += 1
        self.stats.iterations_total += res.iterations
        self.stats.iterations_max = max(self.stats.iterations_max, res.iterations)
        if res.substeps > 1:
            self.stats.substepped_steps += 1
        if res.guard:
            self.stats.guard_rejected_steps += 1
        self.last = res
        if not res.converged:
            self.stats.unconverged_steps += 1
            if self.spec.on_unconverged != "accept_flagged":
                raise ConvergenceError(f"step to t = {t_new:.6g} s did not converge: {res.message}", res)
        else:
            self.stats.max_residual = max(self.stats.max_residual, res.residual)
        return res

    def _servo_lengths(self, lengths: np.ndarray, dt: float) -> np.ndarray:
        """The servos' outputs at the end of this step in place of their commanded ``lengths (na,)``
        (m); the servo state in :attr:`state` advances (a rejected step restores it with the state)."""
        self.last_commands[:] = lengths
        idx = self.model.actuators.servo.index
        np.take(lengths, idx, out=self._servo_u)
        self._servo.advance(self._servo_u, self.state.servo_x, self.state.servo_v, dt)
        lengths[idx] = self.state.servo_x
        return lengths

    def run(self, until: float, dt: float | None = None,
            callback: Callable[["Simulator", StepResult], None] | None = None, every: int = 1) -> RunStats:
        """Step until ``t ≥ until`` (the last step is shortened to land on it); ``callback(sim,
        result)`` after every ``every``-th step of this call and after the last one.

        Between callbacks, the steps of a dynamic run without servos and driven supports run in
        one numba call per batch of them (:meth:`DynamicIntegrator.steps`): when the commands do
        not change (no actuators, or lengths held by :meth:`set_commands`), all the steady ones
        once the loads no longer change; otherwise 256 at a time, their loads (without moment
        loads) and the scene's commanded lengths formed beforehand, as :meth:`step` forms them.
        The same arithmetic, results and statistics as step by step, without the Python of each
        step's call. With a callback at every step (``every=1``) every step is a call of its own."""
        if not (isinstance(every, (int, np.integer)) and every >= 1):
            raise ValueError(f"every must be a whole number of steps ≥ 1, got {every!r}")
        dt = self.spec.dt if dt is None else dt
        end = until - 1e-12 * max(1.0, until)
        start = self.stats.steps
        while self.state.t < end:
            count = 0
            if callback is None:
                count = self._batch_steps(until, dt)
            elif every > 1:                    # a batch ends at the next callback's step
                count = min(self._batch_steps(until, dt), every - (self.stats.steps - start) % every)
            if count >= 2:
                self._run_batch(count, dt)
            else:
                self.step(min(dt, until - self.state.t))
            if callback is not None and ((self.stats.steps - start) % every == 0 or self.state.t >= end):
                callback(self, self.last)
        return self.stats

    def _steady_lam(self) -> np.ndarray | None:
        """The stretches every coming step commands, when they no longer change: no actuators,
        or lengths held by :meth:`set_commands` and no servos; else None."""
        if not self._lengths.size:
            return self._lengths
        if self._override is not None and self._servo is None:
            return self._override / self.model.actuators.l0
        return None

    def _batch_steps(self, until: float, dt: float) -> int:
        """How many whole steps ``dt`` towards ``until`` may run in one call (0: step by step).
        One step short of ``until``: the last, maybe shortened one, goes step by step. Servos
        advance in Python at every step: their runs go step by step."""
        if self._dynamic is None or self._servo is not None or not self._dynamic.fast.batches(self.state.t):
            return 0
        count = int((until - self.state.t) / dt) - 1
        if self._steady_lam() is None:       # the scene's commands: their lengths tabulated
            count = min(count, TABLE_STEPS)
        return count if count >= 2 else 0

    def _command_table(self, count: int, dt: float) -> np.ndarray:
        """``(count, na)``: the stretches that :meth:`step` would command in each of the next
        ``count`` steps ``dt`` (the same times, calls and divisions; the scene's commands: no
        override, see :meth:`_batch_steps`), into a table allocated once."""
        if self._lam_table is None:
            self._lam_table = np.zeros((TABLE_STEPS, self._lengths.size))
        table = self._lam_table[:count]
        l0 = self.model.actuators.l0
        t = self.state.t
        for k in range(count):       # t advances as the step advances it: t_n + dt
            t = t + dt
            np.divide(self._scene_lengths(t), l0, out=table[k])
        return table

    def _run_batch(self, count: int, dt: float) -> None:
        """Up to ``count`` steps ``dt`` in one call (:meth:`DynamicIntegrator.steps`), counted as
        :meth:`step` counts them."""
        lam = self._steady_lam()
        if lam is None:
            lam = self._command_table(count, dt)
        t0 = time.perf_counter()
        done, res, tally, settled = self._dynamic.steps(self.state, dt, lam, count)
        self.stats.wall_time_s += time.perf_counter() - t0
        st = self.stats
        st.steps += done
        st.iterations_total += int(tally[1])
        st.iterations_max = max(st.iterations_max, int(tally[2]))
        if done:
            st.max_residual = max(st.max_residual, float(tally[3]))
        if settled:     # the step whose attempt failed, settled by the policy
            self._account(res, self.state.t + dt)
        else:
            self.last = res

    # -- outputs --------------------------------------------------------------------------
    def energy(self) -> dict:
        r = self.last
        if r is None:
            return {}
        return {"kinetic": r.kinetic, "strain": r.strain, "gravity": r.gravity, "total": r.total_energy}

    def outputs(self) -> dict:
        """Current values of every output the scene declares."""
        e = self.energy()
        return {o.name: evaluate_output(self.model, self.ws, self.state, o, e) for o in self.model.scene.outputs}

    def summary(self) -> dict:
        """Run statistics with the JSON keys of ``flexmb run --json``."""
        st = self.stats
        wall = self.stats.wall_time_s
        return {
            "steps": self.stats.steps,
            "sim_time_s": self.state.t,
            "wall_time_s": wall,
            "rtf": (self.state.t / wall) if wall > 0 else math.inf,
            "steps_per_s": (self.stats.steps / wall) if wall > 0 else math.inf,
            "newton_iterations_mean": st.iterations_total / st.steps if st.steps else 0.0,
            "newton_iterations_max": st.iterations_max,
            "unconverged_steps": self.stats.unconverged_steps,
            "substepped_steps": self.stats.substepped_steps,
            "guard_rejected_steps": self.stats.guard_rejected_steps,
            "max_relative_residual": self.stats.max_residual,
        }
