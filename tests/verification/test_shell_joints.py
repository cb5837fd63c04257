"""Shells in mechanisms: hinge lines (shell–shell, shell–member) by shared positions, director ties
to frames by multipliers, edge loads; the extended-system tangent is exact; hinge lines are free
about their line only; bad shell input is rejected with the file:key and the expectation."""

import copy

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from builders import build, extended_tangent_error
from flexmb_core.errors import SceneError
from flexmb_core.model.assembly import assemble, update_load_scales
from flexmb_core.scene.loader import scene_from_dict


def panels(with_tie: bool = True) -> dict:
    """A clamped mast (frame) carrying panel p1 on a hinge line; p2 hinged to p1's far edge and
    folded; a post (frame) tied rigidly to p2's corner; edge force and edge moment on p2."""
    d = {
        "name": "panels",
        "materials": {"al": {"E": 7.0e10, "nu": 0.33, "rho": 2700.0}},
        "sections": {"tube": {"shape": "tube", "outer_radius": 0.03, "thickness": 0.003}},
        "nodes": {"m0": [0.0, 0.0, 0.0], "m1": [1.0, 0.0, 0.0],
                  "q1": [1.0, 0.5, 0.3], "q0": [0.0, 0.5, 0.3],
                  "r1": [1.0, 0.6, 0.9], "r0": [0.0, 0.6, 0.9], "top": [0.0, 0.9, 1.4]},
        "members": {
            "mast": {"kind": "frame", "from": "m0", "to": "m1", "elements": 1, "material": "al", "section": "tube"},
            "post": {"kind": "frame", "from": "r0", "to": "top", "elements": 1, "material": "al", "section": "tube"},
        },
        "shells": {
            "p1": {"mesh": {"kind": "rectangle", "corners": ["m0", "m1", "q1", "q0"], "divisions": [1, 1]},
                   "thickness": 0.01, "material": "al"},
            "p2": {"mesh": {"kind": "rectangle", "corners": ["q0", "q1", "r1", "r0"], "divisions": [1, 1]},
                   "thickness": 0.008, "material": "al"},
        },
        "joints": [{"type": "hinge_line", "edges": ["p1.bottom"], "member": "mast"},
                   {"type": "hinge_line", "edges": ["p1.top", "p2.bottom"]}],
        "supports": [{"node": "m0", "type": "clamp", "member": "mast"},
                     {"node": "m1", "type": "ball"}],
        "loads": {"edge_forces": {"push": {"edge": "p2.right", "force_per_length": [0.0, 0.0, -30.0]}},
                  "edge_moments": {"twist": {"edge": "p2.top", "moment_per_length": [4.0, 0.0, 0.0]}}},
        "solver": {"analysis": "static"},
    }
    if with_tie:
        d["joints"].append({"type": "shell_rigid", "node": "r0", "shell": "p2", "member": "post"})
    return d


def test_extended_system_tangent_with_shells_hinge_lines_and_ties_is_exact():
    model, sim = build(panels())
    assert model.n_multipliers == 3
    update_load_scales(model, sim.ws, 1.0)
    rng = np.random.default_rng(8)
    q = model.q0 + 0.01 * rng.standard_normal(model.ndof)
    mult = rng.standard_normal(model.n_multipliers)
    assert extended_tangent_error(model, sim, q, mult) < 1e-6


def test_hinge_line_shares_positions_only():
    model, _ = build(panels())
    p1, p2 = model.shell("p1"), model.shell("p2")
    mast = model.member("mast")
    assert np.array_equal(p1.nodes[p1.edges["bottom"]], mast.nodes)       # 4 shared nodes (cubic)
    assert np.array_equal(p1.nodes[p1.edges["top"]], p2.nodes[p2.edges["bottom"]])
    assert not set(p1.gdofs.ravel()) & set(p2.gdofs.ravel())             # each panel its own director


def _rotate_about_line(model, q, nodes_mask_ydofs, gdofs, point, axis, angle):
    rot = Rotation.from_rotvec(angle * np.asarray(axis) / np.linalg.norm(axis)).as_matrix()
    for ids in nodes_mask_ydofs:
        q[ids] = point + rot @ (q[ids] - point)
    for ids in gdofs:
        q[ids] = rot @ q[ids]


