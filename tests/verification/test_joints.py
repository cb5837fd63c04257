"""Joints expressed by shared DOFs (SPEC §5): revolute support and joint, rigid collinear joint,
and the errors that guard what sharing cannot express."""

import copy
import math

import numpy as np
import pytest

from builders import build, extended_tangent_error


def rod_scene(theta0=0.1, length=1.0, E=2e13):
    """A stiff steel rod hanging from a hinge about x, released at θ0 from the vertical."""
    tip = [0.0, length * math.sin(theta0), -length * math.cos(theta0)]
    return {
        "name": "pendulum",
        "materials": {"steel": {"E": E, "nu": 0.3, "rho": 7850.0}},
        "sections": {"rod": {"shape": "circle", "radius": 0.01}},
        "nodes": {"hinge": [0.0, 0.0, 0.0], "tip": tip},
        "members": {"rod": {"kind": "frame", "from": "hinge", "to": "tip", "elements": 2, "material": "steel",
                            "section": "rod", "up": [1, 0, 0]}},
        "supports": [{"node": "hinge", "type": "revolute", "member": "rod", "axis": [1, 0, 0]}],
        "loads": {"gravity": [0.0, 0.0, -9.81]},
        "solver": {"analysis": "dynamic", "integrator": "newmark", "dt": 1e-3, "until": 4.0, "tolerance": 1e-10},
        "outputs": {"tip": {"kind": "node_position", "node": "tip"}},
    }


def test_pendulum_period_on_a_revolute_support():
    """Uniform rigid rod about its end: T = 2π√(2L/3g)·(1 + θ0²/16 + 11θ0⁴/3072)."""
    theta0, length, g = 0.1, 1.0, 9.81
    _, sim = build(rod_scene(theta0, length))
    sim.initialize()
    ys, ts = [], []
    sim.run(4.0, callback=lambda s, r: (ys.append(s.outputs()["tip"][1]), ts.append(s.state.t)))
    ys, ts = np.array(ys), np.array(ts)
    down = np.nonzero((ys[:-1] > 0) & (ys[1:] <= 0))[0]        # downward zero crossings of y
    t_cross = ts[down] - ys[down] * (ts[down + 1] - ts[down]) / (ys[down + 1] - ys[down])
    period = np.mean(np.diff(t_cross))
    exact = 2 * math.pi * math.sqrt(2 * length / (3 * g)) * (1 + theta0**2 / 16 + 11 * theta0**4 / 3072)
    # section rotary inertia adds ρ·I1 per length: (r²/4)/(L²/3) relative to I = mL²/3
    exact *= math.sqrt(1 + 3 * 0.01**2 / 4 / length**2)
    assert period == pytest.approx(exact, rel=2e-4)
    x = np.array(sim.outputs()["tip"])[0]
    assert abs(x) < 1e-12                                      # the motion stays in the hinge plane


def two_links(joint_type):
    """Link 'a' clamped at the root along +y, link 'b' continues along +y; joined at 'k'."""
    d = {
        "name": "links",
        "materials": {"steel": {"E": 2.1e11, "nu": 0.3, "rho": 7850.0}},
        "sections": {"bar": {"shape": "rectangle", "width": 0.02, "height": 0.02}},
        "nodes": {"root": [0.0, 0.0, 0.0], "k": [0.0, 0.5, 0.0], "tip": [0.0, 1.0, 0.0]},
        "members": {"a": {"kind": "frame", "from": "root", "to": "k", "elements": 2, "material": "steel",
                          "section": "bar", "up": [0, 0, 1]},
                    "b": {"kind": "frame", "from": "k", "to": "tip", "elements": 2, "material": "steel",
                          "section": "bar", "up": [0, 0, 1]}},
        "supports": [{"node": "root", "type": "clamp"}],
        "loads": {"forces": {"f": {"node": "tip", "force": [30.0, 0.0, 20.0],
                                   "signal": {"kind": "ramp", "duration": 1.0}}}},
        "solver": {"analysis": "static", "until": 1.0, "dt": 0.5},
        "outputs": {"tip": {"kind": "node_position", "node": "tip"}},
    }
    if joint_type == "revolute":
        d["joints"] = [{"type": "revolute", "node": "k", "members": ["a", "b"], "axis": [0, 0, 1]}]
    elif joint_type == "rigid":
        d["joints"] = [{"type": "rigid", "node": "k", "members": ["a", "b"]}]
    return d


def _tip(d):
    _, sim = build(d)
    sim.initialize()
    sim.run(1.0)
    return np.array(sim.outputs()["tip"])


def test_rigid_collinear_joint_equals_one_member():
    one = copy.deepcopy(two_links(None))
    one["members"] = {"ab": {"kind": "frame", "from": "root", "to": "tip", "via": ["k"], "elements": 4,
                             "material": "steel", "section": "bar", "up": [0, 0, 1]}}
    assert np.allclose(_tip(two_links("rigid")), _tip(one), atol=1e-12)


