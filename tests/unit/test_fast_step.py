"""The numba step (flexmb_core.integrators.fast) is an exact accelerator: on every model it
covers, step by step, it gives bit for bit what the Python path of DynamicIntegrator gives —
including held tangents, refused roots and the sub-stepping that follows, actuator stretches and
their rates, material damping, bars, several frame groups, shells, multipliers, moment loads,
driven supports and the Chung–Hulbert form — and it declines what it does not cover (Chung–Hulbert
with multipliers, which the Python path refuses)."""

import copy
import math

import numpy as np
import pytest

from builders import build, cantilever, free_beam
from flexmb_core.integrators.fast import NumbaStep


def _b1(newton="modified", integrator="generalized_alpha", gravity=False):
    d = cantilever(length=1.0, elements=4, order=3, E=200e9, nu=0.3, rho=7850.0,
                   section={"shape": "circle", "radius": 0.005},
                   forces={"p": {"node": "tip", "force": [0, 0, -196.35],
                                 "signal": {"kind": "ramp", "duration": 0.1, "shape": "smooth"}}},
                   solver={"analysis": "dynamic", "integrator": integrator, "rho_inf": 0.8, "dt": 1e-3,
                           "until": 0.3, "tolerance": 1e-10, "newton": newton}, damping=10.0)
    if gravity:
        d["loads"]["gravity"] = {"acceleration": [0, 0, -9.81], "signal": {"kind": "ramp", "duration": 0.05}}
    return d


def _tumbling():
    return free_beam(integrator="newmark", dt=1e-3, tolerance=1e-10)


def _spin_tumble(model, sim):
    omega, centre = np.array([0.0, 3.0, 20.0]), np.array([0.5, 0.0, 0.0])
    q, v = sim.state.q, sim.state.v
    for b in model.node_ydofs:
        v[b] = np.cross(omega, q[b] - centre) + np.array([0.0, 0.0, 0.5 * math.cos(math.pi * q[b[0]])])
    for mem in model.members:
        for b in mem.vdofs.reshape(-1, 3):
            v[b] = np.cross(omega, q[b])


def _steps(sim, fast, steps):
    """Run ``steps`` steps with the numba step (``fast``) or the Python path: every result's
    fields, the final state (with the actuator stretches and rates) and the tangent refreshes."""
    assert sim._dynamic.fast is not None
    if not fast:
        sim._dynamic.fast = None
    sim.initialize()
    rows = []
    for _ in range(steps):
        r = sim.step()
        rows.append((r.converged, r.iterations, r.residual, r.increment, r.substeps, r.kinetic, r.strain,
                     r.gravity, r.message, r.guard))
    s = sim.state
    return rows, np.concatenate((s.q, s.v, s.a, s.atil, s.lam, s.lam_rate)), sim._dynamic.tangent_updates


def _history(d, fast, steps, setup=None):
    model, sim = build(copy.deepcopy(d))
    if setup:
        setup(model, sim)
    return _steps(sim, fast, steps)


@pytest.mark.parametrize("d", [_b1(), _b1("full"), _b1(integrator="newmark"), _b1(gravity=True),
                               _b1(integrator="chung_hulbert"), _b1("full", integrator="chung_hulbert")],
                         ids=["modified", "full", "newmark", "gravity", "chung_hulbert", "chung_hulbert_full"])
def test_bit_identical_to_the_python_path(d):
    a, b = _history(d, True, 300), _history(d, False, 300)
    assert a[0] == b[0]
    assert np.array_equal(a[1], b[1])
    assert a[2] == b[2] > 0


def test_bit_identical_through_refused_roots_and_sub_steps():
    """The tumbling beam under the trapezoidal rule: failed attempts from step 43 on, a root
    refused by the step guard at step 126, sub-steps after each — the numba step hands every
    failed attempt to the same policy."""
    d = _tumbling()
    a, b = _history(d, True, 130, _spin_tumble), _history(d, False, 130, _spin_tumble)
    assert a[0] == b[0]
    assert np.array_equal(a[1], b[1])
    assert any(r[4] > 1 for r in a[0]) and a[0][125][9] == "inverted"


