"""Path following in statics (issue 16): arc length and displacement control through limit
points, snap-backs and snap-throughs; critical points from the tangent's pivots; snap-through
reports of load-controlled runs; strict solver keys."""

import copy
import json
import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.interpolate import CubicSpline

from builders import build, cantilever
from flexmb_core.errors import SceneError
from flexmb_core.integrators.path_following import PathFollower, PathLoads
from flexmb_core.model.assembly import assemble
from flexmb_core.scene.loader import parse_yaml

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"

# Lee's frame load maximum (load factor, kN), own converged reference: the same frame with 40 + 40
# cubic elements (h = 0.03 m, 2163 free DOFs) traced with Δl = 0.02 m, λ at the zero of dλ/ds of
# the cubic Hermite interpolant between the bracketing points; 20 + 20 elements give 1.851405564,
# 15 + 15 give 1.851405861 (the sequence converges like h^6.2).
LEE_LIMIT_REF = 1.851405504


def scene_dict(name: str) -> dict:
    """A shipped scene as nested dicts, parsed as flexmb parses it (``2.0e11`` is a number)."""
    return parse_yaml((SCENES / f"{name}.yaml").read_text(), name)


def trace(d: dict) -> PathFollower:
    _, sim = build(d)
    pf = PathFollower(sim)
    pf.initialize()
    pf.run()
    return pf


def lee(k: int = 1, **solver) -> dict:
    """The shipped Lee frame with 5k elements per member and solver keys replaced."""
    d = scene_dict("lee_frame")
    for m in d["members"].values():
        m["elements"] = 5 * k
    d["solver"].update(solver)
    return d


def test_lee_frame_through_limit_points_and_snap_back():
    pf = trace(scene_dict("lee_frame"))
    rep = pf.report()
    assert pf.finished and "load factor" in rep["finished"]
    kinds = [c["kind"] for c in rep["limit_points"]]
    assert kinds == ["load_maximum", "load_minimum"]
    top, bottom = rep["limit_points"]
    assert abs(top["load_factor"] - LEE_LIMIT_REF) / LEE_LIMIT_REF < 0.005
    assert top["displacement"] == pytest.approx(-0.4872, abs=2e-3)
    assert bottom["load_factor"] < 0.0                     # the frame has to be pulled back up
    lam = np.array(rep["path"]["load_factor"])
    u = np.array(rep["path"]["displacement"])
    i0, i1 = top["step"], bottom["step"]
    # snap-back: between the limit points the displacement turns back (|v| shrinks by > 5 cm)
    mid = u[i0:i1]
    turn = int(np.argmin(mid))
    assert mid[turn] < top["displacement"] - 0.05 and mid[turn:].max() > mid[turn] + 0.05
    # a smooth path: every increment is bounded by the spherical arc length (positions and ψ‖u₁‖Δλ)
    spec = pf.spec.arc_length
    du, dlam = np.abs(np.diff(u)), np.abs(np.diff(lam))
    assert du.max() <= spec.step.max * (1 + 1e-9)
    assert (dlam * spec.psi * math.sqrt(pf._u1sq)).max() <= spec.step.max * (1 + 1e-9)
    assert dlam.max() < 0.6 and du.max() < 0.05
    # the 3D frame buckles out of plane between its pins before the in-plane maximum
    bif = rep["bifurcations"]
    assert [b["kind"] for b in bif] == ["stability_loss", "stability_gain"]
    assert 1.6 < bif[0]["load_factor"] < top["load_factor"] and bif[0]["step"] < top["step"]
    assert bif[1]["step"] > bottom["step"]


def test_lee_frame_limit_load_converges_under_mesh_refinement():
    """5, 10, 15 cubic elements per member against the 40-element reference: within 0.5 % from
    the coarsest mesh on, errors falling like h^p with p > 4 (measured ≈ 6.2)."""
    h, err = [], []
    for k in (1, 2, 3):
        d = lee(k, until_displacement=-0.5, arc_length={"initial": 0.1, "max": 0.1, "kind": "spherical"})
        del d["solver"]["until_load_factor"]
        limits = trace(d).report()["limit_points"]
        assert limits and limits[0]["kind"] == "load_maximum"
        h.append(1.2 / (5 * k))
        err.append(abs(limits[0]["load_factor"] - LEE_LIMIT_REF) / LEE_LIMIT_REF)
    assert err[0] < 0.005
    assert err[0] > err[1] > err[2]
    rate = np.polyfit(np.log(h), np.log(err), 1)[0]
    assert rate > 4.0, f"errors {err}: rate {rate:.2f}"


