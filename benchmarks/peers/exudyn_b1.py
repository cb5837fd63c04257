"""Benchmark B1 (SPEC §8) run in Exudyn, as a peer baseline for flexmb.

B1: steel cantilever (E = 200 GPa, rho = 7850 kg/m^3, L = 1 m, circular section r = 5 mm),
clamped at x = 0 along +x, dead tip load in -z ramped with the C^2 quintic 10s^3 - 15s^4 + 6s^5
(s = t / 0.5 s) to P = 2 EI / L^2 and then held; mass-proportional damping c_m M v with
c_m = 10 1/s; generalized-alpha (rho_inf = 0.8), dt = 1 ms, 2 s simulated. The error is
|tip(t_end) - reference| / L.

The Exudyn model (the plane of the 2D cable is Exudyn's x-y plane; its y is B1's z):
  * ``ObjectANCFCable2D`` elements on ``NodePoint2DSlope1`` nodes (4 coordinates per node:
    position and slope vector r'), full-order integration;
  * clamp: coordinates x, y and the slope's y component of the root node held by
    ``ObjectConnectorCoordinate`` to a ground node (the slope's x component stays free, so the
    root's axial strain is not constrained);
  * load: ``LoadForceVector`` on the tip node with an Exudyn *symbolic* user function for the
    ramp; it is compiled into a C++ expression tree, so the solver never calls Python;
  * damping: the cable's own damping is strain-rate damping, so c_m M v is added element by
    element as ``ObjectGenericODE2`` with dampingMatrix = c_m M_e (M_e: the element's
    consistent Hermite mass matrix, checked against the mass matrix Exudyn assembles);
  * solver: ``mbs.SolveDynamic`` (C++), generalized-alpha with spectralRadius 0.8, fixed step
    (adaptive step reduction off), Exudyn's default Newton (modified Newton, relative
    tolerance 1e-8) with the absolute tolerance raised to 1e-6 N (see ``_settings``), dense
    linear solver (EXUdense, the default), one thread, default (range-checked) C++ module.

Exudyn is an optional peer: it is imported lazily and is never a dependency of flexmb.
Run ``python -m benchmarks.peers.exudyn_b1`` for the 4/8/16-element table.
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import time
from typing import Any

import numpy as np

# --- B1 definition (SPEC §8) ----------------------------------------------------------------
E = 200e9                     # Young's modulus [Pa]
RHO = 7850.0                  # density [kg/m^3]
NU = 0.3                      # Poisson ratio (enters only through GA, which a cable ignores)
LENGTH = 1.0                  # [m]
RADIUS = 5e-3                 # [m]
AREA = math.pi * RADIUS**2    # [m^2]
INERTIA = math.pi * RADIUS**4 / 4.0
EI = E * INERTIA              # 98.17 N m^2
EA = E * AREA                 # 1.5708e7 N
RHO_A = RHO * AREA            # mass per length [kg/m]
K_LOAD = 2.0                  # P L^2 / EI
P_TIP = K_LOAD * EI / LENGTH**2
T_RAMP = 0.5                  # [s]
C_MASS = 10.0                 # mass-proportional damping [1/s]
SPECTRAL_RADIUS = 0.8
NEWTON_ABS_TOL = 1e-6         # [N], see _settings
ELASTICA_K2 = (0.839358279175, -0.493457480397)   # inextensible elastica, (x, z) / L


PACKAGE = "exudyn"


def available() -> bool:
    """True if the optional peer ``exudyn`` can be imported."""
    try:
        import exudyn  # noqa: F401
    except ImportError:
        return False
    return True


def _exudyn():
    try:
        import exudyn
    except ImportError as err:  # pragma: no cover - the caller checks available() first
        raise RuntimeError("exudyn is not installed; it is an optional peer: "
                           "`pip install exudyn` (or the 'peers' extra)") from err
    return exudyn


def element_mass_matrix(length: float, rho_a: float) -> np.ndarray:
    """Consistent mass matrix (8, 8) of a 2D ANCF cable element.

    Coordinate order per node as in ``NodePoint2DSlope1``: [x, y, x', y'];
    element order [node0, node1]. Cubic Hermite shapes, M = rho_a L/420 [...] (x) I_2.
    """
    L = length
    m4 = rho_a * L / 420.0 * np.array([
        [156.0, 22.0 * L, 54.0, -13.0 * L],
        [22.0 * L, 4.0 * L * L, 13.0 * L, -3.0 * L * L],
        [54.0, 13.0 * L, 156.0, -22.0 * L],
        [-13.0 * L, -3.0 * L * L, -22.0 * L, 4.0 * L * L],
    ])                                                          # (4, 4): [r0, r0', r1, r1']
    return np.kron(m4, np.eye(2))                               # (8, 8)


def _ramp_user_function(mbs, t, load):
    """Tip load P s(t) in -y; recorded symbolically by Exudyn (t is an exudyn.symbolic.Real)."""
    esym = _exudyn().symbolic
    tau = esym.min(t / T_RAMP, 1.0)
    s = tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau))
    return [0.0, -P_TIP * s, 0.0]


def build_model(n_elements: int, *, damping: str = "mass", history: bool = False) -> dict[str, Any]:
    """Build (not solve) the B1 cantilever; returns the Exudyn handles a run needs.

    damping: "mass" (c_m M v, the B1 definition) or "none" (for overhead measurements).
    history: also add a tip-position sensor stored internally (C++, no Python during the solve).
    """
    if n_elements < 1:
        raise ValueError(f"n_elements must be >= 1, got {n_elements}")
    if damping not in ("mass", "none"):
        raise ValueError(f"damping must be 'mass' or 'none', got {damping!r}")
    exu = _exudyn()
    from exudyn.advancedUtilities import CreateSymbolicUserFunction
    from exudyn.itemInterface import (LoadForceVector, MarkerNodeCoordinate,
                                      MarkerNodePosition, NodePoint2DSlope1, NodePointGround,
                                      ObjectANCFCable2D, ObjectConnectorCoordinate,
                                      ObjectGenericODE2, VObjectANCFCable2D,
                                      VObjectConnectorCoordinate, VObjectGenericODE2)

    sc = exu.SystemContainer()
    mbs = sc.AddSystem()
    le = LENGTH / n_elements
    nodes = [mbs.AddNode(NodePoint2DSlope1(referenceCoordinates=[i * le, 0.0, 1.0, 0.0]))
             for i in range(n_elements + 1)]
    for i in range(n_elements):
        mbs.AddObject(ObjectANCFCable2D(
            length=le, massPerLength=RHO_A, bendingStiffness=EI, axialStiffness=EA,
            nodeNumbers=[nodes[i], nodes[i + 1]], useReducedOrderIntegration=0,
            visualization=VObjectANCFCable2D(show=False)))
    if damping == "mass":
        d_e = C_MASS * element_mass_matrix(le, RHO_A)                   # (8, 8)
        zero = np.zeros((8, 8))
        for i in range(n_elements):
            mbs.AddObject(ObjectGenericODE2(
                nodeNumbers=[nodes[i], nodes[i + 1]], massMatrix=zero, stiffnessMatrix=zero,
                dampingMatrix=d_e, forceVector=[0.0] * 8,
                visualization=VObjectGenericODE2(show=False)))

    # clamp: x, y and slope-y of the root node fixed to a ground node
    ground = mbs.AddNode(NodePointGround(referenceCoordinates=[0.0, 0.0, 0.0]))
    m_ground = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=ground, coordinate=0))
    for coordinate in (0, 1, 3):
        m_root = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=nodes[0], coordinate=coordinate))
        mbs.AddObject(ObjectConnectorCoordinate(
            markerNumbers=[m_ground, m_root], visualization=VObjectConnectorCoordinate(show=False)))

    m_tip = mbs.AddMarker(MarkerNodePosition(nodeNumber=nodes[-1]))
    ramp = CreateSymbolicUserFunction(mbs, _ramp_user_function, "loadVectorUserFunction",
                                      itemTypeName="LoadForceVector")
    mbs.AddLoad(LoadForceVector(markerNumber=m_tip, loadVector=[0.0, -P_TIP, 0.0],
                                loadVectorUserFunction=ramp))
    sensor = None
    if history:
        from exudyn.itemInterface import SensorNode
        sensor = mbs.AddSensor(SensorNode(nodeNumber=nodes[-1], storeInternal=True, writeToFile=False,
                                          outputVariableType=exu.OutputVariableType.Position))
    mbs.Assemble()
    # keep `ramp` alive: it owns the expression tree the C++ load evaluates
    return {"exu": exu, "sc": sc, "mbs": mbs, "tip_node": nodes[-1], "ramp": ramp,
            "n_ode2": 4 * (n_elements + 1), "sensor": sensor}


def _settings(exu, dt: float, t_end: float, history_period: float | None = None):
    s = exu.SimulationSettings()
    if history_period is not None:
        s.solution.sensors.writePeriod = history_period
    steps = int(round(t_end / dt))
    ti = s.timeIntegration
    ti.endTime = t_end
    ti.numberOfSteps = steps
    ti.adaptiveStep = False                       # fixed dt; a Newton failure is an error
    ti.verboseMode = 0
    # The residual is in newtons and its round-off floor is ~EA * 1e-16 ~ 1e-9 N per coordinate,
    # so the default absolute tolerance (1e-10) cannot be met in the first steps, where the
    # ramped load is ~1e-6 N and the relative tolerance asks for 1e-14 N: Newton stalls at
    # step 1. 1e-6 N is 5e-9 of P; the tip at 2 s agrees with 1e-7 to 12 digits.
    ti.newton.absoluteTolerance = NEWTON_ABS_TOL
    ti.generalizedAlpha.spectralRadius = SPECTRAL_RADIUS
    ti.generalizedAlpha.useNewmark = False
    ti.generalizedAlpha.useIndex2Constraints = False
    ti.generalizedAlpha.computeInitialAccelerations = True
    s.solution.file.write = False
    s.parallel.numberOfThreads = 1
    s.show.computationTime = False
    s.show.statistics = False
    return s, steps


def _solve(model: dict[str, Any], dt: float, t_end: float, history_period: float | None = None) -> dict[str, Any]:
    exu, mbs = model["exu"], model["mbs"]
    settings, steps = _settings(exu, dt, t_end, history_period)
    t0 = time.perf_counter()
    try:
        mbs.SolveDynamic(settings, solverType=exu.DynamicSolverType.GeneralizedAlpha)
        converged = True
    except exu.SolverError:                       # Exudyn has printed its diagnosis
        converged = False
    wall = time.perf_counter() - t0
    it = mbs.sys["dynamicSolver"].it
    tip = mbs.GetNodeOutput(model["tip_node"], exu.OutputVariableType.Position)
    out = {"wall": wall, "steps": steps, "tip": (float(tip[0]), float(tip[1])),
           "newton": it.newtonStepsCount, "jacobians": it.newtonJacobiCount,
           "converged": converged, "t_reached": float(it.currentTime)}
    if model.get("sensor") is not None:
        h = np.asarray(mbs.GetSensorStoredData(model["sensor"]))          # (n, 4): t, x, y, z
        out["history"] = np.column_stack([h[:, 0], h[:, 1], np.zeros(len(h)), h[:, 2]])   # B1 axes
    return out


def run_b1(n_elements: int, dt: float = 1e-3, t_end: float = 2.0,
           reference=ELASTICA_K2, repeats: int = 3, *, damping: str = "mass",
           history_period: float | None = None) -> dict:
    """Run B1 with ``n_elements`` ANCFCable2D elements; time integration timed ``repeats`` times.

    Each repeat solves a freshly built model; ``wall_time_s`` is the median time of
    ``SolveDynamic`` alone (it includes Exudyn's solver initialization, < 1 ms here).
    ``reference`` is the tip (x, z) / L that the error is measured against.
    A Newton failure is returned, not raised: ``converged`` False, ``t_reached`` < t_end,
    ``tip_error``, ``steps_per_s`` and ``rtf`` NaN (Exudyn prints its own diagnosis).
    ``history_period`` (s): also return ``history`` (n, 4): t, x, y = 0, z of the tip (m, B1
    axes) every period, from an internally stored sensor (the timed solve includes it).
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    if not dt > 0.0 or not t_end > 0.0:
        raise ValueError(f"dt and t_end must be > 0, got dt={dt}, t_end={t_end}")
    runs = []
    for _ in range(repeats):
        model = build_model(n_elements, damping=damping, history=history_period is not None)
        runs.append(_solve(model, dt, t_end, history_period))
        if not runs[-1]["converged"]:
            break
    exu = model["exu"]
    last = runs[-1]
    wall = statistics.median(r["wall"] for r in runs)
    tip = np.array(last["tip"]) / LENGTH
    ref = np.asarray(reference, dtype=float)
    error = float(np.linalg.norm(tip - ref)) if last["converged"] else math.nan
    out = {
        "code": f"exudyn {exu.config.Version()}",
        "family": f"Exudyn ANCF cable2D, {n_elements} el., gen-α ρ∞={SPECTRAL_RADIUS:g}",
        "integrator": "generalized_alpha",
        "model": f"ANCFCable2D, {n_elements} el. (clamp: 3 coordinate constraints; "
                 f"damping: {'c_m M v via GenericODE2' if damping == 'mass' else 'none'}; "
                 f"load: symbolic user function)",
        "n_elements": n_elements,
        "dt": dt,
        "steps": last["steps"],
        "wall_time_s": wall,
        "steps_per_s": last["steps"] / wall if last["converged"] else math.nan,
        "rtf": t_end / wall if last["converged"] else math.nan,
        "tip": [float(last["tip"][0]), float(last["tip"][1])],
        "tip_error": error,
        "newton_iterations_mean": last["newton"] / last["steps"],
        "jacobians": last["jacobians"],
        "wall_times_s": [r["wall"] for r in runs],
        "converged": last["converged"],
        "t_reached": last["t_reached"],
    }
    if "history" in last:
        out["history"] = last["history"]
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--elements", type=int, nargs="+", default=[4, 8, 16])
    parser.add_argument("--dt", type=float, default=1e-3)
    parser.add_argument("--t-end", type=float, default=2.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--damping", choices=["mass", "none"], default="mass")
    args = parser.parse_args(argv)
    if not available():
        print("exudyn is not installed (optional peer): skipped")
        return
    print(f"B1 in Exudyn, dt = {args.dt:g} s, t_end = {args.t_end:g} s, "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}")
    print("settled = |tip(2 t_end) - tip(t_end)| / L (must be <= 1e-6)")
    print(f"{'el.':>4} {'steps/s':>9} {'RTF':>7} {'Newton/step':>11} {'tip x/L':>15} "
          f"{'tip z/L':>16} {'error/L':>9} {'settled':>9}")
    for n in args.elements:
        r = run_b1(n, dt=args.dt, t_end=args.t_end, repeats=args.repeats,
                   damping=args.damping)
        r2 = run_b1(n, dt=args.dt, t_end=2.0 * args.t_end, repeats=1, damping=args.damping)
        settled = math.dist(r["tip"], r2["tip"]) / LENGTH
        failed = "" if r["converged"] else f"  Newton failed at t = {r['t_reached']:g} s"
        print(f"{n:>4} {r['steps_per_s']:>9.0f} {r['rtf']:>7.2f} "
              f"{r['newton_iterations_mean']:>11.2f} {r['tip'][0]:>15.12f} "
              f"{r['tip'][1]:>16.12f} {r['tip_error']:>9.2e} {settled:>9.1e}{failed}")
    print(r["code"])


if __name__ == "__main__":
    main()
