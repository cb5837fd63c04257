"""The step regression cases: runs whose every step result and final state are recorded in
``tests/data/step_references/`` (by ``python tests/step_cases.py``) and compared by
``tests/unit/test_fast_step.py`` and ``tests/unit/test_static_step.py``.

They were recorded when the numba step and the Python Newton it replaced were bit-identical on all
of them (commit d444dc3, ``tests/unit/test_fast_step.py`` of that commit), so they stand for both.
Except two: when the held tangent came to follow the shells' rotation (2026-11-30, an intended
change of results: one Newton iteration a step instead of two on the shell twin, closer to the root),
``scene_stewart_platform_shell`` and ``scene_radiator_panels`` were recorded again; their former
references are the ``*_fixed`` cases, run with ``held_tangent: fixed``.
"""

from __future__ import annotations

import copy
import math
import sys
from pathlib import Path

import numpy as np

from builders import build, cantilever, free_beam

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"
REFERENCES = Path(__file__).resolve().parent / "data" / "step_references"


def b1(newton="modified", integrator="generalized_alpha", gravity=False):
    d = cantilever(length=1.0, elements=4, order=3, E=200e9, nu=0.3, rho=7850.0,
                   section={"shape": "circle", "radius": 0.005},
                   forces={"p": {"node": "tip", "force": [0, 0, -196.35],
                                 "signal": {"kind": "ramp", "duration": 0.1, "shape": "smooth"}}},
                   solver={"analysis": "dynamic", "integrator": integrator, "rho_inf": 0.8, "dt": 1e-3,
                           "until": 0.3, "tolerance": 1e-10, "newton": newton}, damping=10.0)
    if gravity:
        d["loads"]["gravity"] = {"acceleration": [0, 0, -9.81], "signal": {"kind": "ramp", "duration": 0.05}}
    return d


def tumbling():
    return free_beam(integrator="newmark", dt=1e-3, tolerance=1e-10)


def spin_tumble(model, sim):
    omega, centre = np.array([0.0, 3.0, 20.0]), np.array([0.5, 0.0, 0.0])
    q, v = sim.state.q, sim.state.v
    for b in model.node_ydofs:
        v[b] = np.cross(omega, q[b] - centre) + np.array([0.0, 0.0, 0.5 * math.cos(math.pi * q[b[0]])])
    for mem in model.members:
        for b in mem.vdofs.reshape(-1, 3):
            v[b] = np.cross(omega, q[b])


def moments(follower):
    def change(d):
        d["loads"]["moments"] = {"m": {"node": "tip", "member": "beam", "moment": [0.0, 2.0, 1.0],
                                       "follower": follower,
                                       "signal": {"kind": "ramp", "duration": 0.1, "shape": "smooth"}}}
    return change


def driven(d):
    d["supports"][0] = {"node": "root", "type": "driven", "member": "beam",
                        "rotation": {"axis": [0, 0, 1], "angle": {"kind": "ramp", "duration": 0.2, "end": 0.3}},
                        "translation": {"direction": [0, 1, 0],
                                        "distance": {"kind": "ramp", "duration": 0.2, "end": 0.01}}}


def static_cantilever(**solver):
    d = cantilever(length=1.0, elements=4, order=3, E=200e9, nu=0.3, rho=7850.0,
                   section={"shape": "circle", "radius": 0.005},
                   forces={"p": {"node": "tip", "force": [0, 0, -300.0], "signal": {"kind": "ramp", "duration": 1.0}}},
                   solver={"analysis": "static", "until": 1.0, "dt": 0.25, "tolerance": 1e-10, **solver})
    d["loads"]["moments"] = {"m": {"node": "tip", "member": "beam", "moment": [0.0, 2.0, 1.0], "follower": True,
                                   "signal": {"kind": "ramp", "duration": 1.0}}}
    d["supports"][0] = {"node": "root", "type": "driven", "member": "beam",
                        "rotation": {"axis": [0, 0, 1], "angle": {"kind": "ramp", "duration": 1.0, "end": 0.2}}}
    return d


def bisected(policy):
    d = static_cantilever(max_iterations=12, on_unconverged=policy)
    d["solver"]["dt"] = 1.0
    del d["loads"]["moments"]
    d["supports"][0] = {"node": "root", "type": "clamp"}
    return d


def scene_sim(name, overrides=None):
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene import load_scene
    from flexmb_core.simulator import Simulator

    sim = Simulator(compile_scene(load_scene(SCENES / f"{name}.yaml", overrides)))
    sim.warmup()
    return sim


def dict_sim(d, setup=None):
    model, sim = build(copy.deepcopy(d))
    if setup:
        setup(model, sim)
    return sim


# name -> (how to make the simulator, steps (None: statics to the end))
DYNAMIC = {
    "b1_modified": (lambda: dict_sim(b1()), 300),
    "b1_full": (lambda: dict_sim(b1("full")), 300),
    "b1_newmark": (lambda: dict_sim(b1(integrator="newmark")), 300),
    "b1_gravity": (lambda: dict_sim(b1(gravity=True)), 300),
    "b1_chung_hulbert": (lambda: dict_sim(b1(integrator="chung_hulbert")), 300),
    "b1_chung_hulbert_full": (lambda: dict_sim(b1("full", integrator="chung_hulbert")), 300),
    "tumbling_substeps": (lambda: dict_sim(tumbling(), spin_tumble), 130),
    "b1_conservative_moment": (lambda: _changed(moments(False)), 250),
    "b1_follower_moment": (lambda: _changed(moments(True)), 250),
    "b1_driven_support": (lambda: _changed(driven), 250),
    **{f"scene_{s}": ((lambda s=s: scene_sim(s)), n) for s, n in (
        ("stewart_platform_bars", 400), ("stewart_platform_1el", 60), ("stewart_platform_1el_truss", 60),
        ("deployable_boom", 150), ("rps_manipulator", 150), ("boom_step", 100), ("stewart_platform_shell", 150),
        ("right_angle_cantilever", 100), ("tendon_arm", 100), ("spin_up", 150), ("radiator_panels", 60))},
    # the held tangent as formed, not following the shells' rotation (solver.held_tangent): the
    # references recorded before the corotated one became the default (2026-11-30), unchanged
    **{f"scene_{s}_fixed": ((lambda s=s: scene_sim(s, {"held_tangent": "fixed"})), n) for s, n in (
        ("stewart_platform_shell", 150), ("radiator_panels", 60))},
}