def test_lee_frame_out_of_plane_bifurcation_is_physical():
    """The bifurcation the pivots report (λ_b) is real: with an out-of-plane force of 0.05 % of the
    load the frame leaves its plane and its load peaks just below λ_b, below the planar maximum."""
    perfect = trace(lee(until_displacement=-0.4)).report()
    lam_b = perfect["bifurcations"][0]["load_factor"]          # first converged point past it
    d = lee(until_displacement=-0.4)
    d["loads"]["forces"]["P"]["force"] = [0.0, -1000.0, 0.5]
    imperfect = trace(d)
    peak = imperfect.report()["limit_points"]
    assert peak and peak[0]["kind"] == "load_maximum"
    lam_peak = peak[0]["load_factor"]
    assert 0.97 * lam_b < lam_peak < lam_b < LEE_LIMIT_REF
    elbow_z = imperfect.model.node_ydofs[imperfect.model.node("elbow"), 2]
    assert abs(imperfect.state.q[elbow_z]) > 0.1                 # m out of the plane


def test_shallow_arch_snap_through_by_arc_length():
    cyl = trace(scene_dict("shallow_arch")).report()
    assert [c["kind"] for c in cyl["limit_points"]] == ["load_maximum", "load_minimum"]
    assert cyl["bifurcations"] == []
    top, bottom = cyl["limit_points"]
    assert 0.0 < bottom["load_factor"] < 0.6 * top["load_factor"]    # a snap-through under load control
    assert np.all(np.diff(cyl["path"]["displacement"]) < 0.0)       # no snap-back: the crown keeps going down
    d = scene_dict("shallow_arch")
    d["solver"]["arc_length"] = {"initial": 0.002, "max": 0.004, "kind": "spherical", "psi": 1.0}
    sph = trace(d).report()
    for a, b in zip(cyl["limit_points"], sph["limit_points"]):
        # the vertex of the Hermite interpolant is exact to O(Δs⁴): both kinds agree to 1e-5
        assert b["load_factor"] == pytest.approx(a["load_factor"], rel=1e-5)
        assert b["displacement"] == pytest.approx(a["displacement"], abs=1e-5)


def test_displacement_control_reproduces_the_arc_length_path():
    d = scene_dict("shallow_arch")
    d["solver"]["arc_length"] = {"initial": 0.001, "max": 0.001}
    arc = trace(d).report()
    u_a, lam_a = np.array(arc["path"]["displacement"]), np.array(arc["path"]["load_factor"])
    spline = CubicSpline(u_a[::-1], lam_a[::-1])                   # u decreases along the path
    d = scene_dict("shallow_arch")
    del d["solver"]["arc_length"], d["solver"]["until_displacement"]
    d["solver"].update(control="displacement",
                       displacement={"node": "crown", "component": "y", "to": -0.04, "initial": 0.001, "max": 0.001})
    disp = trace(d)
    rep = disp.report()
    assert rep["displacement"] == pytest.approx(-0.04, abs=1e-12)  # lands on 'to'
    u_d, lam_d = np.array(rep["path"]["displacement"]), np.array(rep["path"]["load_factor"])
    assert np.max(np.abs(lam_d - spline(u_d))) < 1e-4 * lam_a.max()
    for a, b in zip(arc["limit_points"], rep["limit_points"]):
        assert b["kind"] == a["kind"] and b["load_factor"] == pytest.approx(a["load_factor"], rel=1e-5)


def _load_controlled_arch(tmp_path: Path, allow: bool) -> Path:
    d = scene_dict("shallow_arch")
    d["loads"]["forces"]["P"]["signal"] = {"kind": "ramp", "start": 0.0, "end": 0.6, "duration": 1.0}
    d["solver"] = {"analysis": "static", "dt": 0.05, "until": 1.0, "max_iterations": 100,
                   "monitor": {"node": "crown", "component": "y"}, "allow_snap_through": allow}
    path = tmp_path / f"arch_load_{allow}.yaml"
    path.write_text(yaml.safe_dump(d))
    return path


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "flexmb_core.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=ROOT, timeout=300)


