"""Path following in statics: arc length (Crisfield) and displacement control.

Every load of the scene (forces, gravity, edge forces, moments) is its constant value times the
load factor λ, an unknown: equilibrium is ``R(x, λ) = r(q; λ) − λ f_ref = 0`` with
``x = [q_free, multipliers] (nsys,)``. One more equation closes the system:

- **arc length** (``control: arc_length``), Crisfield's constraint on the increment of a step
  from the converged (x_n, λ_n): cylindrical ``‖Δu‖² = Δl²``, spherical
  ``‖Δu‖² + ψ² Δλ² ‖u₁‖² = Δl²``. ``Δu`` is the increment of the free nodal **positions** (m;
  section vectors, directors and multipliers are left out so that Δl is a length), ``u₁`` the
  linear displacement per unit load factor at the start (so ψ is dimensionless);
- **displacement control** (``control: displacement``): one displacement component of a node
  is prescribed, stepped to ``solver.displacement.to``.

Each Newton iteration (all of them in one numba call per attempted step,
:func:`~.path_step.path_correct`) factors the tangent K once and solves for two right-hand sides,
``δx_R = −K⁻¹R`` and ``δx_t = K⁻¹ p`` with ``p = −∂R/∂λ`` (the reference load minus the
configuration-dependent moment loads per unit λ); the correction is ``δx = δx_R + δλ δx_t``.
For the arc length δλ is a root of the quadratic constraint; the root kept is the one whose new
increment makes the smallest angle with the previous one (which turns the path at limit points
and follows snap-backs). A negative discriminant or no convergence in ``max_iterations`` halves
the step and retries from x_n, down to the step's ``min``. The predictor is the tangent
``Δx = Δλ δx_t``; its sign follows the previous increment (Feng's criterion: not the sign of
det K, which fails at bifurcations). Steps adapt to the path's curvature: after a step done in
``i`` iterations the next is scaled by √(target_iterations / i), within [½, 2]× and
[``min``, ``max``].

After every step the tangent at the converged state is factored once more; its negative pivots
(counted by the same LU) (:mod:`flexmb_core.integrators.critical`): limit points and bifurcations.

The pseudo-time of a path-following run is the increment count (``state.t = k``) so recorders
see a monotonic clock; the load factor is reported beside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..errors import ConvergenceError, SceneError
from ..model.assembly import apply_drives, assemble
from ..model.model import Model
from ..scene.schema import DofComponent, PathStepSpec, Scene
from ..solvers.result import StepResult
from .critical import PathPoint, TangentLU, classify
from .energy import gravity_potential
from .fast import NON_FINITE_INCREMENT, NON_FINITE_RESIDUAL, OK, SINGULAR
from .packs import singular_note
from .path_step import (ARC, FIXED, N_PO, NO_RESPONSE, NO_ROOT, PO_DISC, PO_INC, PO_IT, PO_LAM, PO_OMEGA,
                        load_direction, path_correct)

if TYPE_CHECKING:
    from ..simulator import Simulator

_AXES = {"x": 0, "y": 1, "z": 2}
_GROWTH = (0.5, 2.0)          # bounds of the step's change factor after a converged step


def check_path_scene(scene: Scene) -> None:
    """Path following scales the loads by λ in place of time: every load signal, actuator
    command and drive must be constant (``SceneError`` at the offending key otherwise)."""
    src = scene.source

    def need_constant(sig, key: str, what: str) -> None:
        if sig is not None and sig.kind != "constant":
            raise SceneError(f"{src}:{key}", f"control: {scene.solver.control} scales {what} by the load "
                                             f"factor; its signal must be constant, got kind '{sig.kind}'")

    for f in scene.forces:
        need_constant(f.signal, f"loads.forces.{f.name}.signal", "every load")
    for m in scene.moments:
        need_constant(m.signal, f"loads.moments.{m.name}.signal", "every load")
    for e in scene.edge_loads:
        need_constant(e.signal, f"loads.edge_{e.kind}s.{e.name}.signal", "every load")
    if scene.gravity is not None:
        need_constant(scene.gravity.signal, "loads.gravity.signal", "every load")
    for name, mem in scene.members.items():
        if mem.actuator is not None:
            need_constant(mem.actuator.command, f"members.{name}.actuator.command", "the loads and holds actuators")
    if scene.commands is not None:
        raise SceneError(f"{src}:commands", f"control: {scene.solver.control} holds actuators at constant "
                                            "lengths; a command program moves them in time")
    for i, s in enumerate(scene.supports):
        need_constant(s.angle, f"supports[{i}].rotation.angle", "the loads and holds drives")
        need_constant(s.distance, f"supports[{i}].translation.distance", "the loads and holds drives")


def position_mask(model: Model) -> np.ndarray:
    """``(nsys,)`` bool: the system unknowns that are free nodal positions (members and shells)."""
    full = np.zeros(model.ndof, dtype=bool)
    for mi in model.members:
        full[mi.ydofs.ravel()] = True
    for sh in model.shells:
        full[sh.ydofs.ravel()] = True
    return np.concatenate([full[model.free], np.zeros(model.n_multipliers, dtype=bool)])


def dof_index(model: Model, dof: DofComponent) -> int:
    """Global DOF id of a node's displacement component."""
    return int(model.node_ydofs[model.node(dof.node), _AXES[dof.component]])


