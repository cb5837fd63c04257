"""The Stewart platform twin (seed appendix, SPEC §6.1/§8) in Exudyn, as a peer baseline for flexmb.

The same mechanism as scenes/stewart_platform.yaml, built from Exudyn's C++ items:

  * legs: ``ObjectANCFCable`` (3D ANCF cable: Euler–Bernoulli, axial + bending, no torsion or shear) on
    ``NodePointSlope1`` nodes, ``n`` elements per leg; steel tube 25 × 3 mm (EA, EI, ρA computed
    exactly as flexmb's section); Kelvin–Voigt damping with the scene's retardation time τ = η/E as
    the cable's strain-rate damping (``axialDamping = EA τ``, ``bendingDamping = EI τ``);
  * actuation: the leg length L(t) of the appendix program (flexmb's Hermite table, blended start and
    switch, identical commands) enters each element as ``referenceAxialStrain = L(t)/L0 − 1``, set from
    a Python pre-step user function every step (Exudyn has no other way to change an object parameter
    during a solve) — the "per-step Python command update" of SPEC §8. Exudyn passes that function
    the *end* time t_{n+1} of the coming step (the state is still at t_n): the commands are L(t_{n+1})
    and the pose sampled there is the one at t_n (until 2026-11-23 this module read t as t_n, which
    set the commands one step ahead and stamped the poses one step late);
  * joints: base ends on ``ObjectJointSpherical`` to ground; platform ends on ``ObjectJointSpherical``
    to the platform;
  * platform: one rigid body (Euler parameters) with the mass and inertia of flexmb's three steel tube
    edges plus the 10 kg payload at the vertices (flexmb's edges are flexible frames; they are ~100×
    stiffer than the legs);
  * gravity on every body; the dynamic run starts from Exudyn's static equilibrium at t = 0;
  * solver: ``SolveDynamic``, generalized-α with spectral radius 0.9 (the scenes' ρ∞), fixed Δt,
    Exudyn's default modified Newton, one thread, dense solver off (sparse).

Pose output: centroid and orientation of the rigid platform at the 10 ms marks, recorded in the same
pre-step function (so the timed run includes it, as flexmb's timed runs include their recording).

Exudyn is an optional peer: imported lazily, never a dependency of flexmb.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/peers/exudyn_stewart.py [--until 20]
"""
from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "stewart_platform.yaml"
MARK = 0.01
CASES = (("ancf4", 1e-3), ("ancf1", 1e-3), ("ancf1", 2e-3), ("ancf1", 4e-3))   # (legs, Δt)
# the flexmb variant of the same class (benchmarks/stewart_platform.py): flexible legs on a rigid
# (truss) platform at equal leg mesh; at Δt = 2 and 4 ms the bar legs, flexmb's cheapest there
COMPARE = {("ancf4", 1e-3): "frame4tp_dt1", ("ancf1", 1e-3): "frame1tp_dt1", ("ancf1", 2e-3): "bars_dt2",
           ("ancf1", 4e-3): "bars_dt4"}


def available() -> bool:
    """True if the optional peer ``exudyn`` can be imported."""
    try:
        import exudyn  # noqa: F401
    except ImportError:
        return False
    return True


def _scene_data() -> dict:
    """Material, sections, payload, gravity, solver and command options of the flexmb scene."""
    sys.path.insert(0, str(ROOT))
    from flexmb_core import sections
    from flexmb_core.scene import load_scene

    scene = load_scene(SCENE)
    steel = scene.materials["steel"]

    def tube(name):
        ro, ri = scene.sections[name].dims
        return sections.tube(ro, ri, steel.nu)
    leg, edge = tube("leg"), tube("edge")
    return {"scene": scene, "E": steel.E, "rho": steel.rho, "tau": steel.retardation_time,
            "leg_area": leg.area, "leg_inertia": leg.i1, "edge_area": edge.area,
            "payload": sum(p.mass for p in scene.point_masses), "gravity": scene.gravity.acceleration,
            "rho_inf": scene.solver.rho_inf}


def _platform_inertia(offsets: np.ndarray, edge_mass: float, payload: float) -> tuple[float, np.ndarray]:
    """Mass and inertia tensor about the centroid of three uniform edges + equal vertex masses."""
    s = (np.arange(2000) + 0.5) / 2000                            # midpoint rule along each edge
    pts, w = [], []
    for a in range(3):
        p0, p1 = offsets[a], offsets[(a + 1) % 3]
        pts.append(p0 + s[:, None] * (p1 - p0))
        w.append(np.full(s.size, edge_mass / s.size))
    pts.append(offsets)
    w.append(np.full(3, payload / 3))
    x, m = np.vstack(pts), np.concatenate(w)
    inertia = np.einsum("i,ij->", m, x * x) * np.eye(3) - np.einsum("i,ij,ik->jk", m, x, x)
    return float(m.sum()), inertia


