"""rerun viewing: ``flexmb run --rrd``, ``flexmb view`` of recordings, the headless PNG.

Each ``.rrd`` is read back with ``rerun.chunk.RrdReader`` and checked for its entities (one per
member, the platform, the scalar series), its time points on ``sim_time`` and some values against
what the run reported. The recordings are written by ``twin_recording`` (this directory) from a
short simulation of the bar-legged Stewart platform.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "stewart_platform_bars.yaml"
MEMBERS = ["leg1", "leg2", "leg3", "leg4", "leg5", "leg6", "edge_ab", "edge_bc", "edge_ca"]
SERIES = ["plots/actuators/length", "plots/actuators/command", "plots/actuators/velocity",
          "plots/actuators/force", "plots/solver/newton_iterations", "plots/solver/residual",
          "plots/energy"]
PLATFORM = ["world/platforms/platform/frame", "world/platforms/platform/mesh",
            "world/platforms/platform/outline"]
ORANGE = (242, 140, 26)          # actuator colour (flexmb_io.messages), as 8-bit RGB
RADIATOR = ROOT / "scenes" / "radiator_panels.yaml"     # two shells of 4 cubic triangles (28 nodes)
SHELLS = ["world/shells/panel1", "world/shells/panel2"]

try:
    import rerun  # noqa: F401
    HAVE_RERUN = True
except ImportError:
    HAVE_RERUN = False
needs_rerun = pytest.mark.skipif(not HAVE_RERUN, reason="rerun-sdk is not installed")


def flexmb(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "flexmb.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=ROOT, timeout=timeout)


class Rrd:
    """What an .rrd holds: time points (ns on sim_time) and static components per entity."""

    def __init__(self, path: Path):
        import pyarrow as pa
        from rerun.chunk import RrdReader

        reader = RrdReader(str(path))
        self.recordings = reader.recordings()
        self.blueprints = reader.blueprints()
        self.times: dict[str, set[int]] = defaultdict(set)
        self.static: dict[str, set[str]] = defaultdict(set)
        self.static_values: dict[str, dict] = defaultdict(dict)      # entity → component → last value
        self._rows: dict[str, list[tuple[int, dict]]] = defaultdict(list)
        for chunk in reader.stream():
            path_ = chunk.entity_path.strip("/")
            rb = chunk.to_record_batch()
            comps = [n for n in rb.schema.names if ":" in n]
            if chunk.is_static:
                self.static[path_].update(comps)
                for c in comps:
                    self.static_values[path_][c] = rb.column(c).to_pylist()[-1]
                continue
            ts = rb.column("sim_time").cast(pa.int64()).to_pylist()
            cols = {c: rb.column(c).to_pylist() for c in comps}
            for i, t in enumerate(ts):
                self.times[path_].add(t)
                self._rows[path_].append((t, {c: v[i] for c, v in cols.items()}))

    def last(self, entity: str, component: str):
        """The value of ``component`` at the entity's last time."""
        return max(self._rows[entity], key=lambda r: r[0])[1][component]


def _grid_ns(times_s) -> set[int]:
    return {int(round(t * 1e9)) for t in times_s}


def _rgba_u32(rgba) -> int:
    """RGBA in [0, 1] → rerun's packed 0xRRGGBBAA."""
    from flexmb_io.viz.layout import rgba8

    r, g, b, a = rgba8(rgba)
    return (r << 24) | (g << 16) | (b << 8) | a


def _radiator_triangles() -> list[np.ndarray]:
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene import load_scene
    from flexmb_io.shells import shell_triangles

    return [shell_triangles(info.tri) for info in compile_scene(load_scene(RADIATOR)).shells]


# --- fixtures ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A bare .mcap of 200 steps (every step recorded) with the scene attached."""
    pytest.importorskip("mcap_ros2")
    from twin_recording import write_recording

    return write_recording(SCENE, tmp_path_factory.mktemp("rec") / "stewart.mcap", until=0.2)


