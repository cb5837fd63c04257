"""Open an ``.rrd`` in the rerun viewer, or render it to a PNG with no display.

The PNG comes from the native viewer run headless (``rerun --headless``, driven through
``rerun.experimental.ViewerClient``), which renders through Vulkan; on a machine without a GPU,
Mesa's software rasterizer (lavapipe, ``apt-get install mesa-vulkan-drivers``) is enough. Every viewer started here binds its gRPC
server to 127.0.0.1 (rerun's default is 0.0.0.0), and the headless one runs with a private
config directory in which rerun's usage analytics are off.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from flexmb_core.errors import FlexmbError

from .layout import TwinLayout

VULKAN_ICD_DIRS = ("/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d", "/usr/local/share/vulkan/icd.d")


class SnapshotUnavailable(FlexmbError):
    """No rerun viewer binary or no Vulkan driver to render with."""


def rerun_executable() -> str | None:
    """The ``rerun`` viewer binary: the one shipped in the rerun-sdk wheel, else on PATH."""
    try:
        import rerun_cli

        exe = Path(rerun_cli.__file__).resolve().parent / "rerun"
        if exe.is_file() and os.access(exe, os.X_OK):
            return str(exe)
    except ImportError:
        pass
    return shutil.which("rerun")


def vulkan_drivers() -> list[str]:
    """Installed Vulkan ICD manifests (lavapipe is ``lvp_icd.*.json``)."""
    env = os.environ.get("VK_ICD_FILENAMES") or os.environ.get("VK_DRIVER_FILES")
    if env:
        return [p for p in env.split(os.pathsep) if Path(p).is_file()]
    return sorted(str(p) for d in VULKAN_ICD_DIRS for p in Path(d).glob("*.json"))


def _private_env(tmp: Path) -> dict[str, str]:
    """Environment for a throw-away viewer: own config (analytics off), data and runtime dirs."""
    cfg = tmp / "config" / "rerun"
    cfg.mkdir(parents=True)
    (cfg / "analytics.json").write_text(json.dumps({"analytics_enabled": False, "analytics_id": "flexmb-snapshot",
                                                    "metadata": {}}))
    run = tmp / "runtime"
    run.mkdir(mode=0o700)
    env = dict(os.environ, XDG_CONFIG_HOME=str(tmp / "config"), XDG_DATA_HOME=str(tmp / "data"),
               XDG_RUNTIME_DIR=str(run), RERUN_APP_ONLY="true")
    # only errors: INFO/WARN lines also pop up as notifications over the rendered views
    env["RUST_LOG"] = "error"
    return env


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _connect(url: str, proc: subprocess.Popen, timeout: float):
    from rerun.experimental import ViewerClient

    deadline = time.monotonic() + timeout
    while True:
        try:
            client = ViewerClient.connect(url)
            client.get_state()
            return client
        except Exception as exc:                # the gRPC server is not up yet
            if proc.poll() is not None or time.monotonic() > deadline:
                raise FlexmbError(f"the headless rerun viewer did not answer on {url} ({exc})") from None
            time.sleep(0.1)


def screenshot(rrd: str | Path, png: str | Path, layout: TwinLayout | None = None, *, size: str = "1600x900",
               timeout: float = 120.0) -> Path:
    """Render ``rrd`` to ``png`` with the headless native viewer, at the last time of ``sim_time``.

    The viewer is driven through ``rerun.experimental.ViewerClient``: open the recording, wait
    until it has loaded, move the time cursor to the end, and save the screenshot once two
    successive frames agree (an ``.rrd`` is indexed first and its chunks fetched on demand, so the
    first frames can still be empty — ``rerun --screenshot-to`` alone caught them). The side, time
    and top panels are collapsed; a ``layout`` also sets the 3D camera.

    Raises
    ------
    SnapshotUnavailable
        No viewer binary or no Vulkan driver (the message says what to install).
    FlexmbError
        The viewer did not start, load or paint in time.
    """
    from .blueprint import TIMELINE

    exe = rerun_executable()
    if exe is None:
        raise SnapshotUnavailable("no rerun viewer binary (pip install 'rerun-sdk==0.41.*')")
    if not vulkan_drivers():
        raise SnapshotUnavailable("no Vulkan driver to render with; on a machine without a GPU install "
                                  "Mesa's software one: apt-get install mesa-vulkan-drivers")
    png = Path(png).resolve()
    png.parent.mkdir(parents=True, exist_ok=True)
    png.unlink(missing_ok=True)
    deadline = time.monotonic() + timeout
    tail = ""
    with tempfile.TemporaryDirectory(prefix="flexmb-snapshot-") as tmpdir:
        tmp = Path(tmpdir)
        port = _free_port()
        log = open(tmp / "viewer.log", "w")
        proc = subprocess.Popen([exe, "--headless", "--bind", "127.0.0.1", "--port", str(port),
                                 "--hide-welcome-screen", "--window-size", size],
                                env=_private_env(tmp), stdout=log, stderr=subprocess.STDOUT)
        try:
            client = _connect(f"rerun+http://127.0.0.1:{port}/proxy", proc, 30.0)
            opened = client.open(str(Path(rrd).resolve()))
            store = opened.store_ids[0] if opened.store_ids else None
            end = _wait_loaded(client, TIMELINE, deadline)
            _views_only(client, store, layout)
            if end is not None:
                client.set_time(TIMELINE, duration=np.timedelta64(end, "ns"), play_state="paused", recording=store)
            previous = None
            while time.monotonic() < deadline:
                image = client.take_screenshot()
                if image == previous:
                    break
                previous = image
                time.sleep(0.5)
            client.save_screenshot(str(png))
        finally:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            log.close()
            tail = "\n".join((tmp / "viewer.log").read_text(errors="replace").strip().splitlines()[-8:])
    if not png.is_file():
        raise FlexmbError(f"the headless rerun viewer wrote no {png}:\n{tail}")
    return png


def _views_only(client, store, layout: TwinLayout | None) -> None:
    """Edit the recording's blueprint in the viewer: side, time and top panels out of the picture
    and, with a layout, the 3D camera of :func:`~flexmb_io.viz.blueprint.eye_controls` (so older
    recordings get it too). The file is not touched."""
    from .blueprint import WORLD, eye_pose

    bp = dict(client.get_blueprint(of="recording", store_id=store).blueprint)
    bp["/blueprint_panel"] = {"PanelBlueprint": {"state": "Collapsed"}}
    bp["/selection_panel"] = {"PanelBlueprint": {"state": "Collapsed"}}
    bp["/top_panel"] = {"PanelBlueprint": {"state": "Hidden"}}
    time_panel = dict(bp.get("/time_panel", {}).get("TimePanelBlueprint", {}))
    bp["/time_panel"] = {"TimePanelBlueprint": time_panel | {"state": "Collapsed"}}
    eye = eye_pose(layout) if layout is not None else None
    if eye is not None:
        fields = {"kind": "Orbital", "eye_up": [0.0, 0.0, 1.0], "position": eye[0].tolist(),
                  "look_target": eye[1].tolist()}
        for key, value in list(bp.items()):
            view = value.get("ViewBlueprint", {})
            if view.get("class_identifier") == "3D" and view.get("space_origin", "").strip("/") == WORLD:
                bp[f"{key}/EyeControls3D"] = {"EyeControls3D": fields}
    client.set_blueprint(bp, store_id=store)


def _wait_loaded(client, timeline: str, deadline: float) -> int | None:
    """Poll until nothing is loading and the recording has data; the end of ``timeline`` (ns)."""
    while True:
        state = client.get_state()
        recs = [r for r in state.recordings if r.timelines]
        if not state.loading and recs:
            ends = [t.end for r in recs for t in r.timelines if t.name == timeline and t.end is not None]
            return max(ends) if ends else None
        if time.monotonic() > deadline:
            raise FlexmbError("the headless rerun viewer did not finish loading the recording in time")
        time.sleep(0.1)


def open_viewer(rrd: str | Path) -> subprocess.Popen:
    """Start the native viewer on ``rrd`` in its own session (it outlives this process).

    Raises
    ------
    SnapshotUnavailable
        No viewer binary, or no display to open a window on.
    """
    exe = rerun_executable()
    if exe is None:
        raise SnapshotUnavailable("no rerun viewer binary (pip install 'rerun-sdk==0.41.*')")
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise SnapshotUnavailable("no display (DISPLAY/WAYLAND_DISPLAY unset): keep the recording with "
                                  "--rrd OUT and open it where there is one (rerun OUT), or use --png")
    return subprocess.Popen([exe, "--bind", "127.0.0.1", "--port", "auto", str(rrd)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
