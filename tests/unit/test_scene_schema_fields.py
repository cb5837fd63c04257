"""The scene schema is written once (issue 16, item 4): every key a scene may hold is a field of a
schema dataclass (:mod:`flexmb_core.scene.schema`), read by one typed reader
(:mod:`flexmb_core.scene.typed`).

These tests walk the dataclasses, so a field added to the schema is covered without editing them:
every field is a key some scene here sets (the shipped scenes and the few extra scenes below), and
every mapping the schema reads refuses a key it does not have — and, for a keyed form (a section's
``shape``, a signal's ``kind``), the keys of the other cases — naming ``file:key``.
"""

from __future__ import annotations

import copy
import dataclasses
import re
import typing
from pathlib import Path

import pytest

from builders import cantilever
from flexmb_core.errors import SceneError
from flexmb_core.scene import schema, typed
from flexmb_core.scene.include import compose
from flexmb_core.scene.loader import parse_yaml, read_scene_text, scene_from_dict
from flexmb_core.scene.reader import Node

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted((ROOT / "scenes").glob("*.yaml")) + sorted((ROOT / "tests" / "data" / "scenes").glob("*.yaml"))
BOGUS = "zz_not_a_key"


# -- the schema, walked ---------------------------------------------------------------------------

def _forms(f) -> list:
    """The dataclasses and keyed forms a field's value is read as (what the reader dispatches on)."""
    if f.spec.form is not None:
        return [f.spec.form]
    out, stack = [], [f.tp]
    while stack:
        t = stack.pop()
        args = [a for a in typing.get_args(t) if a is not Ellipsis and a is not type(None)]
        if args and typing.get_origin(t) is not typing.Literal:
            stack.extend(args)
        elif isinstance(t, type) and getattr(t, "yaml_form", None) is not None:
            out.append(t.yaml_form)
        elif dataclasses.is_dataclass(t):
            out.append(t)
    return out


def schema_classes() -> tuple[dict[type, set[str]], dict[type, list[typed.OneOf]]]:
    """Every dataclass a scene mapping is read as, with its keys; and the keyed forms each case
    class belongs to. From :class:`~flexmb_core.scene.schema.SceneFile` down, plus the classes the
    loader reads itself (mesh points, ``include`` items)."""
    keys: dict[type, set[str]] = {}
    cases: dict[type, list[typed.OneOf]] = {}

    def walk(form) -> None:
        if isinstance(form, typed.OneOf):
            for c in dict.fromkeys(form.cases.values()):
                cases.setdefault(c, []).append(form)
                walk(c)
            if form.split is not None:
                walk(form.split[1])
            return
        if form in keys:
            return
        keys[form] = typed.keys(form)
        for f in typed._fields(form):
            for sub in _forms(f):
                walk(sub)

    for root in (schema.SceneFile, schema.ShellPoint, schema.IncludeItem):
        walk(root)
    return keys, cases


# -- scenes that set the keys no shipped scene needs ------------------------------------------------

def _frame_extras() -> dict:
    d = cantilever(forces={"f": {"node": "tip", "force": [0, 0, -1.0],
                                 "signal": {"kind": "sine", "offset": 0.0, "amplitude": 1.0, "frequency": 2.0,
                                            "phase": 0.1}}})
    d["sections"].update(rod={"shape": "circle", "radius": 0.01, "torsion_constant": 1e-8, "shear_factor": 0.9},
                         pipe={"shape": "tube", "outer_radius": 0.02, "inner_radius": 0.015,
                               "torsion_constant": 1e-7, "shear_factor": 0.5})
    d["nodes"]["base"] = [0.5, -1.0, 0.0]
    d["members"]["beam"]["integration"] = "full"
    d["members"]["lift"] = {"kind": "actuator", "from": "base", "to": "tip", "material": "m", "section": "pipe",
                            "actuator": {"command": {"kind": "constant", "value": 1.2},
                                         "servo": {"bandwidth_hz": 10.0, "damping_ratio": 0.7, "max_rate": 1.0,
                                                   "max_accel": 20.0}}}
    d["members"]["strut"] = {"kind": "truss", "from": "base", "to": "root", "material": "m", "section": "rod"}
    d["supports"] = [{"node": "root", "type": "driven", "member": "beam",
                      "translation": {"direction": [1, 0, 0], "distance": {"kind": "ramp", "duration": 1.0,
                                                                           "t0": 0.5}}},
                     {"node": "base", "type": "ball"}]
    d["loads"]["gravity"] = {"acceleration": [0, 0, -9.81], "signal": 1.0}
    d["loads"]["moments"] = {"m": {"node": "tip", "member": "beam", "moment": [0, 0, 1.0], "follower": True,
                                   "signal": 0.5}}
    d["solver"] = {"analysis": "dynamic", "initial_acceleration": "zero", "max_substep_levels": 2,
                   "on_unconverged": "stop", "newton": "modified", "modified_contraction": 0.5,
                   "tangent_max_age": 10, "held_tangent": "fixed"}
    d["limits"] = {"max_actuator_force": 5.0e4, "singular_configurations": "ignore", "on_violation": "stop"}
    return d


