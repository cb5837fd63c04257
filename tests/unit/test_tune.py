"""`flexmb tune`: every candidate is a valid scene, the chosen one stays within the tolerance of
the refined reference (re-checked independently), errors are measured as documented, and a
tolerance nothing can meet is reported, not hidden. No timing is asserted."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from flexmb_core.cli import main
from flexmb_core.scene.loader import load_scene, parse_yaml, scene_from_dict
from flexmb_core.tune import _run, moves, output_errors, reference_scene

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def test_every_move_gives_a_valid_scene():
    for name in ("stewart_platform.yaml", "radiator_panels.yaml", "actuator_arm.yaml"):
        data = parse_yaml((SCENES / name).read_text())
        labels = []
        for label, move in moves(data):
            import copy
            scene_from_dict(move(copy.deepcopy(data)), source=f"{name} [{label}]")
            labels.append(label)
        scene_from_dict(reference_scene(data), source=f"{name} [reference]")
        assert any("Δt × 2" in x for x in labels)
    legs = [lbl for lbl, _ in moves(parse_yaml((SCENES / "stewart_platform.yaml").read_text())) if "leg1" in lbl]
    assert legs == ["leg1…leg6 (6): bar actuator", "leg1…leg6 (6): 2 elements"]   # the six legs move together


def test_output_errors_follow_the_documented_units():
    ref = {"p": ("platform_pose", np.array([[0, 0, 1, 1, 0, 0, 0.0]])),
           "f": ("actuator_force", np.array([[100.0], [-200.0]])),
           "x": ("node_position", np.array([[1.0, 2.0, 3.0]]))}
    c, s = math.cos(0.001), math.sin(0.001)          # 2 mrad rotation about x
    run = {"p": ("platform_pose", np.array([[0, 3e-4, 1, c, s, 0, 0.0]])),
           "f": ("actuator_force", np.array([[101.0], [-200.0]])),
           "x": ("node_position", np.array([[1.0, 2.0 + 3e-5, 3.0 + 4e-5]]))}
    e = output_errors(run, ref)
    assert e["p.position"] == pytest.approx(3e-4)
    assert e["p.orientation"] == pytest.approx(2e-3, rel=1e-6)
    tiny = {"p": ("platform_pose", np.array([[0, 0, 1, math.cos(1e-11), math.sin(1e-11), 0, 0.0]]))}
    assert output_errors(tiny, {"p": ref["p"]})["p.orientation"] == pytest.approx(2e-11, rel=1e-6)
    assert e["f"] == pytest.approx(1.0 / 200.0)
    assert e["x"] == pytest.approx(5e-5)


def test_tune_chooses_a_scene_within_tolerance_and_writes_it(tmp_path):
    rc = main(["tune", str(SCENES / "actuator_arm.yaml"), "--tol", "1e-4", "--until", "0.4", "--out", str(tmp_path),
               "--quiet"])
    assert rc == 0
    report = json.loads((tmp_path / "actuator_arm_tune.json").read_text())
    assert report["within_tolerance"] and report["trials"][0]["label"] == "as declared"
    assert all(set(t["errors"]) >= {"arm_end", "lift_force"} for t in report["trials"] if not t["message"])
    assert "| candidate | within tol |" in (tmp_path / "actuator_arm_tune.md").read_text()
    # the written scene loads and, run on its own, stays within the tolerance of the reference
    tuned = load_scene(tmp_path / "actuator_arm_tuned.yaml")
    data = parse_yaml((SCENES / "actuator_arm.yaml").read_text())
    sample = 4 * data["solver"]["dt"]
    ref, _, _ = _run(reference_scene(data), 0.4, sample, "ref")
    mine, _, _ = _run(parse_yaml((tmp_path / "actuator_arm_tuned.yaml").read_text()), 0.4, sample, "tuned")
    errs = output_errors(mine, ref)
    assert max(errs[k] for k in ("arm_end", "arm_mid", "lift_length")) <= 1e-4
    assert tuned.solver.dt >= data["solver"]["dt"]


def test_an_unreachable_tolerance_is_reported_with_exit_3(tmp_path, capsys):
    rc = main(["tune", str(SCENES / "actuator_arm.yaml"), "--tol", "1e-15", "--until", "0.2", "--out", str(tmp_path),
               "--outputs", "arm_end"])
    assert rc == 3
    report = json.loads((tmp_path / "actuator_arm_tune.json").read_text())
    assert not report["within_tolerance"] and report["chosen"] == "as declared"
    assert "largest error" in capsys.readouterr().out


def test_bad_tune_input_names_the_flag(capsys):
    assert main(["tune", str(SCENES / "actuator_arm.yaml"), "--tol", "1e-4", "--outputs", "nope"]) == 1
    err = capsys.readouterr().err
    assert "--outputs names ['nope'], which the scene does not declare; declared: ['arm_end'" in err
    assert main(["tune", str(SCENES / "actuator_arm.yaml"), "--tol", "-1"]) == 1
    assert "--tol must be a positive number, got -1.0" in capsys.readouterr().err
