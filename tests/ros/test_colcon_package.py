"""The ROS 2 package: colcon builds the workspace and the twin starts from it as ``ros2 run`` would.

A temporary workspace holds ``flexmb_msgs`` (``msgs/``), ``tf2_msgs`` (``ros/tf2_msgs``) and the node
(``ros/flexmb``, ament_python), built by PyPI's colcon against the venv's ROS 2 wheels. Then, with the
environment of the workspace's ``install/setup.bash``:

- the install holds every file of the ``flexmb_core``, ``flexmb_io``, ``ros2_node`` and ``flexmb``
  packages, the executables in ``lib/flexmb``, the ament index marker, the launch file and the
  scenes; ``tf2_msgs`` generated the standard RIHS01 hash;
- the twin is started exactly as the *installed* launch file starts it (``flexmb_node`` found through
  the ament index like ``ros2 run``, node name and parameters file as ``launch_ros`` passes them) and
  answers commands over DDS, publishes ``/tf``, and imports the workspace's packages, not the venv's.

The numba kernels compile cold (the install is a new source path): the twin's start takes most of
this test's time. A second, quick build of the node package alone checks ``--symlink-install``.
"""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("flexmb_msgs.msg")
pytest.importorskip("tf2_msgs.msg")

from launch_stub import evaluate, load_launch_file, node_command  # noqa: E402
from twin_drive import drive_lockstep, standard_tfmessage_hash  # noqa: E402

from flexmb_core.model.compile import compile_scene  # noqa: E402
from flexmb_core.scene import load_scene  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = {"flexmb_msgs": ROOT / "msgs", "tf2_msgs": ROOT / "ros" / "tf2_msgs", "flexmb": ROOT / "ros" / "flexmb"}
VENV = Path(sys.prefix)
COLCON = Path(sys.executable).with_name("colcon")
SCENE = "stewart_platform_bars.yaml"


def _sourced_env(setup: Path, base: dict) -> dict:
    """The environment after ``source <setup>`` in bash."""
    out = subprocess.run(["bash", "-c", f"source {shlex.quote(str(setup))} >/dev/null && env -0"], env=base,
                         capture_output=True, check=True, timeout=60).stdout
    return dict(item.split("=", 1) for item in out.decode().split("\0") if "=" in item)


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """(workspace, environment of its install/setup.bash, build seconds)."""
    if not COLCON.exists():
        if os.environ.get("CI") == "true":
            pytest.fail(f"{COLCON} missing: the ros-build extra installs colcon-common-extensions")
        pytest.skip("colcon not installed (pip install -e '.[ros-build]')")
    ws = tmp_path_factory.mktemp("colcon_ws")
    env = dict(os.environ, AMENT_PREFIX_PATH=str(VENV), CMAKE_PREFIX_PATH=str(VENV),
               PATH=f"{VENV / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}")
    cmd = [str(COLCON), "--log-base", str(ws / "log"), "build", "--build-base", str(ws / "build"),
           "--install-base", str(ws / "install"), "--paths", *map(str, PACKAGES.values()),
           "--event-handlers", "console_cohesion+", "--cmake-args", f"-DPython3_EXECUTABLE={VENV / 'bin' / 'python'}",
           "-DCMAKE_BUILD_TYPE=Release", "-Wno-dev"]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, cwd=ws, env=env, capture_output=True, text=True, timeout=900)
    seconds = time.monotonic() - t0
    assert proc.returncode == 0, f"colcon build failed ({seconds:.0f} s):\n{proc.stdout[-6000:]}\n{proc.stderr[-3000:]}"
    print(f"colcon build of {', '.join(PACKAGES)}: {seconds:.1f} s")
    return ws, _sourced_env(ws / "install" / "setup.bash", dict(os.environ)), seconds


def test_install_layout(workspace):
    ws, env, _ = workspace
    install = ws / "install"
    assert {p.name for p in install.iterdir() if p.is_dir()} == set(PACKAGES)
    prefix = install / "flexmb"
    for exe in ("flexmb_node", "flexmb_player", "flexmb"):
        assert os.access(prefix / "lib" / "flexmb" / exe, os.X_OK), exe
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "flexmb").is_file()
    assert (prefix / "share" / "flexmb" / "package.xml").read_text() == (PACKAGES["flexmb"] / "package.xml").read_text()
    assert (prefix / "share" / "flexmb" / "launch" / "twin.launch.py").is_file()
    assert (prefix / "share" / "flexmb" / "scenes" / SCENE).read_text() == (ROOT / "scenes" / SCENE).read_text()
    [site] = list((prefix / "lib").glob("python3*/site-packages"))
    for top in ("flexmb_core", "flexmb_io", "ros2_node", "flexmb"):
        source = {p.relative_to(ROOT).as_posix() for p in (ROOT / top).rglob("*")
                  if p.is_file() and p.suffix != ".pyc" and "__pycache__" not in p.parts}
        installed = {p.relative_to(site).as_posix() for p in (site / top).rglob("*")
                     if p.is_file() and p.suffix != ".pyc" and "__pycache__" not in p.parts}
        assert source == installed, (sorted(source - installed)[:10], sorted(installed - source)[:10])
    tf_json = (install / "tf2_msgs" / "share" / "tf2_msgs" / "msg" / "TFMessage.json").read_text()
    assert standard_tfmessage_hash() in tf_json
    # the workspace's packages come first, as a ROS user's overlay would
    where = subprocess.run([sys.executable, "-c", "import flexmb, flexmb_core, flexmb_io, ros2_node, flexmb_msgs, tf2_msgs as m; "
                            "print('\\n'.join(x.__file__ for x in (flexmb, flexmb_core, flexmb_io, ros2_node, flexmb_msgs, m)))"],
                           env=env, cwd="/", capture_output=True, text=True, check=True, timeout=120).stdout.split()
    assert len(where) == 6 and all(Path(w).is_relative_to(install) for w in where), where


