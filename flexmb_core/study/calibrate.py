"""Identify scene parameters from measurements: bounded nonlinear least squares with the
Jacobian's columns evaluated in parallel on Dask (the numerics of ``flexmb calibrate``).

The model is a function ``residuals(theta) -> {channel: (m_c,) array}``: for parameter values
``theta`` (scene units), the simulated minus the measured values of every measured channel, in
the channel's unit (m, N, rad, ...). It runs as a Dask task; this module only needs it picklable.
The recording adapter (:mod:`flexmb_io.bag.calibrate`) builds it from a bag.

Method
------
* **Scaling.** The solver works on ``z = theta / s`` with ``s`` the start's magnitude (the bound
  width for a start at 0), so every unknown is O(1) whatever its unit (E ~ 1e11 Pa next to a mass
  of a few kg).
* **Weights.** Channel ``c`` is divided by its noise level ``sigma_c``: given (``--noise``) or
  estimated. Estimated levels start at ``1e-3`` of the channel's RMS measured value; after each fit
  they become the RMS residual of the channel, corrected for the parameters' degrees of freedom
  (``sigma_c² = SSR_c / (m_c − n m_c / m)``), and the fit is repeated from its solution until the
  levels change by less than 10 % (at most :data:`MAX_PASSES` passes). This is generalized least
  squares with a per-channel variance: channels in different units are weighed by how well the
  twin can reproduce them, and the covariance below is consistent.
* **Solver.** ``scipy.optimize.least_squares`` (trust-region reflective, bounds on ``z``). Its
  Jacobian is forward differences: the ``n`` runs at ``z + h e_i`` (``h`` = ``diff_step`` times
  ``max(|z_i|, 1)``, stepping back from an upper bound) are submitted together, so ``n`` workers
  compute one Jacobian in the time of one run. A trial point whose run fails (a scene that does not
  validate, a step that does not converge) is a non-finite residual: the trust region shrinks.
* **Uncertainty.** ``cov = (Jᵀ W J)⁻¹`` at the solution (``J`` of the residuals in scene units,
  ``W`` the inverse noise variances): standard errors are ``sqrt(diag(cov))``, valid when the
  noise is independent between samples and the model is right; the correlation matrix shows
  unknowns the data cannot separate.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..errors import FlexmbError
from ..scene.overrides import OverrideError, split_key

MAX_PASSES = 4                 # fits with re-estimated noise levels
SIGMA_CHANGE = 0.10            # re-fit while a level changes by more than this fraction
INITIAL_SIGMA = 1e-3           # of the channel's RMS measured value, before the first estimate
DEFAULT_SPAN = 10.0            # without LO:HI a parameter stays within [start / 10, start × 10]


class CalibrationError(FlexmbError):
    """A calibration that cannot run as asked (bad --fit, a failed run at the start, no data)."""


@dataclass(frozen=True)
class FitParam:
    """One unknown: a dotted scene key and its bounds (scene units; None: from the start)."""

    key: str
    lo: float | None = None
    hi: float | None = None


def parse_fit(item: str) -> FitParam:
    """``"materials.steel.E=1.5e11:2.5e11"`` or ``"materials.steel.E"`` → :class:`FitParam`.

    Raises
    ------
    OverrideError
        On bad syntax or bounds (the message names ``--fit`` and the item).
    """
    key, eq, rng = item.partition("=")
    if not split_key(key) or (eq and not rng):
        raise OverrideError(f"--fit {item!r}: expected KEY or KEY=LO:HI, e.g. materials.steel.E=1.5e11:2.5e11")
    if not rng:
        return FitParam(".".join(split_key(key)))
    lo_s, sep, hi_s = rng.partition(":")
    try:
        lo, hi = float(lo_s), float(hi_s)
    except ValueError:
        lo = hi = math.nan
    if not sep or not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise OverrideError(f"--fit {item!r}: bounds must be LO:HI with finite numbers LO < HI, got {rng!r}")
    return FitParam(".".join(split_key(key)), lo, hi)


def bounds(params: list[FitParam], start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds (scene units): given ones, else ``start / 10 … start × 10``.

    Raises
    ------
    CalibrationError
        When a start lies outside its bounds, or is 0 without bounds.
    """
    lo, hi = np.empty(len(params)), np.empty(len(params))
    for i, (p, x) in enumerate(zip(params, start)):
        if p.lo is not None:
            lo[i], hi[i] = p.lo, p.hi
        elif x == 0.0:
            raise CalibrationError(f"--fit {p.key}: its start is 0; give bounds KEY=LO:HI")
        else:
            lo[i], hi[i] = sorted((x / DEFAULT_SPAN, x * DEFAULT_SPAN))
        if not lo[i] <= x <= hi[i]:
            raise CalibrationError(f"--fit {p.key}: the start {x:.6g} lies outside the bounds [{lo[i]:.6g}, {hi[i]:.6g}]"
                                   " (edit the start with --override, or widen the bounds)")
    return lo, hi


