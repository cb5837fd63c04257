"""What every work-precision case shares: the fidelity of a run (:class:`Variant`), the CSV row
schema, the timed flexmb run that samples an output at fixed marks, reference files and errors.

Timing: the wall time of ``Simulator.run`` only (JIT warm-up and initialization excluded), median
of the repeats; a run is repeated on a fresh simulator while the walls sum to less than the
repeat budget (at most ``max_repeats`` times).

Where the runs happen (:func:`run_variants`): one after another in this process (``flexmb bench``,
``--workers 1``, the default: every run has the process to itself), or each variant a Dask task
(``--workers N`` / ``--scheduler``, :func:`variant_task`): errors are the same bits either way;
wall times are those of runs going on at the same time, one per worker process. A run that fails (a step that does not converge
after the scene's sub-stepping policy) is a row with ``completed = False``, NaN errors and the
solver's message in ``note``: reported, never dropped.
"""

from __future__ import annotations

import csv
import importlib
import math
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from flexmb_core.errors import ConvergenceError
from flexmb_core.simulator import Simulator

ROOT = Path(__file__).resolve().parents[2]
REFERENCE_DIR = ROOT / "benchmarks" / "reference"

COLUMNS = (
    "case", "code", "family", "legs", "elements", "order", "integrator", "rho_inf", "newton", "dt",
    "sim_time_s", "steps", "completed", "t_reached_s", "repeats", "wall_s", "wall_min_s", "wall_per_sim_s", "rtf",
    "steps_per_s", "newton_iterations_mean", "substepped_steps", "error", "error_final", "error_closed_form",
    "error_orientation_rad", "note",
)
"""CSV columns (``workprecision.csv``); units: s, m or 1/L as the case's ``error_unit`` says."""

INTEGRATOR_SHORT = {"generalized_alpha": "gen-α", "newmark": "Newmark", "chung_hulbert": "Chung–Hulbert"}
ORDER_NAME = {1: "linear", 2: "quadratic", 3: "cubic", 4: "quartic"}


@dataclass(frozen=True)
class Variant:
    """One fidelity of a flexmb run.

    Attributes
    ----------
    case : str — ``b1``, ``spin_up`` or ``stewart``.
    dt : float — time step (s).
    elements : int — elements per member (per leg for the Stewart frame legs).
    order : int — Lagrange order of the frame elements (1–4); 1 for bar legs.
    integrator : str — ``generalized_alpha`` (Arnold–Brüls) or ``newmark`` (β = 1/4, γ = 1/2).
    rho_inf : float — spectral radius at infinity (generalized-α only).
    newton : str — ``full`` or ``modified`` (tangent reuse).
    legs : str — Stewart only: ``bar`` (one bar actuator per leg, truss platform) or ``frame``.
    """

    case: str
    dt: float
    elements: int = 4
    order: int = 3
    integrator: str = "generalized_alpha"
    rho_inf: float = 0.8
    newton: str = "modified"
    legs: str = "frame"

    @property
    def family(self) -> str:
        """The fidelity without Δt: the points of one family form one line of the diagram."""
        if self.legs == "bar":
            mesh = "bar legs"
        else:
            mesh = f"{self.elements}×{ORDER_NAME[self.order]}" + (" /leg" if self.case == "stewart" else "")
        integ = INTEGRATOR_SHORT[self.integrator]
        if self.integrator == "generalized_alpha":
            integ += f" ρ∞={self.rho_inf:g}"
        return f"{mesh}, {integ}, {self.newton} Newton"

    @property
    def key(self) -> str:
        return f"{self.family}, Δt={self.dt:g}"

    def solver_overrides(self) -> dict:
        """``solver`` keys of the scene this variant changes."""
        out = {"dt": self.dt, "integrator": self.integrator, "newton": self.newton}
        if self.integrator == "generalized_alpha":
            out["rho_inf"] = self.rho_inf
        return out