def test_revolute_joint_is_free_about_its_axis_only():
    """Hinge about z at k: the x-force swings link b about z (mechanism: a static x load cannot be
    carried, so apply only the z-force there), while bending about x is transmitted."""
    d = two_links("revolute")
    d["loads"]["forces"]["f"]["force"] = [0.0, 0.0, 20.0]      # out of the hinge plane: carried
    tip_rev = _tip(d)
    tip_rigid = _tip({**two_links("rigid"), "loads": d["loads"]})
    assert np.allclose(tip_rev, tip_rigid, atol=1e-9)          # moment about x transmitted fully
    # about z the hinge is free: under the in-plane force, statics finds no equilibrium (singular)
    d2 = two_links("revolute")
    d2["loads"]["forces"]["f"]["force"] = [30.0, 0.0, 0.0]
    d2["solver"]["max_substep_levels"] = 0
    d2["solver"]["max_iterations"] = 8
    from flexmb_core.errors import ConvergenceError
    with pytest.raises(ConvergenceError):
        _tip(d2)


def test_off_plane_hinge_by_multipliers_equals_the_shared_vector_hinge():
    """Link b's square section turned 45° about its own axis: no section vector lies on the hinge
    axis z, so the hinge is held by multipliers (a·b_k = 0). A square bends alike about every axis,
    so the response equals the hinge made by sharing the axis vector."""
    shared = two_links("revolute")
    shared["loads"]["forces"]["f"]["force"] = [0.0, 0.0, 20.0]
    turned = copy.deepcopy(shared)
    turned["members"]["b"]["up"] = [1.0, 0.0, 1.0]
    model, _ = build(turned)
    assert model.n_multipliers == 2 and model.hinge_dofs.shape[0] == 1
    assert np.allclose(_tip(turned), _tip(shared), atol=1e-9)


def test_extended_system_tangent_is_exact():
    """Rigid corner + off-plane hinge in one model: the system matrix [[K + λ∇²c, Gᵀ], [G, 0]]
    equals the finite difference of the system residual [f_int + Gᵀλ; c] in q and λ."""
    d = two_links("revolute")
    d["members"]["b"]["up"] = [1.0, 0.0, 1.0]                        # multiplier hinge at k
    d["nodes"]["c"] = [0.5, 1.0, 0.0]
    d["members"]["c"] = {"kind": "frame", "from": "tip", "to": "c", "elements": 1, "material": "steel",
                         "section": "bar", "up": [0, 0, 1]}
    d["joints"].append({"type": "rigid", "node": "tip", "members": ["b", "c"]})   # corner at tip
    model, sim = build(d)
    assert model.n_multipliers == 8
    rng = np.random.default_rng(4)
    q = model.q0 + 0.02 * rng.standard_normal(model.ndof)
    mult = rng.standard_normal(model.n_multipliers)
    assert extended_tangent_error(model, sim, q, mult) < 1e-7


def test_rigid_joint_uses_sharing_when_frames_agree_and_multipliers_otherwise():
    model, _ = build(two_links("rigid"))
    assert model.n_multipliers == 0                 # collinear, same frame: shared vectors
    d = two_links("rigid")
    d["members"]["b"]["up"] = [1, 0, 0]              # same axis, section turned 90°: a corner
    model, _ = build(d)
    assert model.n_multipliers == 6
    assert np.allclose(_tip(d), _tip(two_links("rigid")), atol=1e-9)   # still one rigid beam


def test_statics_with_a_free_spin_link_needs_no_user_trick():
    """A frame member with ball joints at both ends spins freely about its axis (zero stiffness).
    The static solve converges anyway — the load has no component on the spin — to the
    simply supported beam: midspan sag 5qL⁴/(384EI); the section does not wander."""
    d = {
        "name": "ball_ball",
        "materials": {"steel": {"E": 2.1e11, "nu": 0.3, "rho": 7850.0}},
        "sections": {"rod": {"shape": "circle", "radius": 0.01}},
        "nodes": {"a": [0.0, 0.0, 0.0], "b": [1.0, 0.0, 0.0]},
        "members": {"link": {"kind": "frame", "from": "a", "to": "b", "elements": 4, "material": "steel",
                             "section": "rod"}},
        "supports": [{"node": "a", "type": "ball"}, {"node": "b", "type": "ball"}],
        "loads": {"gravity": [0.0, 0.0, -9.81]},
        "solver": {"analysis": "static", "until": 1.0, "dt": 0.5, "max_substep_levels": 0},
        "outputs": {"shape": {"kind": "member_shape", "member": "link"},
                    "frame": {"kind": "section_vectors", "node": "a", "member": "link"}},
    }
    _, sim = build(d)
    sim.initialize()
    sim.run(1.0)
    q_line = 7850.0 * math.pi * 0.01**2 * 9.81
    ei = 2.1e11 * math.pi * 0.01**4 / 4
    mid = sim.outputs()["shape"][6]
    assert mid[2] == pytest.approx(-5 * q_line / (384 * ei), rel=1e-3)
    v1, v2 = map(np.array, sim.outputs()["frame"])
    assert abs(v1[2]) < 1e-2 and abs(v2[1]) < 1e-2       # the end section has not spun away
