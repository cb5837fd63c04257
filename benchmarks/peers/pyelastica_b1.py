"""Benchmark B1 (SPEC §8) run in PyElastica, as a peer baseline for flexmb.

B1: steel cantilever (E = 200 GPa, ρ = 7850 kg/m³, ν = 0.3, L = 1 m, circular section r = 5 mm),
clamped at x = 0 along +x, dead tip load in −z ramped with the C² quintic 10s³ − 15s⁴ + 6s⁵
(s = t / 0.5 s) to P = 2EI/L², then held; mass-proportional damping c_m = 10 1/s; 2 s.

The PyElastica model (numba, explicit):

* rod: ``CosseratRod.straight_rod`` (Cosserat rod: extensible, shearable, torsion), ``n`` elements,
  E and G = E/(2(1 + ν)) (PyElastica's shear factor is its fixed α_c = 27/28, so GA = 27/28·G·A,
  not flexmb's k_s = 0.886);
* clamp: ``OneEndFixedBC`` on node 0 and director 0;
* load: a forcing class adding −P·s(t) to the last node's external force (a numba kernel, same
  quintic as flexmb and Exudyn; PyElastica's ``EndpointForces`` only ramps linearly);
* damping: ``AnalyticalLinearDamper(uniform_damping_constant=c_m)``: v ← v·e^(−c_m Δt),
  ω ← ω·e^(−c_m Δt) every step, i.e. exact mass-proportional damping of translation and rotation;
* time stepping: ``PositionVerlet`` (symplectic, explicit). The stable step is set by the
  shear–rotary-inertia mode of an element, ω ≈ √(α_c G A/(ρ I)) ≈ 1.2e6 rad/s for this rod,
  *independent of the mesh*: Δt ≲ 1.6 µs (1.5 µs runs; 4 µs diverges within 0.05 s for 8 and 16
  elements). 2 s therefore need ~1.3 million steps.

PyElastica is an optional peer: imported lazily, never a dependency of flexmb.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.peers.pyelastica_b1 [--elements 16 --dt 1.5e-6]
"""
from __future__ import annotations

import argparse
import math
import statistics
import time
from typing import Any

import numpy as np

PACKAGE = "pyelastica"
E = 200e9
NU = 0.3
RHO = 7850.0
LENGTH = 1.0
RADIUS = 5e-3
INERTIA = math.pi * RADIUS**4 / 4.0
P_TIP = 2.0 * E * INERTIA / LENGTH**2
T_RAMP = 0.5
C_MASS = 10.0
ELASTICA_K2 = (0.839358279175, -0.493457480397)


def available() -> bool:
    """True if the optional peer ``pyelastica`` (module ``elastica``) can be imported."""
    try:
        import elastica  # noqa: F401
    except ImportError:
        return False
    return True


def _kernel():
    from numba import njit

    @njit(cache=True)
    def add_tip_load(external_forces, p_tip, t_ramp, t):  # pragma: no cover - numba
        s = min(t / t_ramp, 1.0)
        external_forces[2, -1] -= p_tip * s * s * s * (10.0 + s * (-15.0 + 6.0 * s))
    return add_tip_load


def build(n_elements: int, dt: float) -> dict[str, Any]:
    """The finalized simulator collection, the rod and the stepper."""
    import elastica as ea

    if n_elements < 2:
        raise ValueError(f"n_elements must be >= 2, got {n_elements}")
    add_tip_load = _kernel()

    class TipLoad(ea.NoForces):
        def apply_forces(self, system, time=np.float64(0.0)) -> None:
            add_tip_load(system.external_forces, P_TIP, T_RAMP, np.float64(time))

    class B1Simulator(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
        pass

    sim = B1Simulator()
    rod = ea.CosseratRod.straight_rod(n_elements, np.zeros(3), np.array([1.0, 0.0, 0.0]),
                                      np.array([0.0, 1.0, 0.0]), LENGTH, RADIUS, RHO,
                                      youngs_modulus=E, shear_modulus=E / (2.0 * (1.0 + NU)))
    sim.append(rod)
    sim.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,))
    sim.add_forcing_to(rod).using(TipLoad)
    sim.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=C_MASS, time_step=dt)
    sim.finalize()
    return {"ea": ea, "sim": sim, "rod": rod, "stepper": ea.PositionVerlet()}


