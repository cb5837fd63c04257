"""Strict scene schema: errors name file:key, the value received and what was expected."""

import copy
from pathlib import Path

import pytest

from builders import cantilever
from flexmb_core.errors import SceneError
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene, scene_from_dict

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def _err(d, src="s.yaml"):
    with pytest.raises(SceneError) as info:
        compile_scene(scene_from_dict(d, source=src))
    return str(info.value)


def base():
    return cantilever(forces={"f": {"node": "tip", "force": [0, 0, -1.0]}})


def edit(fn):
    d = copy.deepcopy(base())
    fn(d)
    return d


@pytest.mark.parametrize("mutate, expected", [
    (lambda d: d["members"]["beam"].update(elemnts=3), "s.yaml:members.beam: unknown key(s) ['elemnts'] (did you mean "
                                                       "'elements' for 'elemnts'?); allowed keys: "),
    (lambda d: d.update(gravity=[0, 0, -9.81]), "s.yaml:<root>: unknown key(s) ['gravity']"),
    (lambda d: d["members"]["beam"].update(to="nowhere"), "s.yaml:members.beam.to: unknown node 'nowhere'"),
    (lambda d: d["members"]["beam"].update(section="steel"), "s.yaml:members.beam.section: unknown section 'steel'"),
    (lambda d: d["nodes"].update(tip=[1.0, 0.0]), "s.yaml:nodes.tip: expected a list of 3 numbers (m), got [1.0, 0.0]"),
    (lambda d: d["materials"]["m"].update(E=-2.0), "s.yaml:materials.m.E: expected a positive number (Pa), got -2.0"),
    (lambda d: d["materials"]["m"].update(E="stiff"), "s.yaml:materials.m.E: expected a number in Pa, got 'stiff'"),
    (lambda d: d["members"]["beam"].update(order=7), "s.yaml:members.beam.order: expected an integer ≤ 4, got 7"),
    (lambda d: d["members"]["beam"].update(kind="cable"), "expected one of ['frame', 'truss', 'actuator'], got 'cable'"),
    (lambda d: d["sections"]["s"].update(radius=0.1), "key(s) ['radius'] do not apply to a rectangle"),
    (lambda d: d["supports"].append({"node": "tip", "type": "weld"}), "s.yaml:supports[1].type: expected one of"),
    (lambda d: d["loads"]["forces"]["f"].update(node="middle"), "s.yaml:loads.forces.f.node: unknown node 'middle'"),
    (lambda d: d["solver"].update(dt=0), "s.yaml:solver.dt: expected a positive number (s), got 0.0"),
    # a direction whose length under- or overflows (it used to escape as ZeroDivisionError)
    (lambda d: d["members"]["beam"].update(up=[0.0, 0.0, 1e-300]),
     "s.yaml:members.beam.up: expected a non-zero vector (a direction; its squared length a positive, finite "
     "double), got [0.0, 0.0, 1e-300]"),
    # section properties out of double range (OverflowError, ZeroDivisionError in compile_scene before)
    (lambda d: d["sections"]["s"].update(width=1e300), "s.yaml:sections.s: the rectangle [1e+300, 0.02] m has no "
     "positive, finite area, second moments and torsion constant in double precision"),
    (lambda d: d["sections"].update(s={"shape": "circle", "radius": 1e-300}), "s.yaml:sections.s: the circle "
     "[1e-300] m has no positive, finite area"),
    # a negative rotary inertia made NaN mass entries (√ of the ratio to the section's own)
    (lambda d: d["members"]["beam"].update(mass={"rotary_inertia": [1e-3, -1e-3]}),
     "s.yaml:members.beam.mass.rotary_inertia: expected positive rotary inertias [ρI1, ρI2] (kg·m), got [0.001, -0.001]"),
    (lambda d: d["nodes"].update(lonely=[5, 5, 5]), "s.yaml:nodes: node(s) ['lonely'] are not used by any member or shell"),
    # a key that applies to some values of an earlier key only: one message for every such key (schema ``when``)
    (lambda d: d["members"]["beam"].update(actuator={"variant": "bar"}),
     "s.yaml:members.beam.actuator: key(s) ['actuator'] apply to kind: actuator only (kind is 'frame')"),
    (lambda d: d["outputs"].update(x={"kind": "actuator_force", "actuator": "beam"}), "member 'beam' is not an actuator"),
])
def test_errors_name_file_key_value_and_expectation(mutate, expected):
    assert expected in _err(edit(mutate))


