"""Mechanisms built from the joints of SPEC §5: the 3-RPS manipulator against its forward
kinematics, and the shipped mechanism scenes run without a non-converged step."""

from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import fsolve

from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene, scene_from_dict
from flexmb_core.scene.loader import parse_yaml
from flexmb_core.simulator import Simulator

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def rps_forward_kinematics(base, radial_in, lengths, side, guess):
    """Platform vertices of a 3-RPS: leg i rotates in the plane (radial_in_i, z) about its base
    revolute; the three leg tips must be a triangle of the given side."""
    def tips(th):
        return np.array([base[i] + lengths[i] * (np.cos(th[i]) * radial_in[i] + [0.0, 0.0, np.sin(th[i])])
                         for i in range(3)])

    def closure(th):
        p = tips(th)
        return [np.linalg.norm(p[0] - p[1]) - side, np.linalg.norm(p[1] - p[2]) - side,
                np.linalg.norm(p[2] - p[0]) - side]

    th = fsolve(closure, guess, xtol=1e-12)
    assert np.abs(closure(th)).max() < 1e-12
    return tips(th)


def test_rps_static_pose_equals_forward_kinematics():
    d = parse_yaml((SCENES / "rps_manipulator.yaml").read_text())
    d["materials"]["steel"]["E"] = 2.1e15             # rigid limit: kinematics only
    del d["loads"]["gravity"]
    d["solver"] = {"analysis": "static", "until": 2.0, "dt": 0.25, "tolerance": 1e-11}
    model = compile_scene(scene_from_dict(d, source="rps"))
    sim = Simulator(model)
    sim.initialize()
    sim.run(2.0)
    q = sim.state.q
    got = np.array([q[model.node_ydofs[model.node(n)]] for n in ("p1", "p2", "p3")])
    base = np.array([d["nodes"][f"b{i}"] for i in (1, 2, 3)], dtype=float)
    top0 = np.array([d["nodes"][f"p{i}"] for i in (1, 2, 3)], dtype=float)
    radial_in = (top0 - base) * [1, 1, 0]
    radial_in /= np.linalg.norm(radial_in, axis=1, keepdims=True)
    lengths = [1.0, 0.9, 0.8544003745317532]
    fk = rps_forward_kinematics(base, radial_in, lengths, np.linalg.norm(top0[0] - top0[1]),
                                guess=np.arcsin(0.8 / 0.8544) * np.ones(3))
    assert np.abs(got - fk).max() < 1e-8


@pytest.mark.parametrize("scene, until", [("rps_manipulator.yaml", 0.5), ("actuator_arm.yaml", 0.5),
                                          ("deployable_boom.yaml", 1.0)])
def test_mechanism_scenes_run_clean(scene, until):
    model = compile_scene(load_scene(SCENES / scene, {"until": until}))
    sim = Simulator(model)
    sim.initialize()
    sim.run(until)
    s = sim.summary()
    assert s["unconverged_steps"] == 0 and s["newton_iterations_max"] <= 8
    assert all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in sim.outputs().values()
               if not isinstance(v, dict))