def _solve(model: dict[str, Any], dt: float, steps: int, every: int) -> dict:
    sim, rod, stepper = model["sim"], model["rod"], model["stepper"]
    pos = rod.position_collection
    hist = [[0.0, *pos[:, -1]]] if every else []
    t = np.float64(0.0)
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        t = stepper.step(sim, t, dt)
        if every and k % every == 0:
            hist.append([k * dt, *pos[:, -1]])
    wall = time.perf_counter() - t0
    tip = pos[:, -1]
    return {"wall": wall, "tip": (float(tip[0]), float(tip[2])), "history": np.array(hist),
            "finite": bool(np.all(np.isfinite(pos)))}


def run_b1(n_elements: int, dt: float = 1.5e-6, t_end: float = 2.0, reference=ELASTICA_K2, repeats: int = 1,
           *, history_period: float | None = None) -> dict:
    """Run B1 with ``n_elements`` Cosserat elements; returns the keys of
    :func:`benchmarks.peers.exudyn_b1.run_b1` plus ``family``, ``integrator``, ``history`` and ``note``.

    Δt is rounded down so that ``history_period`` (or ``t_end``) is a whole number of steps. The
    numba kernels are compiled (or loaded) on a throwaway simulator first: the timing is the
    stepping loop alone. A blow-up (non-finite positions) is ``converged`` False.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    if not (dt > 0 and t_end > 0):
        raise ValueError(f"dt and t_end must be > 0 s, got dt={dt}, t_end={t_end}")
    span = history_period or t_end
    per = math.ceil(span / dt - 1e-9)
    dt = span / per
    steps = int(round(t_end / dt))
    every = per if history_period else 0
    warm = build(n_elements, dt)
    warm["stepper"].step(warm["sim"], np.float64(0.0), dt)
    runs = [_solve(build(n_elements, dt), dt, steps, every) for _ in range(repeats)]
    last = runs[-1]
    wall = statistics.median(r["wall"] for r in runs)
    ok = last["finite"]
    error = float(np.linalg.norm(np.array(last["tip"]) / LENGTH - np.asarray(reference))) if ok else math.nan
    import elastica
    version = getattr(elastica, "__version__", None) or _dist_version()
    return {
        "code": f"pyelastica {version}",
        "family": f"PyElastica Cosserat rod, {n_elements} el., explicit",
        "model": f"CosseratRod {n_elements} el., OneEndFixedBC, AnalyticalLinearDamper, PositionVerlet",
        "integrator": "position Verlet (explicit)", "n_elements": n_elements, "dt": dt, "steps": steps,
        "wall_time_s": wall, "wall_times_s": [r["wall"] for r in runs],
        "steps_per_s": steps / wall if ok else math.nan, "rtf": t_end / wall if ok else math.nan,
        "tip": list(last["tip"]), "tip_error": error, "converged": ok, "t_reached": t_end if ok else math.nan,
        "history": last["history"], "note": "" if ok else "blew up (non-finite positions)",
    }


def _dist_version() -> str:
    from importlib.metadata import version
    return version("pyelastica")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--elements", type=int, nargs="+", default=[16])
    ap.add_argument("--dt", type=float, default=1.5e-6)
    ap.add_argument("--t-end", type=float, default=2.0)
    args = ap.parse_args(argv)
    if not available():
        print("pyelastica is not installed (optional peer): skipped")
        return
    for n in args.elements:
        r = run_b1(n, dt=args.dt, t_end=args.t_end)
        print(f"{r['family']}: Δt {r['dt']:.4g} s, {r['steps_per_s']:.0f} steps/s, RTF {r['rtf']:.4f}, "
              f"tip {r['tip'][0]:.6f} {r['tip'][1]:.6f}, error/L {r['tip_error']:.2e} {r['note']}")


if __name__ == "__main__":
    main()