def test_load_controlled_snap_through_is_reported_and_fails_the_run(tmp_path):
    out = tmp_path / "snap.json"
    p = _cli("run", _load_controlled_arch(tmp_path, False), "--json", out, "--quiet")
    assert p.returncode == 2, p.stderr
    assert "snap-through at load step 15" in p.stderr and "solver.allow_snap_through: true" in p.stderr
    s = json.loads(out.read_text())
    assert s["completed"] is False and s["unconverged_steps"] == 0 and s["control"] == "load"
    assert "integrator" not in s
    [snap] = s["snap_through"]
    # λ = 0.6 t passes the maximum 0.442 at t = 0.737: the crown jumps from the rising branch to
    # the inverted one
    assert snap["t"] == pytest.approx(0.75) and "jump" in snap["kind"]
    assert snap["displacement_before"] > -0.01 and snap["displacement"] < -0.025
    assert snap["jump_ratio"] > 3.0
    out2 = tmp_path / "allowed.json"
    p = _cli("run", _load_controlled_arch(tmp_path, True), "--json", out2, "--quiet")
    assert p.returncode == 0, p.stderr
    s2 = json.loads(out2.read_text())
    assert s2["completed"] is True and len(s2["snap_through"]) == 1


def test_lee_frame_cli_reports_limit_points_without_integrator(tmp_path):
    out = tmp_path / "lee.json"
    p = _cli("run", "scenes/lee_frame.yaml", "--json", out, "--quiet")
    assert p.returncode == 0, p.stderr
    s = json.loads(out.read_text())
    assert s["completed"] and s["analysis"] == "static" and s["control"] == "arc_length"
    assert "integrator" not in s and "dt" not in s
    assert [c["kind"] for c in s["limit_points"]] == ["load_maximum", "load_minimum"]
    for c in s["limit_points"] + s["bifurcations"]:
        assert set(c) >= {"step", "load_factor", "displacement", "kind"}
    assert s["monitor"] == {"node": "load", "component": "y"}


def test_load_derivative_matches_finite_difference():
    """p = −∂R/∂λ (dead force + conservative and follower moments scaled by λ) against a central
    difference of the residual in λ at a deformed state."""
    d = cantilever(length=1.0, elements=2, forces={"f": {"node": "tip", "force": [0.0, -300.0, 100.0]}},
                   moments={"c": {"node": "tip", "member": "beam", "moment": [0.0, 0.0, 40.0]},
                            "w": {"node": "tip", "member": "beam", "moment": [5.0, 20.0, 0.0], "follower": True}},
                   solver={"analysis": "static", "control": "arc_length", "arc_length": {"initial": 0.01},
                           "monitor": {"node": "tip", "component": "y"}, "until_load_factor": 1.0})
    model, sim = build(d)
    loads = PathLoads(model, sim.ws)
    q = model.q0 + 0.05 * np.random.default_rng(1).standard_normal(model.ndof)
    lam, h = 0.7, 1e-4

    def residual(x):
        loads.set(x)
        assemble(model, sim.ws, q, sim.state.lam, False)
        return (sim.ws.r - sim.ws.f_ext)[model.free]

    fd = -(residual(lam + h) - residual(lam - h)) / (2 * h)
    p = loads.direction(q)[model.free]
    assert np.max(np.abs(p - fd)) < 1e-7 * np.max(np.abs(p))


def test_diverging_newton_prints_no_numpy_warning():
    """A force of 1e300 N overflows the first iterate: reported as a non-finite residual, silently."""
    d = cantilever(length=1.0, elements=1, forces={"tip": {"node": "tip", "force": [0.0, 1e300, 1e300]}},
                   solver={"analysis": "static", "dt": 1.0, "until": 1.0, "on_unconverged": "stop"})
    _, sim = build(d)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = sim._static.solve_at(sim.state, 1.0, sim.state.lam)
    assert not res.converged and "non-finite" in res.message


def test_path_following_refuses_time_dependent_loads():
    d = scene_dict("shallow_arch")
    d["loads"]["forces"]["P"]["signal"] = {"kind": "ramp", "start": 0.0, "end": 1.0, "duration": 1.0}
    _, sim = build(d)
    with pytest.raises(SceneError, match=r"<test>:loads\.forces\.P\.signal: control: arc_length scales every "
                                         r"load by the load factor; its signal must be constant, got kind 'ramp'"):
        PathFollower(sim)