def test_ros2_run_twin_from_the_launch_file_answers_commands(workspace, tmp_path, dds_env, monkeypatch):
    ws, env, build_s = workspace
    # `ros2 run flexmb flexmb_node`: <prefix of flexmb in the ament index>/lib/flexmb/flexmb_node
    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    with monkeypatch.context() as m:
        m.setenv("AMENT_PREFIX_PATH", env["AMENT_PREFIX_PATH"])
        prefix = Path(get_package_prefix("flexmb"))
        launch_file = Path(get_package_share_directory("flexmb")) / "launch" / "twin.launch.py"
        # the installed launch file, with its default scene (resolved through the ament index too)
        _, actions = evaluate(load_launch_file(launch_file), mode="lockstep", play="false")
    [twin] = [a for a in actions if a.kind == "Node"]
    cmd = node_command(twin, prefix, tmp_path / "params.yaml")
    assert cmd[0] == str(ws / "install" / "flexmb" / "lib" / "flexmb" / "flexmb_node")
    scene = twin.kwargs["parameters"][0]["scene"]
    assert scene == str(ws / "install" / "flexmb" / "share" / "flexmb" / "scenes" / SCENE)

    run_env = dict(env, **{k: dds_env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE",
                                                    "OPENBLAS_NUM_THREADS", "PYTHONUNBUFFERED")},
                   NUMBA_CACHE_DIR=str(tmp_path / "numba"))       # the install's kernels: a cache of their own
    model = compile_scene(load_scene(scene))
    log_path = tmp_path / "twin.log"
    t0 = time.monotonic()
    with open(log_path, "w") as log:
        proc = subprocess.Popen(cmd, env=run_env, cwd=tmp_path, stdout=log, stderr=subprocess.STDOUT)
        try:
            out = drive_lockstep(model.actuators.l0, 20, dt=model.scene.solver.dt, alive=lambda: proc.poll() is None,
                                 log=log_path.read_text, timeout_up=400.0)
            answered_s = time.monotonic() - t0
        finally:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
            rc = proc.wait(timeout=60)
    print(f"colcon build {build_s:.1f} s; flexmb_node start to 20 answered commands {answered_s:.1f} s")
    assert rc == 130, log_path.read_text()[-3000:]          # stopped by SIGINT, as documented
    steps = {s.steps for s in out.statuses}
    assert set(range(1, 21)) <= steps and max(steps) == 20       # one step per command, each answered
    stamp = lambda m: m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec  # noqa: E731
    last = [a for a in out.actuator_states if round(stamp(a) / model.scene.solver.dt) == 20][-1]
    assert list(last.commanded_lengths) == pytest.approx([float(x) + 2e-4 for x in model.actuators.l0], abs=1e-12)
    assert out.tf_publishers == [("tf2_msgs/msg/TFMessage", standard_tfmessage_hash())]
    assert out.tf and all(len(m.transforms) >= 1 for m in out.tf)


def test_symlink_install_of_the_node_package(tmp_path):
    """``colcon build --symlink-install`` (setup.py develop): the executables run the repository's sources."""
    if not COLCON.exists():
        pytest.skip("colcon not installed (pip install -e '.[ros-build]')")
    env = dict(os.environ, AMENT_PREFIX_PATH=str(VENV), PATH=f"{VENV / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}")
    proc = subprocess.run([str(COLCON), "--log-base", str(tmp_path / "log"), "build", "--symlink-install",
                           "--build-base", str(tmp_path / "build"), "--install-base", str(tmp_path / "install"),
                           "--paths", str(PACKAGES["flexmb"])], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    run_env = _sourced_env(tmp_path / "install" / "setup.bash", dict(os.environ))
    where = subprocess.run([sys.executable, "-c", "import ros2_node, os; print(os.path.realpath(ros2_node.__file__))"],
                           env=run_env, cwd="/", capture_output=True, text=True, check=True, timeout=120).stdout.strip()
    assert where == str(ROOT / "ros2_node" / "__init__.py")
    exe = tmp_path / "install" / "flexmb" / "lib" / "flexmb" / "flexmb_node"
    usage = subprocess.run([str(exe), "--help"], env=run_env, capture_output=True, text=True, timeout=120)
    assert usage.returncode == 0 and usage.stdout.startswith("usage: flexmb node"), usage.stderr[-2000:]