@pytest.fixture(scope="module")
def shell_recording(tmp_path_factory):
    """The radiator panels (two shells, nine members), every 5 ms step to 0.05 s, scene attached."""
    pytest.importorskip("mcap_ros2")
    from twin_recording import write_recording

    return write_recording(RADIATOR, tmp_path_factory.mktemp("shells") / "radiator.mcap", until=0.05)


@pytest.fixture(scope="module")
def recording_rrd(recording, tmp_path_factory):
    if not HAVE_RERUN:
        pytest.skip("rerun-sdk is not installed")
    out = tmp_path_factory.mktemp("view") / "stewart.rrd"
    p = flexmb("view", recording["path"], "--rrd", out)
    assert p.returncode == 0, p.stderr
    return out, p.stdout


# --- the command line without rerun -----------------------------------------------------------
def test_cli_loads_without_rerun_and_names_the_missing_package():
    code = ("import sys; sys.modules['rerun'] = None\n"       # `import rerun` now raises ImportError
            "import flexmb_io.viz.cli, flexmb.cli\n"
            "p = flexmb.cli.build_parser()\n"
            "a = p.parse_args(['view', 'x.mcap', '--png', 'o.png'])\n"
            "r = p.parse_args(['run', 's.yaml', '--rrd', 'o.rrd', '--rrd-period', '0.02'])\n"
            "assert a.func.__name__ == 'cmd_view' and r.rrd == 'o.rrd' and r.rrd_period == 0.02\n"
            "assert not any(m.startswith('rerun') and sys.modules[m] is not None for m in sys.modules)\n"
            "sys.exit(flexmb.cli.main(['view', 'x.mcap']))\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert p.returncode == 1, p.stderr
    assert "flexmb view needs rerun-sdk" in p.stderr


# --- flexmb run --rrd -------------------------------------------------------------------------
@needs_rerun
def test_run_rrd_logs_members_platform_and_series_every_10_ms(tmp_path):
    rrd, js = tmp_path / "run.rrd", tmp_path / "run.json"
    p = flexmb("run", SCENE, "--until", "0.2", "--rrd", rrd, "--json", js, "--quiet")
    assert p.returncode == 0, p.stderr
    summary = json.loads(js.read_text())
    assert summary["rrd"] == str(rrd) and summary["steps"] == 200
    data = Rrd(rrd)
    assert len(data.recordings) == 1 and len(data.blueprints) == 1
    expected = _grid_ns(0.01 * k for k in range(21))           # t = 0 and every 10 ms to 0.2 s
    for entity in [f"world/members/{m}" for m in MEMBERS] + PLATFORM + SERIES:
        assert data.times[entity] == expected, entity
    # solver wall time and real-time factor exist from the first step on (not at t = 0)
    assert data.times["plots/solver/step_wall_time"] == expected - {0}
    # static geometry and styles are logged once
    assert {"LineStrips3D:radii", "LineStrips3D:colors"} <= data.static["world/members/leg1"]
    assert "Points3D:positions" in data.static["world/supports"]
    assert "Mesh3D:triangle_indices" in data.static["world/platforms/platform/mesh"]
    # the last logged state is the state the run ended in
    lengths = data.last("plots/actuators/length", "Scalars:scalars")
    assert len(lengths) == 6 and lengths[0] == pytest.approx(summary["outputs"]["leg1_length"], abs=1e-12)
    forces = data.last("plots/actuators/force", "Scalars:scalars")
    assert forces[3] == pytest.approx(summary["outputs"]["leg4_force"], rel=1e-12)
    pos = data.last("world/platforms/platform/frame", "Transform3D:translation")
    assert np.allclose(pos, summary["outputs"]["platform"]["position"], atol=1e-6)   # float32 in rerun
    leg1 = np.array(data.last("world/members/leg1", "LineStrips3D:strips")[0])
    assert leg1.shape == (2, 3) and np.linalg.norm(leg1[1] - leg1[0]) == pytest.approx(lengths[0], abs=1e-6)


@needs_rerun
def test_run_rrd_period_always_logs_the_last_step(tmp_path):
    rrd = tmp_path / "run.rrd"
    p = flexmb("run", SCENE, "--until", "0.123", "--rrd", rrd, "--rrd-period", "0.05", "--quiet")
    assert p.returncode == 0, p.stderr
    times = Rrd(rrd).times
    assert times["world/members/leg1"] == _grid_ns([0.0, 0.05, 0.1, 0.123])
    assert times["plots/energy"] == times["world/members/leg1"]


# --- flexmb view of a recording ---------------------------------------------------------------
@needs_rerun
def test_view_mcap_uses_header_stamps_and_the_attached_scene(recording, recording_rrd):
    rrd, stdout = recording_rrd
    assert "scene 'stewart_platform_bars'" in stdout and "t = 0 … 0.2 s" in stdout
    data = Rrd(rrd)
    expected = _grid_ns(recording["times"])
    assert len(expected) == 201                              # t = 0 and every 1 ms step
    for entity in [f"world/members/{m}" for m in MEMBERS] + PLATFORM + SERIES + ["plots/actuators/input"]:
        assert data.times[entity] == expected, entity
    # member kinds, supports and the camera come from scene.yaml
    assert "Points3D:positions" in data.static["world/supports"]
    # values survive MCAP → rerun: the final recorded state
    from flexmb_io.viz.recording import Recording

    last = [m.msg for m in Recording(recording["path"]).messages({"/flexmb_twin/actuator_states"})][-1]
    assert data.last("plots/actuators/length", "Scalars:scalars") == pytest.approx(list(last.lengths), abs=0)
    assert data.last("plots/actuators/force", "Scalars:scalars") == pytest.approx(list(last.axial_forces), abs=0)


@needs_rerun
def test_view_without_scene_draws_from_the_markers(tmp_path):
    from twin_recording import write_recording

    rec = write_recording(SCENE, tmp_path / "bare.mcap", until=0.02, attach_scene=False)
    rrd = tmp_path / "bare.rrd"
    p = flexmb("view", rec["path"], "--rrd", rrd)
    assert p.returncode == 0, p.stderr
    assert "no scene attached" in p.stdout
    data = Rrd(rrd)
    expected = _grid_ns(rec["times"])
    for m in MEMBERS:
        assert data.times[f"world/members/{m}"] == expected, m
    assert data.times["world/platforms/platform/frame"] == expected
    # no scene: no supports, no platform outline (its nodes are unknown), colours from the markers
    assert "world/supports" not in data.static and "world/platforms/platform/mesh" not in data.times
    rgba = data.static["world/members/leg1"]
    assert "LineStrips3D:colors" in rgba


@needs_rerun
def test_view_rosbag2_directory_with_period(tmp_path):
    from twin_recording import write_recording

    rec = write_recording(SCENE, tmp_path / "bag", until=0.05, bag=True)
    assert (tmp_path / "bag" / "metadata.yaml").is_file()
    rrd = tmp_path / "bag.rrd"
    p = flexmb("view", rec["path"], "--rrd", rrd, "--period", "0.01")
    assert p.returncode == 0, p.stderr
    data = Rrd(rrd)
    assert data.times["world/members/leg3"] == _grid_ns(0.01 * k for k in range(6))
    assert data.times["plots/solver/residual"] == data.times["world/members/leg3"]


@needs_rerun
def test_view_reads_a_bag_of_the_recorder(tmp_path):
    """Bags of ``flexmb_io.bag.recorder`` (log time = simulated time, chunks per 0.25 s) view alike."""
    recorder = pytest.importorskip("flexmb_io.bag.recorder")
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.report import TwinReporter
    from flexmb_core.scene import load_scene
    from flexmb_core.simulator import Simulator
    from flexmb_io import messages, topics

    model = compile_scene(load_scene(SCENE))
    sim = Simulator(model)
    sim.initialize()
    reporter = TwinReporter(model)
    kinds = tuple(m.kind for m in model.members)
    times = []
    with recorder.BagRecorder(tmp_path / "bag", scene_path=str(SCENE), scene_text=None, settings={}) as rec:
        for k in range(31):
            if k:
                sim.step()
            s = reporter.read(sim)
            times.append(s.t)
            out = ((topics.SHAPE, messages.shape(s, kinds)),
                   (topics.STATUS, messages.status(s, messages.StatusTiming())),
                   (topics.ACTUATOR_STATES, messages.actuator_state(s)),
                   (topics.PLATFORM_POSE, messages.platform_pose(s)),
                   (topics.JOINT_STATES, messages.joint_state(s)))
            for topic, msg in out:
                rec.write(topic.resolved(), topic.type, msg, s.t)
    rrd = tmp_path / "bag.rrd"
    p = flexmb("view", tmp_path / "bag", "--rrd", rrd)
    assert p.returncode == 0, p.stderr
    assert "scene 'stewart_platform_bars'" in p.stdout
    data = Rrd(rrd)
    for entity in [f"world/members/{m}" for m in MEMBERS] + PLATFORM + SERIES:
        assert data.times[entity] == _grid_ns(times), entity


@needs_rerun
def test_view_reads_a_file_cut_short(recording, tmp_path):
    """A killed recorder leaves no summary and an unfinished chunk: keep what is complete."""
    from flexmb_io.viz.view import view_recording
    from twin_recording import write_recording

    rec = write_recording(SCENE, tmp_path / "long.mcap", until=0.2, attach_scene=False, chunk_size=16 << 10)
    raw = Path(rec["path"]).read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(raw[: int(0.6 * len(raw))])
    with pytest.warns(UserWarning, match="damaged or unfinished"):
        report = view_recording(cut, rrd_path=str(tmp_path / "cut.rrd"))
    assert report.truncated
    n = report.messages["/flexmb_twin/shape"]
    assert 0 < n < 201
    assert len(Rrd(tmp_path / "cut.rrd").times["world/members/leg1"]) == n


# --- shells --------------------------------------------------------------------------------------
@needs_rerun
def test_run_rrd_logs_each_shell_as_a_mesh(tmp_path, shell_recording):
    """``flexmb run --rrd``: one Mesh3D per shell, its 9 flat triangles per element static, the
    node positions every 10 ms, in the shell colour."""
    from flexmb_io.messages import SHELL_RGBA

    rrd = tmp_path / "radiator.rrd"
    p = flexmb("run", RADIATOR, "--until", "0.05", "--rrd", rrd, "--quiet")
    assert p.returncode == 0, p.stderr
    data = Rrd(rrd)
    for entity, tri, name in zip(SHELLS, _radiator_triangles(), ("panel1", "panel2")):
        assert data.times[entity] == _grid_ns(0.01 * k for k in range(6)), entity
        assert data.times[entity] == data.times["world/members/mast"]
        static = data.static_values[entity]
        assert np.array_equal(np.array(static["Mesh3D:triangle_indices"]), tri) and tri.shape == (36, 3)
        assert static["Mesh3D:albedo_factor"] == [_rgba_u32(SHELL_RGBA)]
        last = np.array(data.last(entity, "Mesh3D:vertex_positions"))
        assert last.shape == (28, 3)
        # the final state of this run is the recording's (the same scene and steps), to float32
        assert np.allclose(last, shell_recording["shell_nodes"][name], rtol=0, atol=1e-6)


@needs_rerun
def test_view_folds_the_triangle_lists_back_onto_the_shell_nodes(shell_recording, tmp_path):
    """``flexmb view`` of a bag with its scene: the TRIANGLE_LIST markers become the same meshes
    as a live run logs (28 nodes, the model's triangles), at every recorded stamp."""
    rrd = tmp_path / "view.rrd"
    p = flexmb("view", shell_recording["path"], "--rrd", rrd)
    assert p.returncode == 0, p.stderr
    assert "scene 'radiator_panels'" in p.stdout
    data = Rrd(rrd)
    expected = _grid_ns(shell_recording["times"])
    assert len(expected) == 11
    for entity, tri, name in zip(SHELLS, _radiator_triangles(), ("panel1", "panel2")):
        assert data.times[entity] == expected, entity
        assert np.array_equal(np.array(data.static_values[entity]["Mesh3D:triangle_indices"]), tri)
        last = np.array(data.last(entity, "Mesh3D:vertex_positions"), dtype=np.float32)
        assert np.array_equal(last, shell_recording["shell_nodes"][name].astype(np.float32)), name
    for m in ("mast", "post0", "deploy1", "fold0"):
        assert data.times[f"world/members/{m}"] == expected, m


@needs_rerun
def test_view_without_scene_draws_each_triangle_list_as_is(tmp_path):
    """No scene: the mesh is the marker's triangle list (3 vertices a triangle), in the marker's
    colour, and the camera's bounds take in the shells."""
    from flexmb_io.messages import SHELL_RGBA
    from flexmb_io.viz.view import view_recording
    from twin_recording import write_recording

    rec = write_recording(RADIATOR, tmp_path / "bare.mcap", until=0.01, attach_scene=False)
    rrd = tmp_path / "bare.rrd"
    report = view_recording(rec["path"], rrd_path=str(rrd))
    assert report.scene is None and report.messages["/flexmb_twin/shape"] == 3
    lo, hi = report.layout.bounds
    data = Rrd(rrd)
    for entity, tri, name in zip(SHELLS, _radiator_triangles(), ("panel1", "panel2")):
        nodes = rec["shell_nodes"][name]
        # the bounds are the first shape's; the panels have moved by < 1 µm since
        assert (nodes >= lo - 1e-6).all() and (nodes <= hi + 1e-6).all(), name
        static = data.static_values[entity]
        assert np.array_equal(np.array(static["Mesh3D:triangle_indices"]), np.arange(108).reshape(36, 3))
        assert static["Mesh3D:albedo_factor"] == [_rgba_u32(SHELL_RGBA)]
        last = np.array(data.last(entity, "Mesh3D:vertex_positions"), dtype=np.float32)
        assert np.array_equal(last, nodes[tri.ravel()].astype(np.float32)), name
        assert data.times[entity] == _grid_ns(rec["times"])


def test_layout_of_a_shell_scene_knows_its_meshes_and_bounds():
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene import load_scene
    from flexmb_io.viz.layout import TwinLayout

    model = compile_scene(load_scene(RADIATOR))
    lay = TwinLayout.from_model(model)
    assert [s.name for s in lay.shells] == ["panel1", "panel2"]
    for s, info, tri in zip(lay.shells, model.shells, _radiator_triangles()):
        assert np.array_equal(s.triangles, tri)
        # the first place of each node in the triangle list gives it back
        assert np.array_equal(info.x0[tri.ravel()][s.first], info.x0)
        assert (info.x0 >= lay.bounds[0]).all() and (info.x0 <= lay.bounds[1]).all()
    assert lay.shell("panel1") is lay.shells[0] and lay.shell("new").triangles is None
    # a scene of one generated shell (no named nodes at all), clamped along an edge: the camera
    # frames the mesh and every node of the clamped edge is a support point
    from flexmb_core.scene.loader import parse_yaml, scene_from_dict

    path = ROOT / "scenes" / "shell_slit_annulus.yaml"
    data = parse_yaml(path.read_text())
    data["shells"]["plate"]["mesh"]["divisions"] = [1, 6]           # 12 triangles: a quick compile
    annulus = compile_scene(scene_from_dict(data, source=str(path)))
    assert not annulus.scene.nodes
    lay = TwinLayout.from_model(annulus)
    plate = annulus.shell("plate")
    assert np.array_equal(lay.bounds, [plate.x0.min(axis=0), plate.x0.max(axis=0)])
    clamped = np.asarray(plate.edges["start"])
    assert np.array_equal(lay.support_points, plate.x0[clamped]) and len(clamped) == 4
    assert lay.support_labels[0] == f"plate.start[{clamped[0]}] (clamp)"


def test_view_rejects_what_is_not_a_recording(tmp_path):
    if not HAVE_RERUN:
        pytest.skip("rerun-sdk is not installed")
    p = flexmb("view", tmp_path / "missing")
    assert p.returncode == 1
    assert "missing: no such file or directory" in p.stderr
    (tmp_path / "empty").mkdir()
    p = flexmb("view", tmp_path / "empty")
    assert p.returncode == 1 and "no .mcap file in this directory" in p.stderr


# --- headless PNG -----------------------------------------------------------------------------
@needs_rerun
def test_png_snapshot_shows_the_legs(recording, tmp_path):
    from flexmb_io.viz.snapshot import rerun_executable, vulkan_drivers

    if rerun_executable() is None or not vulkan_drivers():
        pytest.skip("no rerun viewer binary or no Vulkan driver (apt-get install mesa-vulkan-drivers)")
    image = pytest.importorskip("PIL.Image")
    png = tmp_path / "shot.png"
    p = flexmb("view", recording["path"], "--png", png, "--window-size", "800x450", timeout=240)
    assert p.returncode == 0, p.stderr
    assert f"wrote {png}" in p.stdout
    img = np.asarray(image.open(png).convert("RGB")).astype(int)
    assert img.shape[2] == 3 and img.shape[1] >= 800 and img.shape[0] >= 450
    # the actuator legs are drawn: many pixels of their colour in the 3D view (left 60 %)
    left = img[:, : int(0.6 * img.shape[1])]
    orange = np.all(np.abs(left - np.array(ORANGE)) < 40, axis=2)
    assert orange.mean() > 0.005, f"only {orange.mean():.4f} of the 3D view is leg-coloured"


def test_exaggeration_magnifies_bending_and_keeps_ends_rigid_motion_and_stretch():
    """A straight member, then moved rigidly, stretched 1 % and bent by a small arc: drawn ×K,
    its ends stay, its chord points stay on the chord, and the deviation from the chord is K
    times the computed one; a member whose shape does not change is drawn as computed."""
    from scipy.spatial.transform import Rotation

    from flexmb_io.viz.view import Exaggeration

    s = np.linspace(0.0, 1.0, 7)
    straight = np.outer(s, [0.5, 0.0, 0.0])
    ex = Exaggeration(40.0)
    assert np.array_equal(ex.apply("leg", straight), straight)
    rot = Rotation.from_rotvec([0.3, -0.2, 0.7])
    bend = 1e-4 * np.sin(np.pi * s)
    moved = rot.apply(np.column_stack((0.505 * s, bend, 0.0 * s))) + [1.0, 2.0, 3.0]
    drawn = ex.apply("leg", moved)
    assert np.allclose(drawn[[0, -1]], moved[[0, -1]], rtol=0, atol=1e-15)
    chord = moved[0] + s[:, None] * (moved[-1] - moved[0])
    assert np.allclose(drawn - chord, 40.0 * (moved - chord), rtol=0, atol=1e-14)
    assert np.linalg.norm(drawn - chord, axis=1).max() == pytest.approx(40.0 * 1e-4, rel=1e-12)
    assert np.allclose(Exaggeration(1.0).apply("leg", moved), moved)


@needs_rerun
def test_view_rejects_a_bad_exaggeration(recording, tmp_path):
    res = flexmb("view", recording, "--exaggerate", "-2", "--rrd", tmp_path / "x.rrd")
    assert res.returncode != 0
    assert "--exaggerate must be a finite factor > 0, got -2.0" in res.stderr + res.stdout
    assert "Traceback" not in res.stderr
