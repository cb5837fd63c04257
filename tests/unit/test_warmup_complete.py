"""Warm-up compiles everything the time loop calls (issue 15, item 4).

A kernel first called inside ``step()`` compiles there (1–2 s with a cold numba cache) or loads
from the cache (milliseconds): either way the first timed step of a real-time twin misses its
deadline. Instead of timing a cold-cache start (a minute of compiling on 2 cores, and a timing in a
test), this checks the cause directly and with any cache state: every numba dispatcher of flexmb
gains no new compiled signature between the end of ``TwinRunner.start()`` (warm-up and initial
state) and the end of the first steps — a dispatcher's ``signatures`` list grows exactly when it is
compiled or loaded for a call.
"""

from __future__ import annotations

import importlib
import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

import flexmb_core
import flexmb_io
import ros2_node
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene
from flexmb_io.twin import RunnerOptions, TwinRunner

SCENES = Path(__file__).resolve().parents[2] / "scenes"
# twins a node serves: bar legs, frame legs on bars (the demo), a shell platform, a boom with joints and a
# frame actuator
TWINS = ("stewart_platform_bars.yaml", "stewart_platform_1el_truss.yaml", "stewart_platform_shell.yaml",
         "boom_step.yaml")
# modules that need a ROS or viewer install are not the time loop's
SKIP = ("ros2_node.node", "ros2_node.node_cli", "ros2_node.player", "ros2_node.live", "flexmb_io.viz",
        "ros2_node.demo")


def _dispatchers() -> dict[str, numba.core.registry.CPUDispatcher]:
    out = {}
    for pkg in (flexmb_core, flexmb_io, ros2_node):
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            if info.name.startswith(SKIP):
                continue
            try:
                mod = importlib.import_module(info.name)
            except ImportError:
                continue
            for name, obj in vars(mod).items():
                if isinstance(obj, numba.core.registry.CPUDispatcher) and obj.__module__ == mod.__name__:
                    out[f"{mod.__name__}.{name}"] = obj
    return out


def _grown_after_start(scene: str) -> dict[str, list[str]]:
    """Kernels that gained a signature during the first 20 steps after ``start()`` (run in a fresh
    process: a kernel an earlier test already called would not show)."""
    model = compile_scene(load_scene(SCENES / scene, {"until": 1.0}))
    runner = TwinRunner(model, options=RunnerOptions())
    kernels = _dispatchers()
    assert "flexmb_core.kernels.frame3d.frame_group" in kernels and "flexmb_io.commands._evaluate_lines" in kernels
    runner.start()
    before = {k: len(d.signatures) for k, d in kernels.items()}
    names = list(model.actuators.names)
    rest = model.actuators.l0.copy()
    for k in range(20):
        if names and k % 5 == 0:         # commands arrive as they do in the node
            assert runner.command_named("/flexmb_twin/actuator_commands", names, rest + 1e-4 * k / 20, None,
                                        0.0) is None
        assert runner.step().advanced
        runner.sample()
    assert np.isfinite(runner.sample().actuator_forces).all()
    return {k: [str(s) for s in d.signatures[before[k]:]] for k, d in kernels.items()
            if len(d.signatures) > before[k]}


@pytest.mark.parametrize("scene", TWINS)
def test_no_kernel_compiles_or_loads_after_start(scene):
    p = subprocess.run([sys.executable, __file__, scene], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    grown = json.loads(p.stdout.strip().splitlines()[-1])
    assert not grown, f"compiled or loaded inside the time loop, not in warm-up: {grown}"


if __name__ == "__main__":
    print(json.dumps(_grown_after_start(sys.argv[1])))