def test_deployable_boom_reaches_the_kinematic_configuration():
    """Revolute support + revolute joint + two bar actuators: the deployed tip equals the planar
    forward kinematics of the commanded lengths (rigid limit, statics)."""
    d = parse_yaml((SCENES / "deployable_boom.yaml").read_text())
    d["materials"]["aluminium"]["E"] = 7.0e14
    d["solver"] = {"analysis": "static", "until": 4.0, "dt": 0.25, "tolerance": 1e-11}
    model = compile_scene(scene_from_dict(d, source="boom"))
    sim = Simulator(model)
    sim.initialize()
    sim.run(4.0)
    tip = np.array(sim.outputs()["tip"])
    l1, l2 = 0.75, 0.95
    g1 = np.array([0.5, -0.6])
    alpha = fsolve(lambda a: np.linalg.norm(0.5 * np.array([np.cos(a[0]), np.sin(a[0])]) - g1) - l1, [0.3],
                   xtol=1e-12)[0]
    k = np.array([np.cos(alpha), np.sin(alpha)])
    m1 = 0.5 * k
    beta = fsolve(lambda b: np.linalg.norm(k + 0.5 * np.array([np.cos(b[0]), np.sin(b[0])]) - m1) - l2,
                  [alpha + 0.3], xtol=1e-12)[0]
    expected = k + np.array([np.cos(beta), np.sin(beta)])
    assert np.abs(tip[:2] - expected).max() < 1e-8
    assert abs(tip[2]) < 1e-12
    # passive joint angles: the shoulder turned by α, the elbow opened from its 150° fold
    out = sim.outputs()
    assert out["shoulder"] == pytest.approx(alpha, abs=1e-7)
    assert out["elbow"] == pytest.approx((beta - alpha) - np.radians(150.0), abs=1e-7)


def test_actuator_velocity_is_the_rate_of_the_length():
    model = compile_scene(load_scene(SCENES / "deployable_boom.yaml", {"until": 1.0}))
    sim = Simulator(model)
    sim.initialize()
    hist = []
    sim.run(1.0, callback=lambda s, r: hist.append((s.state.t, s.outputs()["act2_velocity"],
                                                   float(np.linalg.norm(np.diff(
                                                       s.state.q[model.actuators.end_ydofs[1]].reshape(2, 3), axis=0))))))
    t, vel, length = map(np.array, zip(*hist))
    fd = np.gradient(length, t)
    assert np.abs(vel[5:-5] - fd[5:-5]).max() < 1e-3 * np.abs(vel).max()


def test_tendon_arm_bends_into_the_chord_geometry_arc():
    """Tendon segments (bar actuators) between spacer disks rigidly attached to the backbone
    (rigid corners by multipliers) bend the backbone into an arc of curvature κ with
    2(1/κ − r)·sin(κ s/2) = ℓ (ℓ the actual segment length, s the disk spacing); the tip turns κL.
    That formula idealizes the backbone as a circular arc; with straight tendon chords the moment
    arm (and the curvature) dips between disks by the chord's sagitta (~4.5 mm of 20 mm here) and
    the backbone shortens under the tendon force: measured 0.7 % below κL, bounded at 1.5 %."""
    d = parse_yaml((SCENES / "tendon_arm.yaml").read_text())
    d["solver"] = {"analysis": "static", "until": 2.0, "dt": 0.25, "tolerance": 1e-11}
    d["outputs"].update({f"len{k}": {"kind": "actuator_length", "actuator": f"t{k}"} for k in (1, 2, 3, 4)})
    model = compile_scene(scene_from_dict(d, source="tendon"))
    assert model.n_multipliers == 24
    sim = Simulator(model)
    sim.initialize()
    sim.run(2.0)
    out = sim.outputs()
    lengths = np.array([out[f"len{k}"] for k in (1, 2, 3, 4)])
    assert np.ptp(lengths) < 1e-4 * lengths.mean()           # near-uniform: disks take the small differences
    r, s, total = 0.02, 0.1, 0.4
    kappa = fsolve(lambda k: 2 * (1 / k[0] - r) * np.sin(k[0] * s / 2) - lengths.mean(), [4.0], xtol=1e-14)[0]
    v1, v2 = map(np.array, out["tip_frame"])
    tangent = np.cross(v1, v2)
    angle = np.arctan2(tangent[0], tangent[2])
    assert 0.985 * kappa * total < angle < kappa * total
    tip = np.array(out["tip"])
    arc = np.array([(1 - np.cos(kappa * total)) / kappa, 0.0, np.sin(kappa * total) / kappa])
    assert np.linalg.norm(tip - arc) < 1e-2 * total
    assert out["tendon_force"] > 0                             # the tendon pulls