@dataclass
class ChannelFit:
    """One measured channel after the fit (residuals in the channel's unit)."""

    name: str
    unit: str
    samples: int
    sigma: float                   # noise level used as its weight (given or estimated)
    sigma_given: bool
    rms_start: float               # RMS residual at the start
    rms: float                     # RMS residual at the solution


@dataclass
class FitResult:
    """What :func:`fit` found."""

    keys: list[str]
    start: np.ndarray              # (n,) scene units
    values: np.ndarray             # (n,)
    std_errors: np.ndarray         # (n,)
    correlation: np.ndarray        # (n, n)
    lower: np.ndarray
    upper: np.ndarray
    channels: list[ChannelFit]
    success: bool
    message: str
    passes: int = 0
    evaluations: int = 0           # model runs: residuals and Jacobian columns
    jacobians: int = 0
    wall_time_s: float = 0.0
    history: list[dict] = field(default_factory=list)   # one entry per residual evaluation

    @property
    def at_bound(self) -> list[bool]:
        """Parameters that ended on a bound (their standard error is not meaningful)."""
        span = self.upper - self.lower
        return [bool(min(v - lo, hi - v) <= 1e-6 * s) for v, lo, hi, s in
                zip(self.values, self.lower, self.upper, span)]


class _Evaluator:
    """Runs the model on Dask for many parameter vectors at once; remembers every result."""

    def __init__(self, client: Any, model: Callable, data: Any, scale: np.ndarray, log: Callable[[dict], None]):
        self.client, self.model, self.data, self.scale = client, model, data, scale
        self.cache: dict[bytes, dict | str] = {}
        self.runs = 0
        self.log = log

    def many(self, zs: list[np.ndarray]) -> list[dict | str]:
        """Residual channels (or the error text of a failed run) for every ``z``."""
        todo = [z for z in zs if z.tobytes() not in self.cache]
        futures = [self.client.submit(self.model, self.data, z * self.scale, pure=False) for z in todo]
        for z, fut in zip(todo, futures):
            try:
                out = fut.result()
            except FlexmbError as exc:         # the run failed: a message, not a crash
                out = str(exc)
            self.cache[z.tobytes()] = out
            self.runs += 1
            self.log({"theta": (z * self.scale).tolist(),
                      "ok": isinstance(out, dict), **({} if isinstance(out, dict) else {"error": out})})
        return [self.cache[z.tobytes()] for z in zs]


def _stack(out: dict, names: list[str], sigma: dict[str, float]) -> np.ndarray:
    return np.concatenate([np.asarray(out[c], dtype=float).ravel() / sigma[c] for c in names])


def _rms(a) -> float:
    a = np.asarray(a, dtype=float).ravel()
    return float(np.sqrt(np.mean(a * a))) if a.size else 0.0


