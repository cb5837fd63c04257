"""Every njit kernel compiles exactly one signature: a new dtype or layout would silently compile
(and cache) another specialization and cost seconds at start-up. Every kernel a step runs is
compiled without numba's runtime (:mod:`flexmb_core.jit`)."""

import inspect
from pathlib import Path

import numba
import numpy as np
import pytest
from numba import njit

import flexmb_core.commands as commands_mod
import flexmb_core.faults as faults_mod
import flexmb_core.integrators.energy as energy_mod
import flexmb_core.integrators.fast as fast_mod
import flexmb_core.integrators.fused as fused_mod
import flexmb_core.integrators.packs as packs_mod
import flexmb_core.integrators.path_step as path_step_mod
import flexmb_core.integrators.static_step as static_step_mod
import flexmb_core.kernels.constraints as constraints_mod
import flexmb_core.kernels.frame3d as frame_mod
import flexmb_core.kernels.guard as guard_mod
import flexmb_core.kernels.moments as moments_mod
import flexmb_core.kernels.scatter as scatter_mod
import flexmb_core.kernels.shell as shell_mod
import flexmb_core.kernels.truss as truss_mod
import flexmb_core.observers as observers_mod
import flexmb_core.solvers.banded as banded_mod
from flexmb_core.jit import KERNEL
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene
from flexmb_core.simulator import Simulator

SCENES = Path(__file__).resolve().parents[2] / "scenes"
MODULES = (frame_mod, truss_mod, moments_mod, energy_mod, constraints_mod, scatter_mod, shell_mod, guard_mod,
           fast_mod, packs_mod, path_step_mod)


# the modules of the step's kernels, and the kernels there that allocate: the model's setup, and the
# platform pose output (numpy's @ and cross; rewritten by hand they would change the recorded bits)
STEP_MODULES = MODULES + (fused_mod, static_step_mod, banded_mod, faults_mod, commands_mod, observers_mod)
ALLOCATING_KERNELS = {"flexmb_core.kernels.shell.shell_constants", "flexmb_core.solvers.banded._cuthill_mckee",
                      "flexmb_core.solvers.banded._to_runs", "flexmb_core.solvers.banded._symbolic",
                      "flexmb_core.solvers.banded._blocks", "flexmb_core.observers._pose_kernel"}


def _kernels(modules=MODULES):
    for mod in modules:
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


def test_step_kernels_run_without_numba_runtime():
    kernels = dict(_kernels(STEP_MODULES))
    assert set(ALLOCATING_KERNELS) <= set(kernels)
    with_runtime = sorted(name for name, disp in kernels.items()
                          if disp.targetoptions.get("_nrt", True) and name not in ALLOCATING_KERNELS)
    assert not with_runtime, f"step kernels compiled with numba's runtime (reference counting): {with_runtime}"


def test_a_step_kernel_may_not_allocate():
    @njit(**{**KERNEL, "cache": False})
    def allocates(n):
        return np.zeros(n).sum()

    with pytest.raises(numba.core.errors.TypingError):
        allocates(3)
