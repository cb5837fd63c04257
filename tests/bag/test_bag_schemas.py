"""The message definitions embedded in recordings match the installed ROS 2 interfaces.

Recording works without ROS from the copies in ``flexmb_io/bag/msgdefs`` (standard types) and
``msgs/msg`` (flexmb_msgs). Where the interface packages are installed (the venv's ament prefix),
each copy must equal the installed ``.msg`` (comments aside), and the RIHS01 type hash written to
``metadata.yaml`` must equal the one rosidl generated (``share/<pkg>/msg/<Type>.json``).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from flexmb_io.bag import schemas
from flexmb_io.bag.rosbag2 import type_hash

VENDORED = sorted(schemas.VENDORED.glob("*/msg/*.msg"))


def _installed(pkg: str, name: str, ext: str = "msg") -> Path | None:
    for prefix in schemas._ament_prefixes():
        p = prefix / "share" / pkg / "msg" / f"{name}.{ext}"
        if p.is_file():
            return p
    return None


def test_every_recorded_type_has_a_complete_schema():
    for t in schemas.RECORDED_TYPES:
        deps = schemas.dependencies(t)
        text = schemas.schema_text(t)
        assert deps[0] == t
        for d in deps[1:]:
            pkg, _, name = d.split("/")
            assert f"MSG: {pkg}/{name}\n" in text
    assert "MSG: std_msgs/Header" in schemas.schema_text("flexmb_msgs/msg/TwinStatus")
    # every vendored file is used by some recorded type (no stale copies)
    used = {d for t in schemas.RECORDED_TYPES for d in schemas.dependencies(t)}
    for path in VENDORED:
        assert f"{path.parts[-3]}/msg/{path.stem}" in used, f"{path} is not needed by any recorded type"


def test_vendored_definitions_match_the_installed_interfaces():
    if _installed("std_msgs", "Header") is None:
        pytest.skip("no ROS 2 interface packages installed in this environment")
    compared, missing = [], []
    for path in VENDORED:
        pkg, name = path.parts[-3], path.stem
        inst = _installed(pkg, name)
        if inst is None:
            missing.append(f"{pkg}/{name}")            # tf2_msgs is not on PyPI
            continue
        assert schemas.strip_comments(path.read_text()) == schemas.strip_comments(inst.read_text()), (
            f"{path} differs from {inst}: refresh with python -m flexmb_io.bag.schemas --refresh PREFIX")
        compared.append(f"{pkg}/{name}")
    assert len(compared) >= 15, (compared, missing)
    assert set(missing) <= {"tf2_msgs/TFMessage"}, missing


def test_flexmb_msgs_in_the_repository_match_the_installed_package():
    if _installed("flexmb_msgs", "TwinStatus") is None:
        pytest.skip("flexmb_msgs is not built into this environment (make setup)")
    for path in sorted(schemas.REPO_MSGS.glob("*.msg")):
        inst = _installed("flexmb_msgs", path.stem)
        assert inst is not None, f"flexmb_msgs/{path.stem} is not installed: run make setup"
        assert schemas.strip_comments(path.read_text()) == schemas.strip_comments(inst.read_text()), (
            f"{path} differs from the installed {inst}: run make setup")


def test_type_hashes_equal_the_ones_rosidl_generated():
    checked = 0
    for t in schemas.RECORDED_TYPES:
        pkg, _, name = t.split("/")
        desc = _installed(pkg, name, "json")
        if desc is None:
            continue
        hashes = {h["type_name"]: h["hash_string"] for h in json.loads(desc.read_text())["type_hashes"]}
        assert type_hash(t, schemas.schema_text(t)) == hashes[t], t
        checked += 1
    if _installed("std_msgs", "Header") is not None:
        assert checked >= 8, checked
    else:
        pytest.skip("no installed type descriptions to compare with")