def test_panel_turns_freely_about_its_hinge_line():
    """Folding p2 rigidly about the p1–p2 hinge line stores no energy and needs no force; the same
    rotation about another axis through the line's end does."""
    d = panels(with_tie=False)
    d["loads"] = {}
    del d["members"]["post"], d["nodes"]["top"]
    model, sim = build(d)
    ws = sim.ws
    p2 = model.shell("p2")
    hinge = set(p2.nodes[p2.edges["bottom"]].tolist())
    own = [model.node_ydofs[n] for n in p2.nodes if n not in hinge]
    q0_, q1_ = np.array([0.0, 0.5, 0.3]), np.array([1.0, 0.5, 0.3])
    for axis, free in ((q1_ - q0_, True), (np.array([0.0, 1.0, 0.2]), False)):
        q = model.q0.copy()
        _rotate_about_line(model, q, own, p2.gdofs, q0_, axis, 0.7)
        u = assemble(model, ws, q, np.ones(0), False)
        fmax = np.abs(ws.r[model.free]).max()
        if free:
            assert u < 1e-12 and fmax < 1e-6
        else:
            assert u > 1.0 and fmax > 1e3


def test_director_tie_follows_a_rigid_rotation_and_holds_after_a_static_solve():
    model, sim = build(panels())
    ws = sim.ws
    rot = Rotation.from_rotvec([0.3, -0.4, 0.9]).as_matrix()
    q = model.q0.copy()
    for n in range(len(model.node_names)):
        q[model.node_ydofs[n]] = rot @ model.q0[model.node_ydofs[n]]
    for mi in model.members:
        for v in mi.vdofs.reshape(-1, 3):
            q[v] = rot @ model.q0[v]
    for info in model.shells:
        for g in info.gdofs:
            q[g] = rot @ model.q0[g]
    assemble(model, ws, q, np.ones(0), False, np.zeros(model.n_multipliers))
    assert np.abs(ws.rc).max() < 1e-14
    # statics under the edge loads with the post pinned at its top (otherwise p1 turns freely on the
    # mast hinge and the post swings about the director, which carries no drilling moment): the
    # tie holds, and p2's director turns
    d = panels()
    d["supports"].append({"node": "top", "type": "ball"})
    model, sim = build(d)
    ws = sim.ws
    sim.initialize()
    sim.run(1.0)
    assert sim.last.converged
    assemble(model, ws, sim.state.q, np.ones(0), False, sim.state.mult)
    assert np.abs(ws.rc).max() < 1e-9
    tie_g = model.tie_dofs[0, :3]
    g, g0 = sim.state.q[tie_g], model.q0[tie_g]
    assert np.degrees(np.arccos(g @ g0 / np.linalg.norm(g))) > 0.01      # it did turn


@pytest.mark.parametrize("edit, where, text", [
    (lambda d: d["joints"][1].update(edges=["p1.upper", "p2.bottom"]), "joints[1].edges[0]",
     "a rectangle has no edge 'upper'; its edges: ['bottom', 'right', 'top', 'left']"),
    (lambda d: d["members"]["mast"].update(elements=2), "shells.p1",
     "edge 'bottom' has 4 nodes but mast has 7"),
    (lambda d: d["materials"]["al"].update(eta=1e5), "shells.p1.material",
     "material 'al' has Kelvin–Voigt damping"),
    (lambda d: d["loads"]["edge_moments"]["twist"].update(moment_per_length=[0.0, 0.0, 3.0]) or
     d["shells"]["p2"]["mesh"].update(corners=["q0", "q1", "r1", "r0"]) or
     d["nodes"].update(r1=[1.0, 1.0, 0.3], r0=[0.0, 1.0, 0.3]) or d["nodes"].update(top=[0.0, 1.4, 0.3]),
     "loads.edge_moments.twist", "is about the shell normal (drilling)"),
    (lambda d: d.update(outputs={"p": {"kind": "shell_point", "shell": "p1", "at": [0.5, 0.1, 0.0]}}),
     "outputs.p.at", "no node of shell 'p1' at [0.5, 0.1, 0.0]"),
    (lambda d: d["supports"].append({"edge": "p2.left", "type": "revolute"}), "supports[2].type",
     "expected one of"),
])
def test_bad_shell_input_names_the_key_and_the_expectation(edit, where, text):
    d = copy.deepcopy(panels())
    edit(d)
    with pytest.raises(SceneError) as err:
        build(d)
    assert where in str(err.value) and text in str(err.value), str(err.value)


def test_shell_only_scene_needs_no_members_or_sections():
    d = panels(with_tie=False)
    for k in ("members", "sections"):
        d.pop(k)
    del d["nodes"]["top"]
    d["joints"] = [{"type": "hinge_line", "edges": ["p1.top", "p2.bottom"]}]
    d["supports"] = [{"edge": "p1.bottom", "type": "clamp"}, {"edge": "p2.top", "type": "ball"}]
    scene = scene_from_dict(d)
    assert not scene.members and set(scene.shells) == {"p1", "p2"}
    model, sim = build(d)
    sim.initialize()
    sim.run(1.0)
    assert sim.last.converged