def build(n_elements: int) -> dict[str, Any]:
    """Build and assemble the model (not solved); returns the handles a run needs."""
    import exudyn as exu
    from exudyn.itemInterface import (LoadMassProportional, MarkerBodyMass, MarkerBodyPosition,
                                      MarkerNodePosition, NodePointSlope1, ObjectANCFCable, ObjectGround,
                                      ObjectJointSpherical, VObjectANCFCable, VObjectJointSpherical)

    from flexmb_core.commands import StewartAppendixProgram

    d = _scene_data()
    scene = d["scene"]
    prog = StewartAppendixProgram(scene.commands)
    geo = prog.geometry
    layout = geo.layout()
    ea, ei = d["E"] * d["leg_area"], d["E"] * d["leg_inertia"]
    rho_a = d["rho"] * d["leg_area"]
    sc = exu.SystemContainer()
    mbs = sc.AddSystem()
    ground = mbs.AddObject(ObjectGround())
    offsets = geo.vertex_offsets()
    mass, inertia = _platform_inertia(offsets, d["rho"] * d["edge_area"] * geo.side, d["payload"])
    from exudyn.rigidBodyUtilities import RigidBodyInertia
    body = mbs.CreateRigidBody(inertia=RigidBodyInertia(mass=mass, inertiaTensor=inertia),
                               referencePosition=list(geo.centroid0()), gravity=list(d["gravity"]),
                               nodeType=exu.NodeType.RotationEulerParameters, show=False)
    body_node = mbs.GetObject(body)["nodeNumber"]
    elements: list[list[int]] = []
    for i in range(6):
        p0 = layout.base_points[i]
        p1 = layout.vertices0[layout.leg_vertex[i]]
        axis = (p1 - p0) / np.linalg.norm(p1 - p0)
        le = float(np.linalg.norm(p1 - p0)) / n_elements
        nodes = [mbs.AddNode(NodePointSlope1(referenceCoordinates=list(p0 + k * le * axis) + list(axis)))
                 for k in range(n_elements + 1)]
        leg = []
        for k in range(n_elements):
            o = mbs.AddObject(ObjectANCFCable(
                length=le, massPerLength=rho_a, axialStiffness=ea, bendingStiffness=ei,
                axialDamping=ea * d["tau"], bendingDamping=ei * d["tau"], nodeNumbers=[nodes[k], nodes[k + 1]],
                useReducedOrderIntegration=0, visualization=VObjectANCFCable(show=False)))
            leg.append(o)
            mm = mbs.AddMarker(MarkerBodyMass(bodyNumber=o))
            mbs.AddLoad(LoadMassProportional(markerNumber=mm, loadVector=list(d["gravity"])))
        elements.append(leg)
        m_ground = mbs.AddMarker(MarkerBodyPosition(bodyNumber=ground, localPosition=list(p0)))
        m_base = mbs.AddMarker(MarkerNodePosition(nodeNumber=nodes[0]))
        mbs.AddObject(ObjectJointSpherical(markerNumbers=[m_ground, m_base],
                                           visualization=VObjectJointSpherical(show=False)))
        m_top = mbs.AddMarker(MarkerNodePosition(nodeNumber=nodes[-1]))
        m_body = mbs.AddMarker(MarkerBodyPosition(bodyNumber=body, localPosition=list(offsets[layout.leg_vertex[i]])))
        mbs.AddObject(ObjectJointSpherical(markerNumbers=[m_top, m_body],
                                           visualization=VObjectJointSpherical(show=False)))
    mbs.Assemble()
    return {"exu": exu, "sc": sc, "mbs": mbs, "body": body, "body_node": body_node, "elements": elements,
            "prog": prog, "l0": layout.lengths0, "rho_inf": d["rho_inf"], "tau": d["tau"],
            "n_ode2": mbs.systemData.ODE2Size(), "mass": mass}


def _settings(exu, dt: float, until: float, rho_inf: float):
    s = exu.SimulationSettings()
    ti = s.timeIntegration
    ti.endTime = until
    ti.numberOfSteps = int(round(until / dt))
    ti.adaptiveStep = False
    ti.verboseMode = 0
    ti.newton.absoluteTolerance = 1e-6            # N; see benchmarks/peers/exudyn_b1.py
    ti.generalizedAlpha.spectralRadius = rho_inf
    ti.generalizedAlpha.useNewmark = False
    ti.generalizedAlpha.useIndex2Constraints = False
    ti.generalizedAlpha.computeInitialAccelerations = True
    s.staticSolver.newton.absoluteTolerance = 1e-6
    s.staticSolver.verboseMode = 0
    s.linearSolver.solverType = exu.LinearSolverType.EigenSparse   # 1.6k steps/s dense (4 el.)
    s.solution.file.write = False
    s.parallel.numberOfThreads = 1
    s.show.computationTime = False
    s.show.statistics = False
    return s


def _set_commands(m: dict, t: float, buf: np.ndarray) -> None:
    m["prog"].lengths(t, buf)
    mbs = m["mbs"]
    for i, leg in enumerate(m["elements"]):
        strain = buf[i] / m["l0"][i] - 1.0
        for o in leg:
            mbs.SetObjectParameter(o, "referenceAxialStrain", strain)