def fit(model: Callable, data: Any, params: list[FitParam], start: np.ndarray, client: Any, *,
        measured_rms: dict[str, float], units: dict[str, str], noise: dict[str, float] | None = None,
        diff_step: float = 1e-3, max_evaluations: int = 200, tolerance: float = 1e-8,
        progress: Callable[[dict], None] | None = None) -> FitResult:
    """Fit ``params`` so ``model(data, theta)`` matches the measurements (module docstring).

    Parameters
    ----------
    model
        ``model(data, theta) -> {channel: residual array}`` (simulated − measured, channel units);
        raises :class:`FlexmbError` when the run fails. Runs on the Dask workers.
    data
        The model's fixed input (the measurements and the twin setup): scattered to the workers once.
    params, start
        The unknowns and their start values (scene units), shape (n,).
    client
        A ``dask.distributed.Client``.
    measured_rms
        RMS of each channel's measured values (sets the first noise estimate).
    units
        Each channel's unit, for the report.
    noise
        Known noise levels (channel → sigma in its unit); the other channels' levels are estimated.
    diff_step
        Forward-difference step, relative to ``max(|z|, 1)`` of the scaled unknowns.
    max_evaluations
        Residual evaluations per pass (each Jacobian costs n more runs).
    tolerance
        ``ftol``/``xtol``/``gtol`` of ``least_squares``.

    Raises
    ------
    CalibrationError
        When the model fails at the start, or a Jacobian column's run fails.
    """
    from scipy.optimize import least_squares

    t0 = time.perf_counter()
    n = len(params)
    start = np.asarray(start, dtype=float)
    lo, hi = bounds(params, start)
    scale = np.where(start != 0.0, np.abs(start), hi - lo)
    history: list[dict] = []

    def log(entry: dict) -> None:
        history.append(entry)
        if progress is not None:
            progress(entry)

    ev = _Evaluator(client, model, client.scatter(data, broadcast=True), scale, log)
    z0 = start / scale
    first = ev.many([z0])[0]
    if not isinstance(first, dict):
        raise CalibrationError(f"the twin does not run at the start values: {first}")
    names = sorted(first)
    if not names:
        raise CalibrationError("no measured channel to fit")
    noise = dict(noise or {})
    unknown = sorted(set(noise) - set(names))
    if unknown:
        raise CalibrationError(f"--noise {unknown[0]}: not a measured channel (channels: {', '.join(names)})")
    sigma = {c: noise.get(c) or max(INITIAL_SIGMA * measured_rms.get(c, 0.0), 1e-300) for c in names}
    m_c = {c: np.asarray(first[c]).size for c in names}
    m = sum(m_c.values())
    if m <= n:
        raise CalibrationError(f"{m} measured values cannot determine {n} unknowns")
    jacobians = 0

    def fun(z: np.ndarray) -> np.ndarray:
        out = ev.many([np.array(z, dtype=float)])[0]
        return _stack(out, names, sigma) if isinstance(out, dict) else np.full(m, np.nan)

    def jac(z: np.ndarray) -> np.ndarray:
        nonlocal jacobians
        jacobians += 1
        z = np.array(z, dtype=float)
        base = fun(z)
        h = diff_step * np.maximum(np.abs(z), 1.0)
        h = np.where(z + h > hi / scale, -h, h)           # stay inside the bounds
        zs = [z + h[i] * np.eye(n)[i] for i in range(n)]
        cols = ev.many(zs)
        J = np.empty((m, n))
        for i, out in enumerate(cols):
            if not isinstance(out, dict):
                raise CalibrationError(f"the Jacobian's run for {params[i].key} = {zs[i][i] * scale[i]:.6g} failed: {out}")
            J[:, i] = (_stack(out, names, sigma) - base) / h[i]
        return J

    z, res, passes = z0, None, 0
    for passes in range(1, MAX_PASSES + 1):
        res = least_squares(fun, z, jac=jac, bounds=(lo / scale, hi / scale), method="trf", x_scale=1.0,
                            ftol=tolerance, xtol=tolerance, gtol=tolerance, max_nfev=max_evaluations)
        z = res.x
        out = ev.many([z])[0]
        new = dict(sigma)
        for c in names:
            if c not in noise:
                dof = max(m_c[c] - n * m_c[c] / m, 1.0)
                ssr = float(np.sum(np.asarray(out[c], dtype=float) ** 2))
                new[c] = max(math.sqrt(ssr / dof), 1e-300)
        change = max(abs(new[c] / sigma[c] - 1.0) for c in names)
        sigma = new
        if change <= SIGMA_CHANGE:
            break
    J = jac(z)                                            # at the solution, with the final weights
    J_theta = J / scale                                   # d(weighted residual)/d(theta)
    try:
        cov = np.linalg.inv(J_theta.T @ J_theta)
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        corr = cov / np.outer(se, se) if np.all(se > 0) else np.full((n, n), np.nan)
    except np.linalg.LinAlgError:
        se, corr = np.full(n, np.inf), np.full((n, n), np.nan)
    end = ev.many([z])[0]
    channels = [ChannelFit(c, units.get(c, ""), m_c[c], sigma[c], c in noise, _rms(first[c]), _rms(end[c]))
                for c in names]
    return FitResult([p.key for p in params], start, z * scale, se, corr, lo, hi, channels,
                     bool(res.status > 0), str(res.message), passes, ev.runs, jacobians,
                     time.perf_counter() - t0, history)