def test_displacement_control_of_a_supported_component_is_refused():
    d = scene_dict("shallow_arch")
    del d["solver"]["arc_length"]
    d["solver"].update(control="displacement", displacement={"node": "left", "component": "x", "to": 0.01,
                                                             "initial": 0.001})
    _, sim = build(d)
    with pytest.raises(SceneError, match="the x displacement of node 'left' is held by a support"):
        PathFollower(sim)


ARC = {"analysis": "static", "control": "arc_length", "arc_length": {"initial": 0.002},
       "monitor": {"node": "crown", "component": "y"}, "until_load_factor": 1.0}


@pytest.mark.parametrize("solver, where, message", [
    ({"analysis": "static", "control": "sideways"}, "solver.control",
     "expected one of ['load', 'arc_length', 'displacement'], got 'sideways'"),
    ({**ARC, "arc_length": None}, "solver.arc_length", "expected a mapping, got NoneType None"),
    ({k: v for k, v in ARC.items() if k != "arc_length"}, "solver",
     "control: arc_length needs an 'arc_length' block"),
    ({**ARC, "arc_length": {"initial": 0.01, "min": 0.1}}, "solver.arc_length",
     "expected min ≤ initial ≤ max for the arc length, got min 0.1, initial 0.01, max 0.1 (m)"),
    ({**ARC, "arc_length": {"initial": 0.01, "kind": "elliptic"}}, "solver.arc_length.kind",
     "expected one of ['cylindrical', 'spherical'], got 'elliptic'"),
    # keys that apply to some values of an earlier key only share one message (the schema's ``when``)
    ({**ARC, "arc_length": {"initial": 0.01, "psi": 2.0}}, "solver.arc_length.psi",
     "key(s) ['psi'] apply to kind: spherical only (kind is 'cylindrical')"),
    ({**ARC, "arc_length": {"initial": 0.01, "steps": 3}}, "solver.arc_length", "unknown key(s) ['steps']"),
    ({**ARC, "arc_length": {"initial": -0.01}}, "solver.arc_length.initial", "expected a positive number (m)"),
    ({**ARC, "monitor": {"node": "crown", "component": "w"}}, "solver.monitor.component",
     "expected one of ['x', 'y', 'z'], got 'w'"),
    ({**ARC, "monitor": {"node": "nowhere", "component": "y"}}, "solver.monitor.node", "unknown node 'nowhere'"),
    ({k: v for k, v in ARC.items() if k != "monitor"}, "solver", "control: arc_length needs a 'monitor'"),
    ({k: v for k, v in ARC.items() if k != "until_load_factor"}, "solver",
     "control: arc_length needs a goal: 'until_load_factor' and/or 'until_displacement'"),
    ({**ARC, "displacement": {"node": "crown", "component": "y", "to": -0.01, "initial": 0.001}},
     "solver.displacement", "key(s) ['displacement'] apply to control: displacement only (control is 'arc_length')"),
    ({"analysis": "static", "until_load_factor": 1.0}, "solver.until_load_factor",
     "key(s) ['until_load_factor'] apply to control: arc_length or displacement"),
    ({"analysis": "dynamic", "control": "arc_length"}, "solver.control",
     "key(s) ['control'] apply to analysis: static only (analysis is 'dynamic')"),
    ({"analysis": "static", "control": "displacement",
      "displacement": {"node": "crown", "component": "y", "to": 0.0, "initial": 0.001}},
     "solver.displacement.to", "expected a non-zero target displacement (m), got 0"),
    ({"analysis": "static", "control": "displacement", "displacement": {"node": "crown", "component": "y"}},
     "solver.displacement", "missing required key(s) ['initial', 'to']"),
    ({"analysis": "static", "allow_snap_through": "yes"}, "solver.allow_snap_through",
     "expected true or false, got 'yes'"),
    ({**ARC, "max_steps": 0}, "solver.max_steps", "expected an integer ≥ 1, got 0"),
    ({"analysis": "static", "control": "load", "until_displacement": -0.1,
      "monitor": {"node": "crown", "component": "y"}}, "solver.until_displacement",
     "key(s) ['until_displacement'] apply to control: arc_length or displacement"),
])
def test_bad_solver_keys_are_rejected(solver, where, message):
    d = scene_dict("shallow_arch")
    d["solver"] = solver
    with pytest.raises(SceneError) as info:
        build(copy.deepcopy(d))
    text = str(info.value)
    assert text.startswith(f"<test>:{where}: "), text
    assert message in text, text