def test_compile_errors_name_the_key():
    """Errors found while compiling name the key they are about, not only its block."""
    import dataclasses

    d = base()
    d["supports"] = [{"node": "root", "type": "revolute", "member": "beam", "axis": [1.0, 1.0, 0.0]}]
    msg = _err(d)
    assert msg.startswith("s.yaml:supports[0].axis: member 'beam' has no section vector along the axis "), msg
    assert "set the member's 'up' to the axis so that V2 lies on it" in msg
    # an actuator on an arc: refused by the schema from a file, and by the compiler from Python
    d = base()
    d["sections"]["s"] = {"shape": "circle", "radius": 0.01}
    d["nodes"]["foot"] = [0.0, -1.0, 0.0]
    d["members"]["lift"] = {"kind": "actuator", "from": "foot", "to": "tip", "material": "m", "section": "s",
                            "arc": {"center": [0.0, 0.0, 0.0]}}
    assert _err(d) == "s.yaml:members.lift.arc: actuators must be straight (no 'arc')"
    del d["members"]["lift"]["arc"]
    scene = scene_from_dict(d, source="s.yaml")
    bent = dataclasses.replace(scene.members["lift"], arc_center=(0.0, 0.0, 0.0))
    with pytest.raises(SceneError) as info:
        compile_scene(dataclasses.replace(scene, members={**scene.members, "lift": bent}))
    assert str(info.value) == "s.yaml:members.lift.arc: actuators must be straight (no 'arc')"


def test_yaml_file_errors_name_the_file(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("name: x\nmaterials: {m: {E: 1e9, rho: 1}}\nsections: {}\nnodes: {}\nmembers: {}\n")
    with pytest.raises(SceneError, match=r"bad.yaml"):
        load_scene(p)
    with pytest.raises(SceneError, match="cannot read scene file"):
        load_scene(tmp_path / "missing.yaml")
    p.write_text("name: [unclosed\n")
    with pytest.raises(SceneError, match="not valid YAML"):
        load_scene(p)


@pytest.mark.timeout(30)
def test_a_scene_path_that_is_no_regular_file_is_refused_unread(tmp_path):
    """A FIFO would block the read until a writer came and /dev/zero would fill the memory: both are
    refused from their file type, before any read, as is a directory."""
    import os

    fifo = tmp_path / "scene.yaml"
    os.mkfifo(fifo)
    for path, kind in ((fifo, "a FIFO"), (Path("/dev/zero"), "a character device"), (tmp_path, "a directory")):
        with pytest.raises(SceneError) as info:
            load_scene(path)
        assert str(info.value) == f"{path}: not a regular file ({kind}); expected a scene file (YAML)"


def test_exponent_floats_without_sign_are_numbers(tmp_path):
    """YAML 1.1 reads '200.0e9' as a string; scenes accept it as a number."""
    scene = load_scene(SCENES / "cantilever_b1.yaml")
    assert scene.materials["steel"].E == 200.0e9


@pytest.mark.parametrize("text,value", [("017", 17), ("0o17", 15), ("0x1F", 31), ("1_000", 1000), ("-.5", -0.5),
                                        ("+.5e3", 500.0), ("1:2:3", "1:2:3"), ("1:20.5", "1:20.5")])
def test_numbers_are_read_by_the_yaml_1_2_core_schema(text, value):
    """No base-60 integers or floats (YAML 1.1 reads '1:2:3' as 3723) and no octal '017': a scene
    value, an --override or a --param VALUE is the number it looks like, or a string the schema refuses."""
    from flexmb_core.scene.loader import parse_yaml

    assert parse_yaml(f"v: {text}")["v"] == value


def test_a_base_60_looking_value_and_an_integer_beyond_floats_are_refused_naming_the_key(tmp_path):
    text = (SCENES / "cantilever_b1.yaml").read_text()
    assert "E: 200.0e9" in text
    for bad, expect in (("1:2:3", "expected a number in Pa, got '1:2:3'"),
                        ("1" + "0" * 400, "expected a finite number, got an integer of 1329 bits")):
        p = tmp_path / "bad.yaml"
        p.write_text(text.replace("E: 200.0e9", f"E: {bad}"))
        with pytest.raises(SceneError) as err:
            load_scene(p)
        assert f"bad.yaml:materials.steel.E: {expect}" in str(err.value)


def test_shipped_scenes_compile():
    for path in sorted(SCENES.glob("*.yaml")):
        model = compile_scene(load_scene(path))
        s = model.summary()
        assert s["dofs"] > 0 and s["mass_kg"] > 0


def test_section_properties_are_computed():
    model = compile_scene(load_scene(SCENES / "cantilever_b1.yaml"))
    import math
    g = model.frame_groups[0]
    area = g.w[0].sum() * 8                         # Σw = element volume A·L/8
    assert area == pytest.approx(math.pi * 0.005**2, rel=1e-12)
    assert model.total_mass == pytest.approx(7850 * math.pi * 0.005**2, rel=1e-12)


@pytest.mark.parametrize("nodes", [["A", "A", "B"], ["A", "B", "A"]])
def test_a_platform_pose_of_no_triangle_is_refused_naming_its_nodes(nodes):
    """Coincident (or collinear) pose nodes give a NaN frame: the JSON of a run carried NaN poses."""
    from flexmb_core.scene.loader import parse_yaml

    path = SCENES / "stewart_platform_bars.yaml"
    data = parse_yaml(path.read_text(), str(path))
    data["outputs"]["platform"]["nodes"] = nodes
    with pytest.raises(SceneError) as info:
        compile_scene(scene_from_dict(data, source=str(path)))
    assert str(info.value).startswith(f"{path}:outputs.platform.nodes: nodes {nodes} at [[")
    assert str(info.value).endswith("m span no triangle (coincident or collinear); expected three nodes of the "
                                    "platform that do")
