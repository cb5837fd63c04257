"""Shells where the seed paper uses them: the deployable radiator (hinge lines, director ties,
actuators) follows rigid-body kinematics, and the Stewart twin with a shell plate tracks the
commanded pose like the rigid-triangle platform."""

import math
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from flexmb_core.model.assembly import assemble
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene
from flexmb_core.simulator import Simulator
from flexmb_core.tracking import PoseTracker

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def _rigid_angles(l_deploy: float, l_fold: float) -> tuple[float, float]:
    """Panel angles (rad) of the rigid mechanism for the commanded lengths (scene comment)."""
    theta = brentq(lambda th: math.hypot(math.cos(th) - 1.2, math.sin(th) + 0.5) - l_deploy, -0.2, 1.3)
    phi = math.acos((1.09 - l_fold ** 2) / 0.6) - math.pi / 3
    return theta, phi


def test_radiator_panels_unfold_along_the_rigid_kinematics():
    model = compile_scene(load_scene(SCENES / "radiator_panels.yaml", {"until": 10.5}))
    sim = Simulator(model)
    sim.initialize()
    y = lambda q, n: q[model.node_ydofs[model.node(n)]]
    worst_theta = worst_phi = 0.0
    for t in np.arange(1.0, 10.51, 0.5):
        sim.run(t)
        q = sim.state.q
        lengths = sim.command_lengths(sim.state.t)
        theta_r, phi_r = _rigid_angles(lengths[1], lengths[3])
        q1, r1 = y(q, "q1"), y(q, "r1")
        theta = math.atan2(q1[2], q1[1])
        d2 = r1 - q1
        phi = math.atan2(d2[2], d2[1]) - theta
        worst_theta = max(worst_theta, abs(theta - theta_r))
        worst_phi = max(worst_phi, abs(phi - phi_r))
    assert math.degrees(worst_theta) < 1e-3            # measured 1.3e-5°
    assert math.degrees(worst_phi) < 0.15              # measured 0.074° (panel2's inertia on thin rods)
    assert math.degrees(abs(phi - phi_r)) < 0.01       # flat at the end: measured 0.003°
    assert np.allclose(y(sim.state.q, "r1"), [2.0, 2.0, 0.0], atol=2e-4)
    assert sim.stats.unconverged_steps == 0
    assemble(model, sim.ws, sim.state.q, sim.state.lam, False, sim.state.mult)
    assert np.abs(sim.ws.rc).max() < 1e-9              # the director ties hold


def test_stewart_twin_with_a_shell_plate_tracks_like_the_rigid_triangle():
    results = {}
    for name in ("stewart_platform_bars", "stewart_platform_shell"):
        model = compile_scene(load_scene(SCENES / f"{name}.yaml", {"until": 1.5}))
        sim = Simulator(model)
        sim.initialize()
        tracker = PoseTracker(model)
        sim.run(1.5, callback=lambda s, r: tracker.update(s.state.t, s.state.q))
        results[name] = (tracker.summary(), sim)
    bars, shell = results["stewart_platform_bars"][0], results["stewart_platform_shell"][0]
    assert shell["max_position_error_m"] < 1e-5 and shell["max_orientation_error_rad"] < 2e-5
    # same legs and payload, a plate of about the truss's mass: the pose errors agree to within 30 %
    assert abs(shell["max_position_error_m"] / bars["max_position_error_m"] - 1.0) < 0.3
    sim = results["stewart_platform_shell"][1]
    centre = sim.outputs()["plate_centre"]["position"][2]
    corners = np.mean([sim.state.q[sim.model.node_ydofs[sim.model.node(n)]][2] for n in "ABC"])
    assert 1e-5 < corners - centre < 1e-3               # the plate sags between its legs (0.3 mm)