def _displacement_control() -> dict:
    d = cantilever(forces={"f": {"node": "tip", "force": [0, 0, -1.0]}})
    d["solver"] = {"analysis": "static", "control": "displacement", "allow_snap_through": True,
                   "displacement": {"node": "tip", "component": "z", "to": -0.01, "initial": 0.001,
                                    "min": 1e-5, "max": 0.002, "target_iterations": 4}}
    return d


def _shell_extras() -> dict:
    return {
        "name": "shell_extras",
        "materials": {"al": {"E": 7e10, "nu": 0.3, "rho": 2700.0}},
        "nodes": {"a": [0, 0, 0], "b": [1, 0, 0], "c": [1, 1, 0], "d": [0, 1, 0]},
        "shells": {
            "plate": {"mesh": {"kind": "rectangle", "corners": ["a", "b", "c", "d"], "divisions": [2, 2],
                               "pattern": "right"},
                      "thickness": 0.01, "material": "al",
                      "points": {"p": {"at": [0.0, 0.5, 0.0], "edge": "left", "tolerance": 1e-3}}},
            "ring": {"mesh": {"kind": "annulus", "center": [0, 0, 2], "axis": [0, 0, 1], "reference": [1, 0, 0],
                              "inner_radius": 1.0, "outer_radius": 2.0, "divisions": [1, 4], "pattern": "left",
                              "closed": True},
                     "thickness": 0.01, "material": "al"},
        },
        "supports": [{"edge": "plate.bottom", "type": "clamp"}, {"edge": "ring.inner", "type": "clamp"}],
    }


def _with_pattern(name: str, shell: str) -> dict:
    path = ROOT / "scenes" / name
    d = parse_yaml(read_scene_text(path), str(path))
    d["shells"][shell]["mesh"]["pattern"] = "left"
    return d


def _scenes() -> list[tuple[dict, str]]:
    out = [(parse_yaml(read_scene_text(p), str(p)), str(p)) for p in SHIPPED]
    out += [(_frame_extras(), "frame_extras.yaml"), (_displacement_control(), "displacement_control.yaml"),
            (_shell_extras(), "shell_extras.yaml"),
            (_with_pattern("shell_pinched_cylinder.yaml", "tube"), "cylinder_pattern.yaml"),
            (_with_pattern("shell_pinched_hemisphere.yaml", "hemi"), "cap_pattern.yaml")]
    return out


@pytest.fixture(scope="module")
def loaded():
    """Every scene loaded once with the typed reader watched: the keys each schema class was read
    with, and the first place (scene, path) each class was read at."""
    seen: dict[type, set[str]] = {}
    where: dict[type, tuple[int, str]] = {}
    current = [0]
    build = typed._Reader._build

    def watch(self, node, cls, given, values):
        if isinstance(node.value, dict):
            seen.setdefault(cls, set()).update(set(node.value) & typed.keys(cls, given))
            where.setdefault(cls, (current[0], node.path))
        return build(self, node, cls, given, values)

    scenes = _scenes()
    typed._Reader._build = watch
    try:
        for i, (data, source) in enumerate(scenes):
            current[0] = i
            data = compose(data, source)             # the include items are read here
            scenes[i] = (data, source)
            scene_from_dict(data, source=source)
            seen.setdefault(schema.SceneFile, set()).update(data)
    finally:
        typed._Reader._build = build
    return scenes, seen, where


def test_every_schema_field_is_a_key_some_scene_sets(loaded):
    _, seen, _ = loaded
    keys, _ = schema_classes()
    missing = [f"{cls.__name__}.{k}" for cls, ks in keys.items() for k in sorted(ks - seen.get(cls, set()))]
    assert not missing, f"schema keys no test scene sets (add one to this file's extras): {missing}"
    assert len(keys) > 60                           # the walk reaches the whole schema


def _at(data: dict, path: str) -> dict:
    node = data
    for part in re.findall(r"[^.\[\]]+|\[\d+\]", path):
        node = node[int(part[1:-1])] if part.startswith("[") else node[part]
    return node


def _refused(data: dict, source: str, path: str, key: str, value=1.0) -> str:
    d = copy.deepcopy(data)
    _at(d, path)[key] = value
    with pytest.raises(SceneError) as err:
        scene_from_dict(d, source=source)
    return str(err.value)


def test_every_mapping_refuses_a_key_it_does_not_have(loaded):
    scenes, _, where = loaded
    keys, _ = schema_classes()
    checked = 0
    for cls in keys:
        if cls is schema.IncludeItem:                 # read before composing: tests/unit/test_scene_include.py
            continue
        i, path = where.get(cls, (None, None)) if cls is not schema.SceneFile else (0, "")
        assert i is not None, f"{cls.__name__} was never read"
        data, source = scenes[i]
        msg = _refused(data, source, path, BOGUS)
        assert msg.startswith(f"{source}:{path or '<root>'}: unknown key(s) ['{BOGUS}']; allowed keys: "), \
            (cls.__name__, msg)
        checked += 1
    assert checked == len(keys) - 1


