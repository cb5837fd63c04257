"""Shells in ``~/shape`` and in recordings: each cubic triangle as its 9 flat triangles (one
TRIANGLE_LIST marker per shell), recorded by ``flexmb run --mcap``, compared by ``flexmb replay``;
and the shape of scenes without shells unchanged to the byte."""

from __future__ import annotations

import json

import numpy as np
import pytest

from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene
from flexmb_io import messages as M
from flexmb_io import topics as T
from flexmb_io import wire
from flexmb_io.bag.reader import BagReader
from flexmb_io.bag.recorder import BagRecorder
from flexmb_io.bag.replay import replay
from flexmb_io.shells import SUBTRIANGLES, ShellShapes, shell_triangles
from flexmb_io.twin import TwinRunner

from bag_helpers import ROOT, STEWART_BARS, flexmb

RADIATOR = "scenes/radiator_panels.yaml"        # 9 members, then 2 shells of 4 cubic triangles
# The 10-node triangle's lattice (vertices 0 1 2; edge nodes 3 4 on 0→1, 5 6 on 1→2, 7 8 on 2→0;
# centroid 9), tiled by hand: 6 triangles pointing like the element, 3 upside down.
HAND_TILING = {(0, 3, 8), (3, 4, 9), (4, 1, 5), (8, 9, 7), (9, 5, 6), (7, 6, 2), (9, 8, 3), (5, 9, 4), (6, 7, 9)}


def _rotations(tri) -> set[tuple[int, int, int]]:
    a, b, c = (int(v) for v in tri)
    return {(a, b, c), (b, c, a), (c, a, b)}


@pytest.fixture(scope="module")
def radiator():
    return compile_scene(load_scene(ROOT / RADIATOR))


# --- the tiling -------------------------------------------------------------------------------
def test_nine_flat_triangles_tile_the_cubic_triangle():
    from flexmb_core.model.shell_geometry import LOCAL_NODES_3L

    assert SUBTRIANGLES.shape == (9, 3) and SUBTRIANGLES.dtype == np.int64
    # the hand tiling, each triangle with the element's orientation (any cyclic start)
    matched = set()
    for t in SUBTRIANGLES:
        hit = _rotations(t) & HAND_TILING
        assert len(hit) == 1, f"{t.tolist()} is not one of the hand tiling's triangles in its orientation"
        matched |= hit
    assert matched == HAND_TILING
    assert sorted(set(SUBTRIANGLES.ravel().tolist())) == list(range(10))          # every node drawn
    xi = LOCAL_NODES_3L[:, 1:] / 3.0                                             # (ξ1, ξ2) of each node
    p = xi[SUBTRIANGLES]                                                         # (9, 3, 2)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    area = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    assert np.allclose(area, 1.0 / 18.0, rtol=0, atol=1e-15)                    # 9 × 1/18 = the element's 1/2
    # conforming: the 9 boundary segments once, the 9 inner edges twice
    edges: dict[tuple[int, int], int] = {}
    for a, b, c in SUBTRIANGLES.tolist():
        for e in ((a, b), (b, c), (c, a)):
            edges[tuple(sorted(e))] = edges.get(tuple(sorted(e)), 0) + 1
    assert sorted(edges.values()) == [1] * 9 + [2] * 9


def test_flat_triangles_of_a_scene_mesh_cover_it_facing_its_normal(radiator):
    for info in radiator.shells:
        tri = shell_triangles(info.tri)
        assert tri.shape == (9 * info.tri.shape[0], 3) and tri.flags.c_contiguous
        x = info.x0[tri]                                                         # (nt, 3, 3)
        n = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])                       # 2 × area × unit normal
        v = info.x0[info.tri[:, :3]]
        flat_area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum()
        assert 0.5 * np.linalg.norm(n, axis=1).sum() == pytest.approx(flat_area, rel=1e-12)   # a flat panel
        assert (np.einsum("ij,ij->i", n, info.normal0[tri].mean(axis=1)) > 0).all(), info.name


def test_shell_shapes_gather_the_nodes_from_the_state(radiator):
    shells = ShellShapes(radiator)
    assert shells.names == ("panel1", "panel2") and len(shells) == 2
    q = np.random.default_rng(3).normal(size=radiator.ndof)
    xyz = shells.xyz
    shells.read(q)
    assert shells.xyz is xyz                                                     # filled in place
    for i, info in enumerate(radiator.shells):
        assert np.array_equal(shells.points[i], q[info.ydofs])
        assert np.array_equal(shells.vertices(i), q[info.ydofs][shell_triangles(info.tri).ravel()])
    empty = ShellShapes(compile_scene(load_scene(ROOT / STEWART_BARS)))
    assert len(empty) == 0 and empty.xyz.shape == (0, 3)
    empty.read(q)                                                                # nothing to do, no error


