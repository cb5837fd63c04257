"""Every njit kernel compiles exactly one signature: a new dtype or layout would silently compile
(and cache) another specialization and cost seconds at start-up."""

import inspect
from pathlib import Path

import numba
import pytest

import flexmb_core.integrators.energy as energy_mod
import flexmb_core.integrators.fast as fast_mod
import flexmb_core.integrators.packs as packs_mod
import flexmb_core.integrators.path_step as path_step_mod
import flexmb_core.kernels.constraints as constraints_mod
import flexmb_core.kernels.frame3d as frame_mod
import flexmb_core.kernels.guard as guard_mod
import flexmb_core.kernels.moments as moments_mod
import flexmb_core.kernels.scatter as scatter_mod
import flexmb_core.kernels.shell as shell_mod
import flexmb_core.kernels.truss as truss_mod
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene
from flexmb_core.simulator import Simulator

SCENES = Path(__file__).resolve().parents[2] / "scenes"
MODULES = (frame_mod, truss_mod, moments_mod, energy_mod, constraints_mod, scatter_mod, shell_mod, guard_mod,
           fast_mod, packs_mod, path_step_mod)


def _kernels():
    for mod in MODULES:
        for name, obj in inspect.getmembers(mod):
            if isinstance(obj, numba.core.registry.CPUDispatcher) and obj.__module__ == mod.__name__:
                yield f"{mod.__name__}.{name}", obj


def test_each_kernel_compiles_one_signature():
    for scene in ("cantilever_b1.yaml", "actuator_arm.yaml", "tendon_arm.yaml", "deployable_boom.yaml",
                  "radiator_panels.yaml", "shell_roll_up.yaml"):
        model = compile_scene(load_scene(SCENES / scene, {"until": 0.02}))
        sim = Simulator(model)
        sim.warmup()
        sim.initialize()
        sim.run(0.02)
        sim.outputs()
    kernels = dict(_kernels())
    assert kernels, "no kernels found"
    used = {k: v for k, v in kernels.items() if v.signatures}
    assert "flexmb_core.kernels.frame3d.frame_group" in used
    assert "flexmb_core.kernels.shell.shell_group" in used
    assert "flexmb_core.kernels.constraints.director_tie_group" in used
    for name, disp in used.items():
        assert len(disp.signatures) == 1, f"{name} compiled {len(disp.signatures)} signatures: {disp.signatures}"


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.__name__)
def test_kernels_are_cached(module):
    for name, disp in _kernels():
        if name.startswith(module.__name__):
            assert disp._cache.__class__.__name__ != "NullCache", f"{name} lacks cache=True"
