"""The shell scene vocabulary of issue 16 at compile level: symmetry and roller supports fix the
DOFs they claim, mesh points (named or given in place) resolve to the same mesh node, a closed
mesh has no seam edges; and bad input — generator keys, coordinates that match no mesh node,
skew symmetry planes — is refused with the file:key and the reason."""

import copy
from pathlib import Path

import numpy as np
import pytest

from flexmb_core.errors import SceneError
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene.loader import parse_yaml, read_scene_text, scene_from_dict

SCENES = Path(__file__).resolve().parents[2] / "scenes"
HEMI = SCENES / "shell_pinched_hemisphere.yaml"


def _hemisphere(n: int = 2) -> dict:
    data = parse_yaml(read_scene_text(HEMI), str(HEMI))
    data["shells"]["hemi"]["mesh"]["divisions"] = [n, n]
    return data


def _compile(data: dict):
    return compile_scene(scene_from_dict(data, source=str(HEMI)))


def test_symmetry_and_roller_fix_the_components_they_name():
    model = _compile(_hemisphere())
    info = model.shell("hemi")
    fixed = np.ones(model.ndof, dtype=bool)
    fixed[model.free] = False
    start, end = info.edges["start"], info.edges["end"]            # on the planes y = 0 and x = 0
    assert np.all(fixed[info.ydofs[start, 1]]) and np.all(fixed[info.gdofs[start, 1]])
    assert np.all(fixed[info.ydofs[end, 0]]) and np.all(fixed[info.gdofs[end, 0]])
    assert not np.any(fixed[info.adofs])                             # the thickness stays free
    a = model.node_ydofs[model.node("hemi.A")]                       # on 'start', with the z roller
    assert list(fixed[a]) == [False, True, True]
    # two components per symmetry-edge node, the shared corner node once more, plus the roller
    n_start, n_end = start.size, end.size
    assert fixed.sum() == 2 * n_start + 2 * n_end + 1


def test_a_point_in_place_is_the_named_mesh_node():
    data = _hemisphere()
    data["loads"]["forces"]["pull"]["node"] = {"shell": "hemi", "at": [10.0, 0.0, 0.0]}
    model = _compile(data)
    name = model.scene.forces[0].node
    assert name == "hemi@loads.forces.pull" and model.node(name) == model.node("hemi.A")
    assert model.load_vectors[0][model.node_ydofs[model.node("hemi.A")]].tolist() == [1.0, 0.0, 0.0]


def test_points_with_a_tolerance_take_the_nearest_node():
    data = _hemisphere()
    data["shells"]["hemi"]["points"]["A"] = {"at": [10.0, 0.0, 0.01], "tolerance": 0.05, "edge": "rim"}
    model = _compile(data)
    assert np.allclose(model.q0[model.node_ydofs[model.node("hemi.A")]], [10.0, 0.0, 0.0])


def _edit(path: str, value):
    def apply(d):
        keys = path.split(".")
        node = d
        for k in keys[:-1]:
            node = node[int(k)] if isinstance(node, list) else node[k]
        if isinstance(node, list):
            node[int(keys[-1])] = value
        else:
            node[keys[-1]] = value
    return apply


@pytest.mark.parametrize("edit, where, text", [
    (_edit("shells.hemi.mesh.length", 3.0), "shells.hemi.mesh",
     "key(s) ['length'] do not apply to a 'spherical_cap' mesh"),
    (_edit("shells.hemi.mesh.polar_angles", [0.5, 0.2]), "shells.hemi.mesh.polar_angles",
     "expected polar angles [α0, α1] (rad, from the pole 'axis') with 0 ≤ α0 < α1 < π"),
    (_edit("shells.hemi.mesh.closed", True), "shells.hemi.mesh.angles",
     "a closed mesh turns once: θ1 − θ0 must be 2π"),
    (_edit("shells.hemi.mesh.kind", "sphere"), "shells.hemi.mesh.kind",
     "expected one of ['rectangle', 'triangle', 'annulus', 'cylinder', 'spherical_cap']"),
    (_edit("shells.hemi.points.A", [10.0, 0.0, 0.5]), "shells.hemi.points.A:",
     "no mesh node of shell 'hemi' within"),
    (_edit("loads.forces.pull.node", {"shell": "hemi", "at": [9.0, 0.0, 0.0]}), "loads.forces.pull.node.at",
     "no mesh node of shell 'hemi' within"),
    (_edit("loads.forces.pull.node", "hemi.Q"), "loads.forces.pull.node", "unknown node 'hemi.Q'"),
    (_edit("supports.0.normal", [0.0, 1.0, 1.0]), "supports[0].normal",
     "a symmetry normal must lie along x, y or z"),
    (_edit("supports.0.normal", [1.0, 0.0, 0.0]), "supports[0]:",
     "edge hemi.start is not in a plane x = const"),
    (_edit("supports.1.edge", "hemi.hole"), "supports[1]:",
     "edge hemi.hole is not in a plane x = const"),
    (lambda d: _edit("supports.1.edge", "hemi.hole")(d) or _edit("supports.1.normal", [0.0, 0.0, 1.0])(d),
     "supports[1]:", "shell 'hemi' does not meet the plane z = 9.51057 at a right angle"),
    (_edit("supports.0.type", "clamp"), "supports[0]",
     "key(s) ['normal'] do not apply to an edge support of type 'clamp'"),
    # every case of a keyed form names its missing keys the same way (the type, the keys, what they mean)
    (_edit("supports.2", {"node": "hemi.A", "type": "roller"}), "supports[2]",
     "a 'roller' support needs ['normal'] (the plane's normal along x, y or z, e.g. [1, 0, 0])"),
])
def test_bad_shell_vocabulary_names_the_key_and_the_reason(edit, where, text):
    d = copy.deepcopy(_hemisphere())
    edit(d)
    with pytest.raises(SceneError) as err:
        _compile(d)
    msg = str(err.value)
    assert where in msg and text in msg, msg


def test_a_closed_cylinder_has_no_seam_edges():
    path = SCENES / "shell_pinched_cylinder_closed.yaml"
    data = parse_yaml(read_scene_text(path), str(path))
    data["supports"].append({"edge": "tube.start", "type": "ball"})
    with pytest.raises(SceneError) as err:
        scene_from_dict(data, source=str(path))
    assert "supports[5].edge" in str(err.value)
    assert "a closed cylinder has no edge 'start'; its edges: ['bottom', 'top']" in str(err.value)


def test_a_path_following_monitor_may_name_a_mesh_point():
    from flexmb_core.integrators.path_following import PathFollower
    from flexmb_core.simulator import Simulator

    data = _hemisphere()
    data["solver"] = {"analysis": "static", "control": "arc_length", "arc_length": {"initial": 1e-3},
                      "monitor": {"node": "hemi.A", "component": "x"}, "until_displacement": 2e-3, "max_steps": 50}
    model = _compile(data)
    sim = Simulator(model)
    pf = PathFollower(sim)
    pf.initialize()
    pf.run()
    rep = pf.report()
    assert rep["monitor"] == {"node": "hemi.A", "component": "x"}
    gid = model.node_ydofs[model.node("hemi.A"), 0]
    assert rep["displacement"] == sim.state.q[gid] - model.q0[gid] >= 2e-3     # the pull at A is outward
    data["solver"]["monitor"]["node"] = "hemi.Z"
    with pytest.raises(SceneError, match=r"solver\.monitor\.node: unknown node 'hemi\.Z'; defined: .*'hemi\.A'"):
        _compile(data)