class PathLoads:
    """The loads at load factor λ on a workspace: ``f_ext = λ f_ref`` and moment scales λ·s⁰."""

    def __init__(self, model: Model, ws):
        self.model, self.ws = model, ws
        self._s0 = np.array([s.value for s in model.load_signals], dtype=float)
        self._fol0 = np.array([s.value for s in model.moments.follower_signals], dtype=float)
        self._cons0 = np.array([s.value for s in model.moments.cons_signals], dtype=float)
        f_ref = np.zeros(model.ndof)
        if model.load_vectors.shape[0]:
            f_ref += self._s0 @ model.load_vectors
        f_ref += model.gravity_signal.value * model.gravity_vector
        self.f_ref = f_ref                          # (ndof,) N, dead loads per unit λ
        self._p = np.zeros(model.ndof)
        self._kdummy = np.zeros(0)

    def set(self, lam: float) -> None:
        ws = self.ws
        np.multiply(self._s0, lam, out=ws.load_scale)
        np.multiply(self._fol0, lam, out=ws.follower_scale)
        np.multiply(self._cons0, lam, out=ws.cons_scale)
        np.multiply(self.f_ref, lam, out=ws.f_ext)

    def direction(self, q: np.ndarray) -> np.ndarray:
        """``p = −∂R/∂λ (ndof,)`` at ``q`` (:func:`~.path_step.load_direction`, the corrector's own)."""
        m = self.model.moments
        load_direction(q, self.f_ref, self._fol0, self._cons0, m.follower_vdofs, m.follower_mbody, m.follower_smap,
                       m.cons_vdofs, m.cons_axes, m.cons_magnitude, m.cons_smap, False, self._p, self._kdummy)
        return self._p.copy()


@dataclass
class _Attempt:
    converged: bool
    iterations: int
    increment: float
    message: str = ""


