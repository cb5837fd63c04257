"""The numba Newton of statics (flexmb_core.integrators.static_step) is an exact accelerator: load
increment by increment it reaches bit for bit the states of the Python loop of StaticSolver —
frames with moment loads and driven supports, multipliers, shells, refused roots and bisected load
increments, accept_flagged — and reports the same iterations, increments, energies, messages and
flags (the relative residual is a norm summed in another order: equal to a few ulps)."""

import copy
from pathlib import Path

import numpy as np
import pytest

from builders import build, cantilever

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def _run(sim, fast: bool):
    assert sim._static.fast is not None
    if not fast:
        sim._static.fast = None
    sim.initialize()
    rows = []
    while sim.state.t < sim.spec.until - 1e-12:
        r = sim.step()
        rows.append((r.converged, r.iterations, r.increment, r.substeps, r.strain, r.gravity, r.message, r.guard,
                     r.residual))
    return rows, np.concatenate((sim.state.q, sim.state.mult, sim.state.lam))


def _same(a, b):
    assert [r[:8] for r in a[0]] == [r[:8] for r in b[0]]
    assert np.array_equal(a[1], b[1])
    for x, y in zip(a[0], b[0]):
        assert x[8] == pytest.approx(y[8], rel=1e-12, abs=1e-300)


def _cantilever(**solver):
    d = cantilever(length=1.0, elements=4, order=3, E=200e9, nu=0.3, rho=7850.0,
                   section={"shape": "circle", "radius": 0.005},
                   forces={"p": {"node": "tip", "force": [0, 0, -300.0], "signal": {"kind": "ramp", "duration": 1.0}}},
                   solver={"analysis": "static", "until": 1.0, "dt": 0.25, "tolerance": 1e-10, **solver})
    d["loads"]["moments"] = {"m": {"node": "tip", "member": "beam", "moment": [0.0, 2.0, 1.0], "follower": True,
                                       "signal": {"kind": "ramp", "duration": 1.0}}}
    d["supports"][0] = {"node": "root", "type": "driven", "member": "beam",
                        "rotation": {"axis": [0, 0, 1], "angle": {"kind": "ramp", "duration": 1.0, "end": 0.2}}}
    return d


def test_bit_identical_with_moments_and_a_driven_support():
    d = _cantilever()
    a, b = _run(build(copy.deepcopy(d))[1], True), _run(build(copy.deepcopy(d))[1], False)
    _same(a, b)
    assert all(r[0] for r in a[0]) and a[0][-1][1] > 1


def test_bit_identical_through_bisected_and_flagged_increments():
    """One increment for a load that needs several: no convergence in 12 iterations, then the
    increment is split in 4 (substep), or kept and flagged (accept_flagged)."""
    for policy in ("substep", "accept_flagged"):
        d = _cantilever(max_iterations=12, on_unconverged=policy)
        d["solver"]["dt"] = 1.0
        del d["loads"]["moments"]
        d["supports"][0] = {"node": "root", "type": "clamp"}
        a, b = _run(build(copy.deepcopy(d))[1], True), _run(build(copy.deepcopy(d))[1], False)
        _same(a, b)
        if policy == "substep":
            assert a[0][-1][3] > 1 and a[0][-1][0]
        else:
            assert not a[0][-1][0]


@pytest.mark.parametrize("scene", ["shell_roll_up", "shell_strip_shear", "shell_pulled_cylinder"])
def test_bit_identical_on_shipped_shell_scenes(scene):
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene import load_scene
    from flexmb_core.simulator import Simulator

    runs = [_run(Simulator(compile_scene(load_scene(SCENES / f"{scene}.yaml"))), fast) for fast in (True, False)]
    _same(*runs)


def test_bit_identical_with_rigid_corners():
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene import load_scene
    from flexmb_core.simulator import Simulator

    over = {"analysis": "static", "until": 1.0, "dt": 0.25}
    runs = [_run(Simulator(compile_scene(load_scene(SCENES / "right_angle_cantilever.yaml", over))), fast)
            for fast in (True, False)]
    _same(*runs)
    assert runs[0][1][-6:].any()          # the corner's multipliers carry moments