def sweep(case: str, families: list[dict], dts: dict[int, tuple[float, ...]] | tuple[float, ...]) -> list[Variant]:
    """Variants ``Variant(case, dt, **family)`` for every family and Δt, without duplicates.

    ``dts`` is one tuple for all families or a dict family index → tuple.
    """
    out: list[Variant] = []
    for i, fam in enumerate(families):
        for dt in (dts[i] if isinstance(dts, dict) else dts):
            v = Variant(case, dt, **fam)
            if v not in out:
                out.append(v)
    return out


@dataclass
class Timed:
    """A timed flexmb run: walls of the repeats (s), the run summary, samples at the marks.

    ``samples`` maps the mark index k (time k·mark) to the observed value, shape (m,).
    """

    walls: list[float]
    summary: dict
    samples: dict[int, np.ndarray] = field(default_factory=dict)
    completed: bool = True
    message: str = ""
    t_reached: float = 0.0

    @property
    def wall(self) -> float:
        return statistics.median(self.walls) if self.walls else math.nan


def timed_run(start: Callable[[], Simulator], until: float, mark: float,
              observe: Callable[[Simulator], np.ndarray], *, budget_s: float, max_repeats: int) -> Timed:
    """Run ``start()`` (an initialized simulator) to ``until``, sampling ``observe`` every ``mark`` s.

    A short untimed run first loads every kernel a step can reach. The timed run is repeated on fresh
    simulators while the walls sum to less than ``budget_s`` (at most ``max_repeats`` runs); samples
    and summary are those of the first repeat. A
    :class:`ConvergenceError` ends the run as ``completed = False`` (the repeats stop).
    """
    if not (mark > 0 and until > 0):
        raise ValueError(f"mark and until must be > 0 s, got mark={mark}, until={until}")
    walls: list[float] = []
    first: Timed | None = None
    try:        # untimed: loads every kernel a step can reach (warmup() covers the assembly only)
        start().run(min(until, 3 * mark))
    except ConvergenceError:
        pass
    while True:
        sim = start()
        samples = {0: np.array(observe(sim), dtype=float)}
        tol = 0.1 * sim.spec.dt

        def record(s: Simulator, _res) -> None:
            t = s.state.t
            k = round(t / mark)
            if abs(t - k * mark) < tol:
                samples[k] = np.array(observe(s), dtype=float)

        message, completed = "", True
        t0 = time.perf_counter()
        try:
            sim.run(until, callback=record)
        except ConvergenceError as exc:
            message, completed = str(exc), False
        walls.append(time.perf_counter() - t0)
        if first is None:
            first = Timed(walls, sim.summary(), samples, completed, message, sim.state.t)
        if not completed or sum(walls) >= budget_s or len(walls) >= max_repeats:
            return first


# -- references --------------------------------------------------------------------------------------
def write_reference(path: Path, header: dict[str, str], columns: list[str], data: np.ndarray) -> None:
    """A reference history as CSV: ``# key: value`` header lines, one column row, full precision."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        for k, v in header.items():
            f.write(f"# {k}: {v}\n")
        w = csv.writer(f)
        w.writerow(columns)
        for row in data:
            w.writerow([repr(float(x)) for x in row])


def read_reference(path: Path) -> tuple[dict[str, str], list[str], np.ndarray]:
    """Read :func:`write_reference`'s file: (header, columns, data (n_rows, n_columns))."""
    if not path.exists():
        raise FileNotFoundError(f"reference file {path} is missing: regenerate it with "
                                f"`flexmb bench --case {path.stem} --make-reference`")
    header, rows, columns = {}, [], None
    with path.open() as f:
        for line in f:
            if line.startswith("#"):
                k, _, v = line[1:].partition(":")
                header[k.strip()] = v.strip()
            elif columns is None:
                columns = line.strip().split(",")
            elif line.strip():
                rows.append([float(x) for x in line.split(",")])
    return header, columns or [], np.array(rows)


