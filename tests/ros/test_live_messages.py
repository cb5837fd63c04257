"""What the node publishes (fast fillers) equals what it records (flexmb_io.messages dicts)."""

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("flexmb_msgs.msg")

from dds_harness import ROOT  # noqa: E402

from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import load_scene  # noqa: E402
from flexmb_io import messages as M  # noqa: E402
from ros2_node.convert import to_dict  # noqa: E402
from ros2_node.live_messages import LiveMessages  # noqa: E402
from flexmb_io.shells import shell_triangles  # noqa: E402
from flexmb_io.twin import TwinRunner  # noqa: E402


@pytest.mark.parametrize("scene", ["stewart_platform_bars.yaml", "rps_manipulator.yaml", "stewart_platform_shell.yaml",
                                   "radiator_panels.yaml"])
def test_live_fillers_equal_the_recorded_dicts(scene):
    model = compile_scene(load_scene(str(ROOT / "scenes" / scene)))
    runner = TwinRunner(model)
    runner.start()
    for _ in range(5):
        runner.step()
    s = runner.sample()
    live = LiveMessages(s)
    timing = M.StatusTiming(step_wall_time=1e-4, steps=5, deadline_misses=1, real_time_factor=0.99,
                            command_stamp=0.004, command_latency=2e-4, rejected_commands=3, message="x")
    pairs = [(live.fill_joint_state(s), M.joint_state(s)), (live.fill_actuator_state(s), M.actuator_state(s)),
             (live.fill_status(s, timing), M.status(s, timing)), (live.fill_clock(s.t), M.clock(s.t)),
             (live.fill_shape(s, runner.member_kinds, runner.shells), M.shape(s, runner.member_kinds, runner.shells))]
    pairs += [(live.fill_pose(s, i), M.platform_pose(s, i)) for i in range(len(s.poses))]
    if live.tf_msg is not None:
        pairs.append((live.fill_tf(s), M.tf(s)))
    for msg, d in pairs:
        got = to_dict(msg)
        _assert_contains(got, d, type(msg).__name__)
    # shells: one TRIANGLE_LIST after the members, 3 points per flat triangle (9 per cubic element),
    # at the model's shell nodes; refilled in place at a later state
    shape = live.fill_shape(s, runner.member_kinds, runner.shells)
    tris = [mk for mk in shape.markers if mk.type == M.MARKER_TRIANGLE_LIST]
    assert [mk.ns for mk in tris] == [sh.name for sh in model.shells]
    assert [mk.id for mk in tris] == list(range(len(model.members), len(model.members) + len(model.shells)))
    points_before = [mk.points[0] for mk in tris]
    for _ in range(2):
        runner.step()
    s = runner.sample()
    shape = live.fill_shape(s, runner.member_kinds, runner.shells)
    _assert_contains(to_dict(shape), M.shape(s, runner.member_kinds, runner.shells), "MarkerArray (refilled)")
    q = runner.sim.state.q
    for mk, info, p0 in zip(shape.markers[len(model.members):], model.shells, points_before):
        assert mk.points[0] is p0                                    # no new objects per message
        assert len(mk.points) == 27 * info.tri.shape[0]
        got = np.array([[p.x, p.y, p.z] for p in mk.points])
        assert np.array_equal(got, q[info.ydofs][shell_triangles(info.tri).ravel()]), info.name
    if model.scene.outputs and any(o.kind == "joint_angle" for o in model.scene.outputs):
        assert len(s.joint_names) > 0 and len(to_dict(live.fill_joint_state(s))["name"]) == len(s.actuator_names) + len(s.joint_names)


def _assert_contains(got, want, where):
    """Every field of ``want`` is in ``got`` with the same value (``got`` may have more fields)."""
    if isinstance(want, dict):
        for k, v in want.items():
            assert k in got, f"{where}.{k} missing"
            _assert_contains(got[k], v, f"{where}.{k}")
    elif isinstance(want, list):
        assert len(got) == len(want), f"{where}: {len(got)} items, expected {len(want)}"
        for i, (g, w) in enumerate(zip(got, want)):
            _assert_contains(g, w, f"{where}[{i}]")
    else:
        assert got == want, f"{where}: {got!r} != {want!r}"