def _changed(change):
    d = b1()
    change(d)
    return dict_sim(d)


def _accept_flagged():
    d = tumbling()
    d["solver"]["on_unconverged"] = "accept_flagged"
    return dict_sim(d, spin_tumble)


DYNAMIC["tumbling_accept_flagged"] = (_accept_flagged, 130)

STATIC = {
    "static_moments_driven": lambda: dict_sim(static_cantilever()),
    "static_bisected_substep": lambda: dict_sim(bisected("substep")),
    "static_bisected_accept_flagged": lambda: dict_sim(bisected("accept_flagged")),
    **{f"static_{s}": (lambda s=s: scene_sim(s)) for s in ("shell_roll_up", "shell_strip_shear",
                                                            "shell_pulled_cylinder")},
    "static_right_angle_cantilever": lambda: scene_sim("right_angle_cantilever",
                                                       {"analysis": "static", "until": 1.0, "dt": 0.25}),
}

# the result fields compared exactly, and the floats compared to a tolerance
EXACT = ("converged", "iterations", "substeps", "message", "guard")
FLOATS = ("residual", "increment", "kinetic", "strain", "gravity")


def run_dynamic(sim, steps):
    """Every step's result and the final state (q, v, a, ã, λ, λ̇, multipliers), tangent refreshes."""
    sim.initialize()
    rows = [sim.step() for _ in range(steps)]
    s = sim.state
    return rows, np.concatenate((s.q, s.v, s.a, s.atil, s.lam, s.lam_rate, s.mult)), sim._dynamic.tangent_updates


def run_static(sim):
    sim.initialize()
    rows = []
    while sim.state.t < sim.spec.until - 1e-12:
        rows.append(sim.step())
    s = sim.state
    return rows, np.concatenate((s.q, s.mult, s.lam)), 0


def run(name):
    if name in DYNAMIC:
        make, steps = DYNAMIC[name]
        return run_dynamic(make(), steps)
    return run_static(STATIC[name]())


def record(name) -> None:
    rows, state, updates = run(name)
    np.savez_compressed(REFERENCES / f"{name}.npz", state=state, updates=updates,
                        exact=np.array([repr(tuple(getattr(r, f) for f in EXACT)) for r in rows]),
                        floats=np.array([[getattr(r, f) for f in FLOATS] for r in rows], dtype=float))


def load(name):
    with np.load(REFERENCES / f"{name}.npz") as z:
        return {k: z[k] for k in z.files}


# runs whose references SuperLU solved in part (tests/unit/test_fast_step.py says how they differ)
PIVOTED = {"scene_stewart_platform_1el", "scene_stewart_platform_1el_truss", "scene_tendon_arm",
           "static_right_angle_cantilever"}


def check_against_reference(name):
    """Run case ``name`` and compare it with its reference; returns the results."""
    ref = load(name)
    if name in DYNAMIC:
        make, steps = DYNAMIC[name]
        sim = make()
        rows, state, updates = run_dynamic(sim, steps)
    else:
        sim = STATIC[name]()
        rows, state, updates = run_static(sim)
    exact = [repr(tuple(getattr(r, f) for f in EXACT)) for r in rows]
    assert exact == list(ref["exact"])          # converged, iterations, sub-steps, messages, flags
    assert updates == int(ref["updates"])
    floats = np.array([[getattr(r, f) for f in FLOATS] for r in rows], dtype=float)
    if name not in PIVOTED:
        assert np.array_equal(state, ref["state"])
        assert np.array_equal(floats[:, 2:], ref["floats"][:, 2:])   # energies
        # the residual and increment norms of statics are loop sums against numpy's BLAS: ulps
        np.testing.assert_allclose(floats[:, :2], ref["floats"][:, :2], rtol=1e-12, atol=1e-300)
        return rows
    n = sim.model.ndof
    nodes = np.asarray(sim.model.node_ydofs).ravel()
    q, q_ref = state[:n], ref["state"][:n]
    assert np.abs(q[nodes] - q_ref[nodes]).max() <= 1e-13 * np.abs(q_ref).max()
    assert np.abs(q - q_ref).max() <= 1e-4                       # the legs' free spin (docstring)
    if name in DYNAMIC:
        v, v_ref = state[n:2 * n], ref["state"][n:2 * n]
        assert np.abs(v[nodes] - v_ref[nodes]).max() <= 1e-6 * np.abs(v_ref).max()
    np.testing.assert_allclose(floats[:, 3:], ref["floats"][:, 3:], rtol=1e-8, atol=1e-12)   # strain, gravity
    return rows


if __name__ == "__main__":
    REFERENCES.mkdir(parents=True, exist_ok=True)
    for name in sys.argv[1:] or [*DYNAMIC, *STATIC]:
        record(name)
        print("recorded", name, flush=True)