def test_chung_hulbert_with_multipliers_keeps_the_python_path_and_its_refusal():
    from pathlib import Path

    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene import scene_from_dict
    from flexmb_core.scene.loader import parse_yaml
    from flexmb_core.simulator import Simulator

    path = Path(__file__).resolve().parents[2] / "scenes" / "right_angle_cantilever.yaml"
    data = parse_yaml(path.read_text(), str(path))
    data["solver"]["integrator"] = "chung_hulbert"
    model = compile_scene(scene_from_dict(data, source=str(path)))
    sim = Simulator(model)
    assert "integrator chung_hulbert with multipliers" in NumbaStep.unsupported(model, sim.spec)
    assert sim._dynamic.fast is None
    sim.initialize()
    with pytest.raises(ValueError, match="chung_hulbert integrator does not support rigid corners"):
        sim.step()
    d = _b1()
    d["solver"].update(integrator="chung_hulbert")
    model, sim = build(d)
    assert NumbaStep.unsupported(model, sim.spec) == "" and sim._dynamic.fast is not None


def test_bit_identical_when_failed_steps_are_accepted_and_flagged():
    """accept_flagged keeps a failed attempt's last iterate: the numba step leaves it as the
    Python path does (the tumbling beam's failures and refused roots, kept and flagged)."""
    d = _tumbling()
    d["solver"]["on_unconverged"] = "accept_flagged"
    a, b = _history(d, True, 130, _spin_tumble), _history(d, False, 130, _spin_tumble)
    assert a[0] == b[0]
    assert np.array_equal(a[1], b[1])
    assert sum(not r[0] for r in a[0]) > 0


def _moments(follower):
    def change(d):
        d["loads"]["moments"] = {"m": {"node": "tip", "member": "beam", "moment": [0.0, 2.0, 1.0],
                                       "follower": follower,
                                       "signal": {"kind": "ramp", "duration": 0.1, "shape": "smooth"}}}
    return change


def _driven(d):
    d["supports"][0] = {"node": "root", "type": "driven", "member": "beam",
                        "rotation": {"axis": [0, 0, 1], "angle": {"kind": "ramp", "duration": 0.2, "end": 0.3}},
                        "translation": {"direction": [0, 1, 0],
                                        "distance": {"kind": "ramp", "duration": 0.2, "end": 0.01}}}


@pytest.mark.parametrize("change", [_moments(False), _moments(True), _driven],
                         ids=["conservative moment", "follower moment", "driven support"])
def test_bit_identical_with_moment_loads_and_driven_supports(change):
    d = _b1()
    change(d)
    a, b = _history(d, True, 250), _history(d, False, 250)
    assert a[0] == b[0]
    assert np.array_equal(a[1], b[1])
    assert a[2] == b[2] > 0


def _scene_history(path, fast, steps):
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene import load_scene
    from flexmb_core.simulator import Simulator

    sim = Simulator(compile_scene(load_scene(path)))
    sim.warmup()
    return _steps(sim, fast, steps)


@pytest.mark.parametrize("scene, steps", [
    ("stewart_platform_bars", 400),     # bars only, damped, six actuators on a command program
    ("stewart_platform_1el", 60),       # damped actuated frame legs
    ("stewart_platform_1el_truss", 60),  # damped actuated frame legs on bars (the demo)
    ("deployable_boom", 150),           # frames and bars
    ("rps_manipulator", 150),
    ("boom_step", 100),                 # two frame groups
    ("stewart_platform_shell", 150),    # a shell platform on bar legs
    ("right_angle_cantilever", 100),    # a rigid corner (multipliers)
    ("tendon_arm", 100),                # rigid corners (multipliers) and bars
    ("spin_up", 150),                   # a driven support turning a frame
    ("radiator_panels", 60),            # shells, hinge lines, director ties: SuperLU pivots the tangent
])
def test_bit_identical_on_shipped_scenes(scene, steps):
    from pathlib import Path

    path = str(Path(__file__).resolve().parents[2] / "scenes" / f"{scene}.yaml")
    a, b = _scene_history(path, True, steps), _scene_history(path, False, steps)
    assert a[0] == b[0]
    assert np.array_equal(a[1], b[1])
    assert a[2] == b[2] > 0
