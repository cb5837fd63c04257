"""Scene composition (``include:`` with overrides, :mod:`flexmb_core.scene.include`): merge order,
relative paths from the including file, overrides by dotted keys, and the rejections (cycles,
missing files, overrides of keys the included scene lacks) with their messages."""

from pathlib import Path

import pytest

from flexmb_core.errors import SceneError
from flexmb_core.scene import load_scene

BASE = """
name: base
description: a base scene
materials:
  steel: {E: 2.0e11, nu: 0.3, rho: 7850.0}
sections:
  bar: {shape: circle, radius: 0.01}
nodes: {a: [0.0, 0.0, 0.0], b: [1.0, 0.0, 0.0]}
members:
  beam: {kind: frame, from: a, to: b, elements: 2, material: steel, section: bar}
supports:
  - {node: a, type: clamp}
solver: {analysis: static, dt: 0.5, until: 1.0}
"""


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def test_include_with_overrides_then_own_keys_on_top(tmp_path):
    _write(tmp_path / "lib" / "base.yaml", BASE)
    top = _write(tmp_path / "cases" / "top.yaml", """
include:
  file: ../lib/base.yaml
  overrides: {materials.steel.E: 2.2e11, members.beam.elements: 3, solver.tolerance: 1.0e-10}
name: top
materials:
  alu: {E: 7.0e10, rho: 2700.0}
supports:
  - {node: a, type: ball}
""")
    scene = load_scene(top)
    assert scene.name == "top" and scene.description == "a base scene"
    assert scene.materials["steel"].E == 2.2e11                     # override in the included file
    assert set(scene.materials) == {"steel", "alu"}                 # mappings merge
    assert scene.members["beam"].elements == 3
    assert [s.type for s in scene.supports] == ["ball"]            # lists replace
    assert scene.solver.tolerance == 1e-10 and scene.solver.dt == 0.5
    assert scene.source == str(top)


def test_includes_compose_in_order_and_nest_relative_to_each_file(tmp_path):
    _write(tmp_path / "a" / "base.yaml", BASE)
    _write(tmp_path / "a" / "mid.yaml", "include: base.yaml\nname: mid\nsolver: {dt: 0.25}\ndescription: null\n")
    _write(tmp_path / "b" / "mat.yaml", "materials: {steel: {E: 1.0e11, rho: 7000.0}}\n")
    top = _write(tmp_path / "top.yaml", "include: [a/mid.yaml, b/mat.yaml]\n")
    scene = load_scene(top)
    assert scene.name == "mid" and scene.description == ""              # null removes a key
    assert scene.solver.dt == 0.25 and scene.solver.until == 1.0    # nested mappings merge
    assert scene.materials["steel"].E == 1.0e11 and scene.materials["steel"].nu == 0.3


@pytest.mark.parametrize("files, top, where, text", [
    ({"a.yaml": "include: b.yaml\nname: a\n", "b.yaml": "include: {file: a.yaml}\nname: b\n"}, "a.yaml",
     "b.yaml:include.file", "include cycle: a.yaml → b.yaml → a.yaml; a scene may not include itself"),
    ({"a.yaml": "include: [a.yaml]\nname: a\n"}, "a.yaml", "a.yaml:include[0]", "include cycle: a.yaml → a.yaml"),
    ({"a.yaml": "include: nowhere.yaml\nname: a\n"}, "a.yaml", "a.yaml:include",
     "no scene file"),
    ({"base.yaml": BASE, "a.yaml": "include: {file: base.yaml, overrides: {materials.copper.E: 1.0}}\n"},
     "a.yaml", "a.yaml:include.overrides.materials.copper.E", "the scene has no key 'materials.copper'"),
    ({"base.yaml": BASE, "a.yaml": "include: {file: base.yaml, override: {}}\n"}, "a.yaml", "a.yaml:include",
     "unknown key(s) ['override'] (did you mean 'overrides' for 'override'?); allowed keys: ['file', 'overrides']"),
])
def test_bad_includes_are_refused_with_the_key_and_the_reason(tmp_path, files, top, where, text):
    for name, body in files.items():
        _write(tmp_path / name, body)
    with pytest.raises(SceneError) as err:
        load_scene(tmp_path / top)
    msg = str(err.value)
    assert where in msg and text in msg, msg


def test_relative_include_needs_a_file_location():
    from flexmb_core.scene.loader import scene_from_dict

    with pytest.raises(SceneError) as err:
        scene_from_dict({"include": "base.yaml", "name": "x"})
    assert "<dict>:include" in str(err.value) and "needs the including file's location" in str(err.value)