# --- scenes without shells: the same bytes as before -----------------------------------------
def test_shape_of_a_scene_without_shells_is_byte_identical_to_the_reference_bag():
    """The first ``~/shape`` of ``bags/stewart_bars_appendix`` (recorded before shells existed),
    re-made now, with the model's (empty) shells, serializes (rosbags, :mod:`flexmb_io.wire`) to the
    very same bytes as the former hand-written encoder wrote."""
    bag = ROOT / "bags" / "stewart_bars_appendix"
    topic = T.SHAPE.resolved()
    first = next(iter(BagReader(bag).messages({topic})))
    assert first.log_time_ns == 0
    model = compile_scene(load_scene(ROOT / STEWART_BARS))
    runner = TwinRunner(model)
    s = runner.start()
    assert len(runner.shells) == 0
    d = M.shape(s, runner.member_kinds, runner.shells)
    assert wire.plain(d) == wire.plain(M.shape(s, runner.member_kinds))
    assert wire.serialize(T.SHAPE.type, d) == bytes(first.data)


# --- flexmb run --mcap and flexmb replay of a shell scene -------------------------------------
@pytest.fixture(scope="module")
def radiator_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("shells") / "radiator"
    p = flexmb("run", RADIATOR, "--until", "0.1", "--quiet", "--mcap", out)
    assert p.returncode == 0, p.stderr
    return out


def test_run_bag_has_one_triangle_list_per_shell_through_the_shell_nodes(radiator_bag, radiator):
    r = BagReader(radiator_bag)
    shapes = [m.decode() for m in r.messages({T.SHAPE.resolved()})]
    assert len(shapes) == 3                                                      # 20 Hz: t = 0, 0.05, 0.1 s
    members = [m.name for m in radiator.members]
    for msg in shapes:
        assert [mk.ns for mk in msg.markers] == members + ["panel1", "panel2"]
        assert [mk.id for mk in msg.markers] == list(range(len(members) + 2))
        assert [mk.type for mk in msg.markers] == [M.MARKER_LINE_STRIP] * len(members) + [M.MARKER_TRIANGLE_LIST] * 2
        for mk in msg.markers[len(members):]:
            assert len(mk.points) == 4 * 9 * 3                                   # 4 elements × 9 triangles × 3
            assert (mk.scale.x, mk.scale.y, mk.scale.z) == (1.0, 1.0, 1.0) and mk.action == M.MARKER_ADD
            assert (mk.color.r, mk.color.g, mk.color.b, mk.color.a) == pytest.approx(M.SHELL_RGBA, abs=1e-7)  # float32
            st, st0 = mk.header.stamp, msg.markers[0].header.stamp
            assert mk.header.frame_id == "world" and (st.sec, st.nanosec) == (st0.sec, st0.nanosec)
            assert mk.pose.orientation.w == 1.0 and mk.pose.position.x == 0.0
    # t = 0: the points are the model's shell nodes, three per flat triangle, in the state the run starts from
    runner = TwinRunner(radiator)
    runner.start()
    q = runner.sim.state.q
    for mk, info in zip(shapes[0].markers[len(members):], radiator.shells):
        got = np.array([[p.x, p.y, p.z] for p in mk.points])
        assert np.array_equal(got, q[info.ydofs][shell_triangles(info.tri).ravel()]), info.name


def test_run_bag_of_a_shell_scene_replays_bit_identically(radiator_bag, tmp_path):
    p = flexmb("replay", radiator_bag, "--json", tmp_path / "r.json")
    assert p.returncode == 0, p.stdout + p.stderr
    rep = json.loads((tmp_path / "r.json").read_text())
    shape = next(f for f in rep["fields"] if (f["topic"], f["field"]) == ("/flexmb_twin/shape", "points"))
    assert shape["identical"] and shape["worst"] == 0.0 and shape["samples"] == 3 * 11      # 11 markers a shape


def test_replay_compares_the_shell_points(tmp_path, radiator):
    """A node-style bag whose last shape has one shell point moved by 1 mm fails the replay at
    that shell; a shell the replayed scene does not have is a mismatch."""
    def record(out, *, move: float = 0.0, rename: bool = False) -> None:
        runner = TwinRunner(radiator)       # no commands: the actuators hold, here and in the replay
        rec = BagRecorder(out, scene_path=str(ROOT / RADIATOR), scene_text=(ROOT / RADIATOR).read_text(),
                          settings={"dt": runner.dt, "node_name": "flexmb_twin", "source": "test"})
        kinds, shells = runner.member_kinds, runner.shells
        s = runner.start()
        for k in range(11):
            if k:
                assert runner.step().advanced
                s = runner.sample()
            if k % 5 == 0:
                d = M.shape(s, kinds, shells)
                if k == 10:
                    d.markers[-1].points[7].z += move
                    if rename:
                        d.markers[-1].ns = "panel3"
                rec.write(T.SHAPE.resolved(), T.SHAPE.type, d, s.t)
        rec.close()

    record(tmp_path / "same")
    rep = replay(tmp_path / "same")
    assert rep.ok and all(f.identical for f in rep.fields), rep.format()
    record(tmp_path / "moved", move=1e-3)
    rep = replay(tmp_path / "moved")
    bad = rep.beyond()
    assert rep.exit_code == 3 and [(f.topic, f.field, f.element) for f in bad] == [(T.SHAPE.resolved(), "points", "panel2")]
    assert bad[0].worst == pytest.approx(1e-3, rel=1e-9) and bad[0].t == pytest.approx(10 * 0.005)
    record(tmp_path / "renamed", rename=True)
    rep = replay(tmp_path / "renamed")
    assert rep.exit_code == 3 and any("marker ns 'panel3' is not a shell of the replay" in m for m in rep.mismatches)
