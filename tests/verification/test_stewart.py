"""Stewart platform twin (seed appendix): the scene runs, the pose observer is exact for rigid
motion, the command program is checked against the scene, and the platform tracks the command."""

import copy
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from flexmb_core.errors import SceneError
from flexmb_core.model.compile import compile_scene
from flexmb_core.observers import platform_pose
from flexmb_core.scene import load_scene, scene_from_dict
from flexmb_core.scene.loader import parse_yaml
from flexmb_core.simulator import Simulator

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "stewart_platform.yaml"


@pytest.fixture(scope="module")
def model():
    return compile_scene(load_scene(SCENE))


def test_pose_observer_recovers_a_rigid_motion(model):
    rot = Rotation.from_rotvec([0.2, -0.4, 0.9])
    shift = np.array([0.1, -0.3, 0.25])
    q = model.q0.copy()
    for n in ("A", "B", "C"):
        d = model.node_ydofs[model.node(n)]
        q[d] = rot.apply(model.q0[d]) + shift
    pos, quat = platform_pose(model, q, ("A", "B", "C"))
    centroid0 = np.mean([model.q0[model.node_ydofs[model.node(n)]] for n in "ABC"], axis=0)
    assert np.allclose(pos, rot.apply(centroid0) + shift, atol=1e-14)
    x, y, z, w = rot.as_quat()
    assert np.allclose(quat, np.sign(w) * np.array([w, x, y, z]), atol=1e-14)


def test_program_must_match_the_scene_geometry():
    d = parse_yaml(SCENE.read_text())
    bad = copy.deepcopy(d)
    bad["nodes"]["A"][2] = 1.1
    with pytest.raises(SceneError, match="must match the program's"):
        compile_scene(scene_from_dict(bad, source="s.yaml"))
    bad = copy.deepcopy(d)
    bad["commands"]["actuators"] = bad["commands"]["actuators"][:5]
    with pytest.raises(SceneError, match="drives 6 actuators, got 5"):
        compile_scene(scene_from_dict(bad, source="s.yaml"))


def test_platform_tracks_the_appendix_command(model):
    """First second (the blended start): realistic steel legs track within 1e-5 m and 1e-4 rad."""
    sim = Simulator(model)
    sim.initialize()
    pos_err, ang_err = [], []

    def check(s, res):
        out = s.outputs()["platform"]
        p_ref, q_ref = s.model.program.reference_pose(s.state.t)     # the scene's law (blends included)
        pos_err.append(np.linalg.norm(np.array(out["position"]) - p_ref))
        dot = min(1.0, abs(float(np.dot(out["orientation_wxyz"], q_ref))))
        ang_err.append(2 * np.arccos(dot))

    sim.run(1.0, callback=check)
    assert sim.summary()["unconverged_steps"] == 0
    assert max(pos_err) < 1e-5
    assert max(ang_err) < 1e-4
    # legs push the 48 kg mechanism up: compression in every leg
    forces = [sim.outputs()[k] for k in ("leg1_force", "leg4_force")]
    assert all(f < 0 for f in forces)


@pytest.mark.parametrize("start, switch_blend, continuity", [("blended", 0.0, 2), ("exact", 0.0, 2),
                                                              ("blended", 0.5, 2), ("blended", 0.5, 4)])
def test_tabulated_command_equals_the_law(model, start, switch_blend, continuity):
    """The Hermite table of the appendix law (1 ms grid, one-sided rates) is exact to 1e-11 m,
    including around the rate jump at t = 10 s and through the blended switch."""
    from flexmb_core.commands import StewartAppendixProgram
    from flexmb_core.scene.schema import CommandProgramSpec

    prog = StewartAppendixProgram(CommandProgramSpec("stewart_appendix", tuple("abcdef"), start, 1.0,
                                                     switch_blend, continuity))
    ts = np.concatenate([np.random.default_rng(3).uniform(0, 20, 500), np.linspace(9.7, 10.3, 301),
                         [0.0, 9.9995, 10.0, 10.0004, 20.0, 25.0]])
    err = max(np.abs(prog.lengths(t) - prog.exact_lengths(t)).max() for t in ts)
    assert err < 1e-11


BARS = SCENE.parent / "stewart_platform_bars.yaml"


def _track(path, until, **material):
    d = parse_yaml(path.read_text())
    d["materials"]["steel"].update(material)
    d["solver"]["until"] = until
    sim = Simulator(compile_scene(scene_from_dict(d, source=str(path))))
    sim.initialize()
    from flexmb_core.tracking import PoseTracker
    tracker = PoseTracker(sim.model)
    sim.run(until, callback=lambda s, r: tracker.update(s.state.t, s.state.q))
    assert sim.summary()["unconverged_steps"] == 0
    return tracker.summary()


def test_rigid_limit_tracks_the_appendix_for_20_s():
    """Legs 10⁴ × stiffer than steel: the platform follows the commanded pose (forward kinematics of
    the commanded lengths) within 1e-5 m and 1e-5 rad over the whole 20 s trajectory."""
    tr = _track(BARS, 20.0, E=2.1e15)
    assert tr["max_position_error_m"] < 1e-5
    assert tr["max_orientation_error_rad"] < 1e-5


def test_tracking_deviation_scales_with_leg_compliance():
    """The deviation of the real (steel) legs is elastic: 10× stiffer legs, ≈10× smaller error."""
    soft = _track(BARS, 3.0)
    stiff = _track(BARS, 3.0, E=2.1e12)
    assert 1e-6 < soft["max_position_error_m"] < 1e-4
    assert stiff["max_position_error_m"] == pytest.approx(soft["max_position_error_m"] / 10, rel=0.2)