class PathFollower:
    """Traces the equilibrium path of a static scene with ``control: arc_length|displacement``.

    Drives a :class:`~flexmb_core.simulator.Simulator` built for the scene (its model, workspace,
    state and run statistics): :meth:`initialize`, then :meth:`step` or :meth:`run`.

    Attributes
    ----------
    lam : float — load factor of the current state.
    points : list[PathPoint] — every converged state, the start included.
    step_length : float — the next increment (m of arc length or of the controlled displacement).
    """

    def __init__(self, sim: "Simulator"):
        self.sim = sim
        model, spec = sim.model, sim.spec
        self.model, self.spec, self.ws, self.state = model, spec, sim.ws, sim.state
        if spec.analysis != "static" or spec.control not in ("arc_length", "displacement"):
            raise ValueError(f"PathFollower needs analysis: static with control arc_length or displacement, "
                             f"got {spec.analysis}/{spec.control}")
        check_path_scene(model.scene)
        self.arc = spec.control == "arc_length"
        self.steps: PathStepSpec = spec.arc_length.step if self.arc else spec.displacement.step
        self.psi2 = spec.arc_length.psi ** 2 if self.arc and spec.arc_length.kind == "spherical" else 0.0
        self.loads = PathLoads(model, self.ws)
        self.lu = TangentLU(model)            # factors, solves and counts negative pivots at each point
        self.w = position_mask(model)
        # the corrector runs in one numba call (path_step.py) on the static Newton's packs and LU
        self._packs, self._sky = sim._static.fast.packs, sim._static.lu.skyline
        self._wmask = np.ascontiguousarray(self.w[:model.nfree], dtype=np.float64)
        self._rm = np.zeros(model.ndof)
        self._d_t = np.zeros(model.nsys)
        self._dx_start = np.zeros(model.nsys)
        self._io = np.zeros(N_PO)
        nf, n = model.nfree, model.nsys
        self._inv_scale = 1.0 / model.dof_scale[model.free]
        self.monitor = dof_index(model, spec.monitor) if spec.monitor is not None else -1
        self.control = -1                     # system row of the controlled displacement
        if not self.arc:
            d = spec.displacement
            gid = dof_index(model, d.dof)
            self.control = int(model.free_index[gid])
            if self.control < 0:
                raise SceneError(f"{model.scene.source}:solver.displacement",
                                 f"the {d.dof.component} displacement of node '{d.dof.node}' is held by a "
                                 f"support; displacement control needs a free component")
        self.lam = 0.0
        self.points: list[PathPoint] = []
        self.step_length = self.steps.initial
        self.finished = False
        self.reason = ""
        self._rf = np.zeros(n)
        self._pt = np.zeros(n)
        self._dt = np.zeros(n)                # K⁻¹ p at the last converged state
        self._dx = np.zeros(n)                # increment of the step under way
        self._dx_prev = np.zeros(n)           # increment of the last converged step
        self._dlam_prev = 0.0
        self._u1sq = 0.0                      # ‖u₁‖² (m²): spherical arc length's load scale
        self._lam_scale = 0.0
        self._nf = nf

    # -- system pieces ----------------------------------------------------------------------
    def _x_add(self, dx: np.ndarray) -> None:
        self.state.q[self.model.free] += dx[:self._nf]
        self.state.mult += dx[self._nf:]

    def _residual(self, lam: float, want_k: bool) -> float:
        """Assemble ``R(x, λ)`` into ``self._rf`` (and K into ``ws.kdata``); returns the strain energy."""
        m, ws, st = self.model, self.ws, self.state
        self.loads.set(lam)
        strain = assemble(m, ws, st.q, st.lam, want_k, st.mult)
        self._rf[:self._nf] = (ws.r - ws.f_ext)[m.free]
        self._rf[self._nf:] = ws.rc
        return strain

    def _tangent_direction(self) -> np.ndarray:
        """``K⁻¹ p`` with the last factorization (p padded with zeros on the multiplier rows)."""
        self._pt[:self._nf] = self.loads.direction(self.state.q)[self.model.free]
        self._pt[self._nf:] = 0.0
        return self.lu.solve(self._pt)

    def _wdot(self, a: np.ndarray, b: np.ndarray) -> float:
        return float(np.dot(a[self.w], b[self.w]))

    def _displacement(self) -> float:
        return float(self.state.q[self.monitor] - self.model.q0[self.monitor]) if self.monitor >= 0 else math.nan

    # -- start ------------------------------------------------------------------------------
    def initialize(self) -> StepResult:
        """Equilibrium at λ = 0 (actuators at their constant commands), its tangent and pivots."""
        sim, st = self.sim, self.state
        lengths = sim.command_lengths(0.0)
        st.lam[:] = lengths / self.model.actuators.l0
        st.t = 0.0
        apply_drives(self.model, st.q, 0.0)
        att = self._newton_fixed(0.0)
        if not att.converged:
            raise ConvergenceError(f"equilibrium at load factor 0 did not converge: {att.message}")
        res = self._accept(att, 0.0)
        sim.last = res
        return res

    def _newton_fixed(self, lam: float) -> _Attempt:
        """Plain Newton at a fixed load factor (the start of the path)."""
        self._dx_start[:] = 0.0
        return self._corrector(lam, 0.0, FIXED, self._dx_start)

    def _corrector(self, lam: float, dl: float, control: int, dx_acc: np.ndarray) -> _Attempt:
        """:func:`~.path_step.path_correct` from the state in hand at load factor ``lam``; the
        attempt, with ``self.lam`` at its last iterate."""
        st, ws, sky, loads, io = self.state, self.ws, self._sky, self.loads, self._io
        cf, ci, wf, wi = self._packs.packs
        lam_point = self.points[-1].lam if self.points else 0.0
        code = path_correct(st.q, st.lam, st.mult, ws.f_ext, ws.r, sky._env, sky._inv_diag, sky._stats, self._wmask,
                            dx_acc, loads.f_ref, loads._fol0, loads._cons0, self._rm, self._pt, self._d_t, lam, dl,
                            self.psi2 * self._u1sq, lam_point, self._lam_scale, control, cf, ci, wf, wi,
                            self._packs.lay, io)
        self.lam = float(io[PO_LAM])
        it, inc = int(io[PO_IT]), float(io[PO_INC])
        if code == OK:
            return _Attempt(True, it, inc)
        why = {NON_FINITE_RESIDUAL: f"non-finite residual at iteration {it}",
               NON_FINITE_INCREMENT: f"non-finite increment at iteration {it}",
               SINGULAR: f"singular tangent at iteration {it} (a non-finite pivot, or a zero matrix)",
               NO_RESPONSE: "the controlled displacement does not respond to the load",
               NO_ROOT: f"no real root of the arc-length constraint (discriminant {io[PO_DISC]:.3g})"}.get(code)
        if why is None:
            why = (f"no convergence in {self.spec.max_iterations} iterations (increment {inc:.2e})"
                   f"{singular_note(io[PO_OMEGA])}")
        return _Attempt(False, it, inc, why)

    def _accept(self, att: _Attempt, ds: float) -> StepResult:
        """Book a converged state: tangent and its direction for the next predictor, pivots, point."""
        strain = self._residual(self.lam, True)
        ref = max(np.linalg.norm(self.ws.r[self.model.free]), np.linalg.norm(self.ws.f_ext[self.model.free]), 1e-300)
        rel = float(np.linalg.norm(self._rf[:self._nf]) / ref)
        self.lu.factor(self.ws.kdata)
        n_neg = self.lu.negative_pivots
        self._dt[:] = self._tangent_direction()
        if not self.points:                   # ‖u₁‖²: the spherical constraint's load scale (m²)
            self._u1sq = max(self._wdot(self._dt, self._dt), 1e-300)
        s = (self.points[-1].s if self.points else 0.0) + ds
        dlam_ds, du_ds = self._slopes()
        self.points.append(PathPoint(len(self.points), self.lam, self._displacement(), s, att.iterations, n_neg,
                                     dlam_ds, du_ds))
        grav = gravity_potential(self.state.q, self.model.q0, self.model.gravity_vector)
        return StepResult(True, att.iterations, rel, att.increment, 1, 0.0, strain, grav)

    def _slopes(self) -> tuple[float, float]:
        """dλ/ds and du/ds of the path at the converged state, in the direction of travel (the
        tangent ``self._dt`` oriented like the increment that arrived here; forward at the start)."""
        dt = self._dt
        c2 = self.psi2 * self._u1sq
        norm = math.sqrt(self._wdot(dt, dt) + c2)
        if not norm > 0.0:
            return math.nan, math.nan
        sign = 1.0
        if self.points:
            dlam = self.lam - self.points[-1].lam
            sign = 1.0 if self._wdot(self._dx, dt) + c2 * dlam >= 0.0 else -1.0
        dlam_ds = sign / norm
        row = int(self.model.free_index[self.monitor]) if self.monitor >= 0 else -1
        return dlam_ds, (dlam_ds * dt[row] if row >= 0 else (0.0 if self.monitor >= 0 else math.nan))

    # -- one increment ----------------------------------------------------------------------
    def step(self) -> StepResult:
        """One converged increment of the path (halving the step after a failure, down to
        ``min``); an unconverged result leaves the state at the last converged point."""
        q0, m0, lam0 = self.state.q.copy(), self.state.mult.copy(), self.lam
        iters, tries, last = 0, 0, ""
        while True:
            tries += 1
            dl = self._bounded_step()
            att = self._attempt(dl)
            iters += att.iterations
            if att.converged:
                break
            self.state.q[:], self.state.mult[:], self.lam = q0, m0, lam0
            last = att.message
            if self.step_length <= self.steps.min * (1.0 + 1e-12):
                res = StepResult(False, iters, math.nan, att.increment, tries,
                                 message=f"no converged increment down to the minimum step "
                                         f"{self.steps.min:.3g} m: {last}")
                self.sim.last = res
                return res
            self.step_length = max(0.5 * self.step_length, self.steps.min)
        self._dx_prev[:] = self._dx
        self._dlam_prev = self.lam - lam0
        if self._lam_scale == 0.0:
            self._lam_scale = abs(self._dlam_prev)
        ds = math.sqrt(self._wdot(self._dx, self._dx) + self.psi2 * self._u1sq * self._dlam_prev ** 2)
        att.iterations = iters
        res = self._accept(att, ds)
        res.substeps = tries
        if tries > 1:
            res.message = f"step cut {tries - 1} time(s) after: {last}"
        self.state.t = float(len(self.points) - 1)
        self._adapt(att.iterations if tries == 1 else self.spec.max_iterations)
        self._check_goals()
        self.sim.last = res
        return res

    def _bounded_step(self) -> float:
        """The increment to try: for displacement control, cut to land on ``to``."""
        dl = self.step_length
        if not self.arc:
            left = abs(self.spec.displacement.to - self._controlled())
            dl = min(dl, left)
        return dl

    def _controlled(self) -> float:
        gid = self.model.free[self.control]
        return float(self.state.q[gid] - self.model.q0[gid])

    def _adapt(self, iterations: int) -> None:
        st = self.steps
        factor = min(max(math.sqrt(st.target_iterations / max(iterations, 1)), _GROWTH[0]), _GROWTH[1])
        self.step_length = min(max(self.step_length * factor, st.min), st.max)

    def _attempt(self, dl: float) -> _Attempt:
        """Predictor + corrector of one increment of size ``dl``; on success the state and
        ``self.lam`` hold the new point and ``self._dx`` the increment."""
        dt = self._dt
        if self.arc:
            norm = math.sqrt(self._wdot(dt, dt) + self.psi2 * self._u1sq)
            if not norm > 0.0:
                return _Attempt(False, 0, math.inf, "the tangent moves no nodal position")
            ref = self._wdot(self._dx_prev, dt) + self.psi2 * self._u1sq * self._dlam_prev
            sign = 1.0 if not self.points or len(self.points) == 1 or ref >= 0.0 else -1.0
            dlam = sign * dl / norm
        else:
            if abs(dt[self.control]) < 1e-300:
                return _Attempt(False, 0, math.inf, "the controlled displacement does not respond to the load")
            target = math.copysign(dl, self.spec.displacement.to - self._controlled())
            dlam = target / dt[self.control]
        self._dx[:] = dlam * dt
        self._x_add(self._dx)
        self.lam += dlam
        return self._correct(dl)

    def _correct(self, dl: float) -> _Attempt:
        return self._corrector(self.lam, dl, ARC if self.arc else self.control, self._dx)

    # -- goals and the run ------------------------------------------------------------------
    def _check_goals(self) -> None:
        spec, pts = self.spec, self.points
        a, b = pts[-2], pts[-1]
        if spec.until_load_factor is not None and (a.lam - spec.until_load_factor) * (b.lam - spec.until_load_factor) <= 0.0 \
                and b.lam != a.lam:
            self.finished, self.reason = True, f"load factor reached {spec.until_load_factor:g}"
        if spec.until_displacement is not None:
            goal = spec.until_displacement
            if (a.u - goal) * (b.u - goal) <= 0.0 and b.u != a.u:
                self.finished, self.reason = True, f"displacement reached {goal:g} m"
        if not self.arc and abs(self._controlled() - spec.displacement.to) <= 1e-9 * abs(spec.displacement.to):
            self.finished, self.reason = True, f"controlled displacement reached {spec.displacement.to:g} m"

    def run(self, callback: Callable[["Simulator", StepResult], None] | None = None) -> None:
        """Increments until a goal is reached; :class:`ConvergenceError` when an increment fails
        at the minimum step or ``max_steps`` pass without reaching a goal. The simulator's
        statistics count every increment."""
        import time
        stats = self.sim.stats
        while not self.finished:
            if len(self.points) - 1 >= self.spec.max_steps:
                raise ConvergenceError(f"no goal reached in max_steps = {self.spec.max_steps} increments "
                                       f"(load factor {self.lam:.6g})")
            t0 = time.perf_counter()
            res = self.step()
            stats.wall_time_s += time.perf_counter() - t0
            stats.steps += 1
            stats.iterations_total += res.iterations
            stats.iterations_max = max(stats.iterations_max, res.iterations)
            if res.substeps > 1:
                stats.substepped_steps += 1
            if not res.converged:
                stats.unconverged_steps += 1
                raise ConvergenceError(f"increment {len(self.points)} from load factor {self.lam:.6g} "
                                       f"did not converge: {res.message}", res)
            stats.max_residual = max(stats.max_residual, res.residual)
            if callback is not None:
                callback(self.sim, res)

    def report(self) -> dict:
        """The path-following keys of ``flexmb run --json``."""
        limits, bifs = classify(self.points, final=True)
        mon = self.spec.monitor
        u = [p.u if math.isfinite(p.u) else None for p in self.points]
        return {
            "control": self.spec.control,
            "load_factor": self.lam,
            "monitor": None if mon is None else {"node": mon.node, "component": mon.component},
            "displacement": u[-1] if u else None,
            "finished": self.reason,
            "limit_points": limits,
            "bifurcations": bifs,
            "path": {"load_factor": [p.lam for p in self.points], "displacement": u,
                     "iterations": [p.iterations for p in self.points],
                     "negative_pivots": [p.negative_pivots for p in self.points]},
        }