def run(case: str = "ancf4", dt: float = 1e-3, until: float = 20.0, repeats: int = 1, *,
        commands: bool = True) -> dict:
    """Solve the twin with ``case`` ∈ CASES; returns speed, the pose history at the 10 ms marks and
    the key of the flexmb variant to compare RTF with (same Δt, same class of legs).

    ``commands=False`` drops the Python pre-step function: the legs hold their length (no motion, no
    pose record) — it measures the solver without the per-step Python update, for reference only."""
    n = {"ancf4": 4, "ancf1": 1}[case]
    walls, out = [], None
    for _ in range(repeats):
        m = build(n)
        exu, mbs = m["exu"], m["mbs"]
        buf = np.zeros(6)
        s = _settings(exu, dt, until, m["rho_inf"])
        _set_commands(m, 0.0, buf)
        mbs.SolveStatic(s)                                                  # equilibrium under gravity at t = 0
        sd = mbs.systemData
        sd.SetODE2Coordinates(sd.GetODE2Coordinates(), configuration=exu.ConfigurationType.Initial)
        sd.SetAECoordinates(sd.GetAECoordinates(), configuration=exu.ConfigurationType.Initial)
        marks: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        node = m["body_node"]

        def pre_step(mbs_, t):
            # Exudyn calls this before the step t_n → t_{n+1} with t = t_{n+1} (the state is at t_n)
            t_n = t - dt
            k = round(t_n / MARK)
            if abs(t_n - k * MARK) < 0.1 * dt:
                p = np.array(mbs_.GetNodeOutput(node, exu.OutputVariableType.Position))
                r = np.array(mbs_.GetNodeOutput(node, exu.OutputVariableType.RotationMatrix)).reshape(3, 3)
                marks[k] = (p, r)
            _set_commands(m, t, buf)                                        # L(t_{n+1}) for the step t_n → t_{n+1}
            return True

        if commands:
            mbs.SetPreStepUserFunction(pre_step)
        t0 = time.perf_counter()
        try:
            mbs.SolveDynamic(s, solverType=exu.DynamicSolverType.GeneralizedAlpha)
            ok = True
        except exu.SolverError:
            ok = False
        walls.append(time.perf_counter() - t0)
        if ok and commands:          # the pre-step function never sees the end time: record it here
            p = np.array(mbs.GetNodeOutput(node, exu.OutputVariableType.Position))
            r = np.array(mbs.GetNodeOutput(node, exu.OutputVariableType.RotationMatrix)).reshape(3, 3)
            marks[round(until / MARK)] = (p, r)
        it = mbs.sys["dynamicSolver"].it
        out = {"marks": marks, "ok": ok, "t_reached": float(it.currentTime), "newton": it.newtonStepsCount,
               "jacobians": it.newtonJacobiCount, "n_ode2": m["n_ode2"]}
        if not ok:
            break
    steps = int(round(until / dt))
    wall = statistics.median(walls)
    ks = sorted(out["marks"])
    from scipy.spatial.transform import Rotation
    how = "commands from Python every step" if commands else "no command update (legs held, no motion)"
    return {"label": f"Exudyn {exu.config.Version()}, ANCF cable legs ({n} el./leg), rigid platform, Δt = {dt * 1e3:g} ms, "
                     + how, "commands": commands,
            "case": case, "elements_per_leg": n, "dt": dt, "until": until, "ode2_coordinates": out["n_ode2"],
            "converged": out["ok"], "t_reached": out["t_reached"], "steps": steps, "wall_time_s": wall,
            "walls_s": walls, "steps_per_s": steps / wall if out["ok"] else math.nan,
            "rtf": until / wall if out["ok"] else math.nan,
            "newton_iterations_mean": out["newton"] / steps, "jacobians": out["jacobians"],
            "compare_with": COMPARE.get((case, dt)) if commands else None,
            "_marks": np.array(ks), "_pos": np.array([out["marks"][k][0] for k in ks]),
            "_quat": (Rotation.from_matrix([out["marks"][k][1] for k in ks]).as_quat(canonical=True, scalar_first=True)
                      if ks else np.empty((0, 4)))}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--until", type=float, default=20.0)
    args = ap.parse_args(argv)
    if not available():
        print("exudyn is not installed (optional peer): skipped")
        return
    sys.path.insert(0, str(ROOT))
    for c, dt, cmd in [(c, dt, True) for c, dt in CASES] + [("ancf4", 1e-3, False)]:
        r = run(c, dt, args.until, commands=cmd)
        print(f"{r['label']}: {r['ode2_coordinates']} ODE2 coordinates, converged {r['converged']}, "
              f"{r['steps_per_s']:.0f} steps/s, RTF {r['rtf']:.2f}, Newton {r['newton_iterations_mean']:.2f}/step")


if __name__ == "__main__":
    main()