def test_every_case_refuses_the_keys_of_the_other_cases(loaded):
    """A section's ``radius`` on a rectangle, a sine's ``frequency`` on a ramp …: refused with the
    case named, for every key that another case of the same form takes."""
    scenes, _, where = loaded
    _, cases = schema_classes()
    checked = 0
    for cls, forms in cases.items():
        i, path = where[cls]
        data, source = scenes[i]
        own = typed.keys(cls) | {f.tag for f in forms}
        for form in forms:
            tag = _at(data, path).get(form.tag)
            if form.cases.get(tag) is not cls:
                continue                          # read through the other form of a split
            for other in sorted(set().union(*map(typed.keys, form.cases.values())) - own):
                msg = _refused(data, source, path, other)
                assert msg.startswith(f"{source}:{path}: key(s) ['{other}'] do not apply to "
                                      f"{form.title.format(tag)}; expected "), (cls.__name__, msg)
                checked += 1
    assert checked > 100


def test_a_field_reads_its_type_range_and_default_from_the_schema():
    """The reader's rules on a small dataclass of its own: required, default, range, choices,
    renamed key, computed default, ``when`` and ``check()``."""

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Probe:
        size: float = typed.spec(positive=True, unit="m")
        count: int = typed.spec(3, lo=1, hi=9)
        mode: typing.Literal["a", "b"] = "a"
        start: str = typed.spec("x", key="from")
        half: float = typed.spec(default_from=lambda v: v["size"] / 2)
        extra: float = typed.spec(0.0, when=(("mode", ("b",)),))

        def check(self):
            if self.half > self.size:
                raise typed.Invalid(f"half {self.half} exceeds size {self.size}", "half")

    def read(value):
        return typed.read(Node(value, "p", "f.yaml"), Probe)

    def fails(value):
        with pytest.raises(SceneError) as err:
            read(value)
        return str(err.value)

    assert read({"size": 2.0}) == Probe(size=2.0, count=3, mode="a", start="x", half=1.0, extra=0.0)
    assert read({"size": 2, "from": "y", "mode": "b", "extra": 1.0, "half": 0.5}) == Probe(
        size=2.0, count=3, mode="b", start="y", half=0.5, extra=1.0)
    assert fails({}) == "f.yaml:p: missing required key(s) ['size']"
    assert fails({"size": -1.0}) == "f.yaml:p.size: expected a positive number (m), got -1.0"
    assert fails({"size": 1.0, "count": 10}) == "f.yaml:p.count: expected an integer ≤ 9, got 10"
    assert fails({"size": 1.0, "mode": "c"}) == "f.yaml:p.mode: expected one of ['a', 'b'], got 'c'"
    assert fails({"size": 1.0, "start": "y"}) == ("f.yaml:p: unknown key(s) ['start']; allowed keys: "
                                                  "['count', 'extra', 'from', 'half', 'mode', 'size']")
    assert fails({"size": 1.0, "extra": 2.0}) == "f.yaml:p.extra: key(s) ['extra'] apply to mode: b only (mode is 'a')"
    assert fails({"size": 1.0, "half": 3.0}) == "f.yaml:p.half: half 3.0 exceeds size 1.0"
    assert fails([1.0]) == "f.yaml:p: expected a mapping, got [1.0]"


def test_material_defaults_come_from_the_schema():
    """G = E / 2(1 + ν) and ν = 0 when not given (the field defaults), bit for bit."""
    d = cantilever(E=2.0e11)
    del d["materials"]["m"]["nu"]
    m = scene_from_dict(d, source="s.yaml").materials["m"]
    assert (m.nu, m.G, m.eta) == (0.0, 2.0e11 / (2.0 * (1.0 + 0.0)), 0.0)
    d["materials"]["m"]["nu"] = 0.3
    assert scene_from_dict(d, source="s.yaml").materials["m"].G == 2.0e11 / (2.0 * (1.0 + 0.3))


def test_a_bad_signal_value_says_what_a_signal_may_be():
    d = cantilever(forces={"f": {"node": "tip", "force": [0, 0, -1.0], "signal": "fast"}})
    with pytest.raises(SceneError) as err:
        scene_from_dict(d, source="s.yaml")
    assert str(err.value) == ("s.yaml:loads.forces.f.signal: expected a number or a mapping with 'kind' (one of "
                              "['constant', 'ramp', 'sine', 'table', 'spin_up']), got 'fast'")


def test_a_support_on_an_edge_takes_no_node():
    path = ROOT / "scenes" / "shell_pinched_hemisphere.yaml"
    d = parse_yaml(read_scene_text(path), str(path))
    d["supports"][0]["node"] = "hemi.A"
    with pytest.raises(SceneError) as err:
        scene_from_dict(d, source="h.yaml")
    assert str(err.value) == "h.yaml:supports[0]: key(s) ['node'] do not apply with 'edge'; expected ['edge', 'normal', 'type']"