def history_error(samples: dict[int, np.ndarray], ref_t: np.ndarray, ref: np.ndarray, mark: float,
                  until: float, scale: float = 1.0) -> tuple[float, float, int]:
    """Max and final-mark distance of sampled values from a reference history, divided by ``scale``.

    Parameters
    ----------
    samples : mark index → value (m,).
    ref_t : (n,) s — reference times (multiples of ``mark``).
    ref : (n, m) — reference values.
    mark, until : s — the sampling interval and the end of the compared window.

    Returns
    -------
    (max over common marks, value at the last common mark, number of common marks); NaN when the
    run missed a mark of the window (it did not complete).
    """
    ks = np.rint(ref_t / mark).astype(int)
    keep = ref_t <= until + 1e-9
    d = []
    for k, r in zip(ks[keep], ref[keep]):
        if k not in samples:
            return math.nan, math.nan, 0
        d.append(float(np.linalg.norm(samples[k] - r)) / scale)
    return max(d), d[-1], len(d)


def row(variant: Variant | None = None, **values) -> dict:
    """A CSV row: every column, from the variant's fields and ``values`` (missing → empty/NaN)."""
    out = {c: "" for c in COLUMNS}
    for c in ("error", "error_final", "error_closed_form", "error_orientation_rad"):
        out[c] = math.nan
    if variant is not None:
        out.update(case=variant.case, code="flexmb", family=variant.family, legs=variant.legs,
                   elements=variant.elements if variant.legs != "bar" else 1, order=variant.order,
                   integrator=variant.integrator,
                   rho_inf=variant.rho_inf if variant.integrator == "generalized_alpha" else "",
                   newton=variant.newton, dt=variant.dt)
    unknown = set(values) - set(COLUMNS)
    if unknown:
        raise KeyError(f"unknown work-precision columns {sorted(unknown)}; expected a subset of {COLUMNS}")
    out.update(values)
    return out


def timing_columns(timed: Timed, until: float) -> dict:
    """The speed columns of a flexmb run (NaN speeds when it did not complete)."""
    s = timed.summary
    ok = timed.completed
    wall = timed.wall
    return dict(sim_time_s=until, steps=s["steps"], completed=ok, t_reached_s=timed.t_reached,
                repeats=len(timed.walls), wall_s=wall, wall_min_s=min(timed.walls),
                substepped_steps=s["substepped_steps"],
                wall_per_sim_s=wall / until if ok else math.nan, rtf=until / wall if ok else math.nan,
                steps_per_s=s["steps"] / wall if ok else math.nan,
                newton_iterations_mean=s["newton_iterations_mean"], note=timed.message)


# -- running a sweep -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class VariantTask:
    """One run of a case's sweep (picklable: what a Dask task receives). ``context`` is the case's
    :func:`context` (references, closed forms), computed once by the caller."""

    case: str
    variant: Variant
    quick: bool
    context: dict
    budget_s: float
    max_repeats: int


def variant_task(task: VariantTask) -> dict:
    """The CSV row of one variant (the Dask task of ``flexmb bench --workers N``)."""
    mod = importlib.import_module(f"benchmarks.workprecision.{task.case}")
    return mod.variant_row(task.variant, task.quick, task.context, budget_s=task.budget_s,
                           max_repeats=task.max_repeats)


def run_variants(case: str, variants: list[Variant], quick: bool, context: dict, *, budget_s: float,
                 max_repeats: int, log: Callable[[str], None], line: Callable[[dict], str],
                 client=None) -> list[dict]:
    """Every variant's row, in ``variants`` order: in this process one after another (``client``
    None), or all at once as tasks of a Dask ``client``. ``log(line(row))`` as each row arrives."""
    tasks = [VariantTask(case, v, quick, context, budget_s, max_repeats) for v in variants]
    if client is None:
        rows = []
        for t in tasks:
            rows.append(variant_task(t))
            log(line(rows[-1]))
        return rows
    from flexmb_core.study.tasks import run_all

    return run_all(client, variant_task, tasks, name=f"flexmb-bench-{case}", on_result=lambda i, r: log(line(r)))
