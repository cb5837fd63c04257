"""Malformed scenes (issue 15): every bad file gets one clear answer — exit 1, a message that names
the file and the key (or line:column), bounded in size — within 2 s and 500 MB, whatever the file
holds (alias bombs, 10⁷ elements through aliased members, non-UTF-8, deep nesting, duplicates).

Each case runs ``flexmb check FILE`` as a subprocess and measures its wall time and peak RSS with
``os.wait4`` (the child's own resource usage). The limits are bounds on the program's behaviour, not
benchmarks: the clean cases answer in well under a second.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FLEXMB = ROOT / ".venv" / "bin" / "flexmb"
WALL_S, RSS_MB, MESSAGE_BYTES = 2.0, 500.0, 2048
# The 2 s bound is held on the child's CPU time (user + system, from wait4): the machine is shared,
# and a loaded machine stretches wall time without the program doing more. Unloaded, wall ≈ CPU
# (0.5–0.8 s per case); wall is held to a looser hard bound.
WALL_LOADED_S = 3 * WALL_S

BASE = """\
name: malformed
materials:
  steel: {E: 200.0e9, nu: 0.3, rho: 7850.0}
sections:
  rod: {shape: circle, radius: 0.005}
nodes:
  root: [0.0, 0.0, 0.0]
  tip: [1.0, 0.0, 0.0]
members:
  beam: {kind: frame, from: root, to: tip, elements: 4, material: steel, section: rod}
supports:
  - {node: root, type: clamp}
"""


def _aliased_members(n_members: int, elements: int) -> str:
    """``n_members`` members that are one aliased mapping of ``elements`` elements each."""
    head = BASE.replace("  beam: {kind: frame,", f"  m0: &m {{kind: frame, elements: {elements},").replace(
        ", elements: 4, material", ", material")
    rest = "".join(f"  m{i}: *m\n" for i in range(1, n_members))
    return head.replace("supports:", rest + "supports:")


def _alias_bomb(levels: int = 9) -> str:
    """Billion laughs: 9 levels of 9 aliases (9⁹ ≈ 3.9·10⁸ values) where a vector is expected."""
    lines = ["bomb0: &b0 [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]"]
    for i in range(1, levels):
        lines.append(f"bomb{i}: &b{i} [" + ", ".join([f"*b{i - 1}"] * 9) + "]")
    bomb = "\n".join("x-" + ln for ln in lines)          # x-…: extra top-level keys, refused later
    return bomb + "\n" + BASE.replace("  tip: [1.0, 0.0, 0.0]", f"  tip: *b{levels - 1}")


def _unused_nodes(n: int) -> str:
    """``n`` unused nodes, all at one aliased position (compact: 2n YAML values to compose)."""
    extra = "".join(f"  spare{i}: *p\n" for i in range(n))
    return BASE.replace("  tip: [1.0, 0.0, 0.0]\n", "  tip: [1.0, 0.0, 0.0]\n  spare: &p [0.0, 1.0, 0.0]\n"
                        ).replace("members:", extra + "members:")


def _duplicate_node() -> str:
    return BASE.replace("  tip: [1.0, 0.0, 0.0]\n", "  tip: [1.0, 0.0, 0.0]\n  tip: [2.0, 0.0, 0.0]\n")


def _duplicate_member() -> str:
    line = "  beam: {kind: frame, from: root, to: tip, elements: 4, material: steel, section: rod}\n"
    return BASE.replace(line, line + line.replace("elements: 4", "elements: 2"))


def _generated_name_clash() -> str:
    """A scene node named like a generated interior node ('beam/1')."""
    return BASE.replace("  tip: [1.0, 0.0, 0.0]\n", "  tip: [1.0, 0.0, 0.0]\n  beam/1: [0.25, 0.0, 0.0]\n").replace(
        "supports:", "  other: {kind: truss, from: root, to: beam/1, material: steel, section: rod}\nsupports:")


CASES = {
    # id: (file contents (str or bytes), text the message must contain)
    "aliased_members_1e7_elements": (_aliased_members(1000, 10000),
                                     ":members: total number of elements: 10 000 000"),
    "aliased_members_1e5_elements": (_aliased_members(10, 10000),
                                     "exceeds the limit of 5 000; raise it with `flexmb check|run --max-elements N`"),
    "alias_bomb_as_vector": (_alias_bomb(), ":6:10: YAML values after alias expansion (anchor &b5): 597 871 exceeds "
                                            "the limit of 100 000; raise it with `flexmb check|run --max-yaml-nodes N`"),
    "recursive_alias": (BASE.replace("  tip: [1.0, 0.0, 0.0]", "  tip: &t [1.0, *t, 0.0]"),
                        "recursive alias (anchor &t): a value contains itself"),
    "non_utf8": (BASE.encode().replace(b"name: malformed", b"name: mal\xfformed"),
                 ":1:10: not UTF-8 text: byte ff at offset 9"),
    "deep_brackets": (BASE.replace("  tip: [1.0, 0.0, 0.0]", "  tip: " + "[" * 100_000 + "]" * 100_000),
                      re.compile(r":8:\d+: nesting deeper than 64 levels \(a scene needs about 8\)")),
    "unclosed_brackets": (BASE.replace("  tip: [1.0, 0.0, 0.0]", "  tip: " + "[" * 100_000),
                          re.compile(r":8:\d+: nesting deeper than 64 levels \(a scene needs about 8\)")),
    "duplicate_key": (BASE.replace("{E: 200.0e9,", "{E: 200.0e9, E: 1.0,"),
                      ":3:23: duplicate key 'E' (first at line 3)"),
    "duplicate_node": (_duplicate_node(), ":9:3: duplicate key 'tip' (first at line 8)"),
    "duplicate_member": (_duplicate_member(), ":11:3: duplicate key 'beam' (first at line 10)"),
    "generated_node_name": (_generated_name_clash(), ":nodes.beam/1: the name 'beam/1' is taken by interior node 1"),
    "unused_nodes_200k": (_unused_nodes(200_000), ":49991:3: YAML values (scalars, lists, mappings): 100 001 (counting "
                                                  "stopped here) exceeds the limit of 100 000"),
    "huge_unknown_keys": (BASE.replace("name: malformed\n", "name: malformed\n" + "".join(
        f"k{i}: 1\n" for i in range(20_000))), ":<root>: unknown key(s) ['k0', 'k1', 'k10', 'k100', 'k1000', "
                                                 "'k10000', 'k10001', 'k10002', … and 19 992 more]; allowed keys:"),
    "huge_list_where_number_expected": (BASE.replace("radius: 0.005", "radius: [" + "1, " * 50_000 + "1]"),
                                        ":sections.rod.radius: expected a number in m, got list of "
                                        "50 001 items [1, 1, 1"),
    "huge_string": (BASE.replace("radius: 0.005", "radius: " + "x" * 1_000_000),
                    ":sections.rod.radius: expected a number in m, got 'xxxx"),
    "huge_integer": (BASE.replace("radius: 0.005", "radius: 1" + "0" * 5000),
                     ":5:32: an integer of 5 001 digits; expected a number a scene can use"),
    "not_a_mapping": ("- just\n- a list\n", ":<root>: expected a mapping, got ['just', 'a list']"),
    "invalid_yaml": (BASE.replace("  rod: {shape: circle, radius: 0.005}", "  rod: {shape: circle, radius: 0.005"),
                     "not valid YAML"),
    "degenerate_up": (BASE.replace("section: rod}", "section: rod, up: [1.0, 0.0, 0.0]}"),
                      ":members.beam.up: 'up' [1.0, 0.0, 0.0] is parallel to the member axis"),
    "missing_file": (None, "cannot read scene file (No such file or directory)"),
    "control_character": (BASE.replace("name: malformed", "name: mal\x00formed"),
                          ":1:10: not valid YAML: the control character U+0000 is not allowed in YAML text"),
    "member_below_rounding": (BASE.replace("tip: [1.0, 0.0, 0.0]", "tip: [1.0, 1.0e-100, 0.0]")
                              .replace("root: [0.0, 0.0, 0.0]", "root: [1.0, 0.0, 0.0]"),
                              ":members.beam: nodes 'root' and 'tip' are 1e-100 m apart; a member needs at least "
                              "1e-09 m (1e-9 of its nodes' distance from the origin, 1e-12 m at least)"),
}


# Runs the command and writes "returncode wall_s cpu_s maxrss_kB" of it to argv[1]. A small
# launcher between pytest and flexmb: Linux carries a process's peak RSS across fork and exec, so a
# child forked straight from a big pytest process would report pytest's own size.
LAUNCHER = """
import os, subprocess, sys, time
t0 = time.perf_counter()
p = subprocess.Popen(sys.argv[2:])
_, status, ru = os.wait4(p.pid, 0)
p.returncode = os.waitstatus_to_exitcode(status)
with open(sys.argv[1], "w") as f:
    f.write(f"{p.returncode} {time.perf_counter() - t0} {ru.ru_utime + ru.ru_stime} {ru.ru_maxrss}")
"""


def run_check(path: Path, *flags: str) -> tuple[int, str, float, float, float]:
    """(exit code, stdout + stderr, wall s, CPU s, peak RSS MB) of ``flexmb check PATH`` — the
    child's own wall and CPU time and peak RSS (``os.wait4`` in a small launcher)."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", NUMBA_CACHE_DIR=str(ROOT / ".cache" / "numba"))
    env.pop("FLEXMB_DEBUG", None)
    with tempfile.TemporaryDirectory() as d:
        stats = Path(d) / "stats"
        try:
            p = subprocess.run([sys.executable, "-c", LAUNCHER, str(stats), str(FLEXMB), "check", str(path), *flags],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, cwd=ROOT, timeout=60)
        except subprocess.TimeoutExpired:
            pytest.fail(f"flexmb check {path.name} gave no answer within 60 s")
        code, wall, cpu, rss_kb = stats.read_text().split()
    assert p.returncode == 0, p.stdout[-2000:]
    return int(code), p.stdout.decode("utf-8", "replace"), float(wall), float(cpu), int(rss_kb) / 1024.0


def write_case(tmp_path: Path, name: str, content) -> Path:
    path = tmp_path / f"{name}.yaml"
    if content is None:
        return path                                     # missing file
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8")
    else:
        path.write_bytes(content)
    return path


@pytest.mark.skipif(not FLEXMB.exists(), reason="needs the .venv/bin/flexmb entry point")
@pytest.mark.parametrize("name", [k for k, (_, text) in CASES.items() if text is not None])
def test_malformed_scene_is_refused_clearly_fast_and_bounded(tmp_path, name):
    content, expected = CASES[name]
    path = write_case(tmp_path, name, content)
    code, out, wall, cpu, rss = run_check(path)
    assert code == 1, out[:2000]
    assert out.startswith(f"flexmb check: scene error: {path}"), out[:2000]
    # The column of a nesting refusal depends on the parser: libyaml >= 0.2.6 scans ~1000 brackets ahead.
    found = expected.search(out) if isinstance(expected, re.Pattern) else expected in out
    assert found, out[:2000]
    assert "Traceback" not in out
    assert len(out.encode()) < MESSAGE_BYTES, f"{len(out.encode())} bytes: {out[:300]}"
    assert cpu < WALL_S, f"{cpu:.2f} s CPU"
    assert wall < WALL_LOADED_S, f"{wall:.2f} s wall ({cpu:.2f} s CPU)"
    assert rss < RSS_MB, f"{rss:.0f} MB"


@pytest.mark.skipif(not FLEXMB.exists(), reason="needs the .venv/bin/flexmb entry point")
def test_unused_nodes_are_bounded(tmp_path):
    """200 000 unused nodes: the message counts them and lists a few (it listed all, 2 MB)."""
    path = write_case(tmp_path, "unused", _unused_nodes(200_000))
    code, out, wall, cpu, rss = run_check(path, "--max-yaml-nodes", "2000000", "--max-dofs", "10000000")
    assert code == 1, out[:2000]
    assert (f"{path}:nodes: node(s) ['spare', 'spare0', 'spare1', 'spare2', 'spare3', 'spare4', 'spare5', "
            "'spare6', … and 199 993 more] are not used by any member or shell (200 001 in all)" in out), out[:2000]
    assert len(out.encode()) < MESSAGE_BYTES
    # 400 000 YAML values with raised limits: seconds of parsing (the user asked for it); the
    # message is what this case tests, time and memory are only held to loose bounds
    assert cpu < 20.0 and rss < RSS_MB, (wall, cpu, rss)


@pytest.mark.skipif(not FLEXMB.exists(), reason="needs the .venv/bin/flexmb entry point")
def test_raised_limits_let_a_big_scene_through_to_the_next_check(tmp_path):
    """--max-elements raises the element limit; the DOF limit then speaks, naming its own flag."""
    path = write_case(tmp_path, "big", _aliased_members(10, 10000))
    code, out, *_ = run_check(path, "--max-elements", "200000", "--max-dofs", "1000")
    assert code == 1 and "number of DOFs: 2 " in out and "--max-dofs N" in out, out


@pytest.mark.skipif(not FLEXMB.exists(), reason="needs the .venv/bin/flexmb entry point")
def test_file_size_limit(tmp_path):
    path = write_case(tmp_path, "big_file", BASE + "#" * 3000 + "\n")
    code, out, *_ = run_check(path, "--max-file-bytes", "1000")
    assert code == 1 and "scene file size in bytes:" in out and "--max-file-bytes N" in out, out


def test_merge_keys_are_not_duplicates():
    """``<<: *base`` then an explicit key overrides the merged one: YAML's rule, not a duplicate."""
    from flexmb_core.scene.loader import parse_yaml

    data = parse_yaml("base: &b {E: 1.0, rho: 2.0}\nsteel: {<<: *b, E: 3.0}\n")
    assert data["steel"] == {"E": 3.0, "rho": 2.0}


def test_stray_compile_error_is_one_clean_line(tmp_path, monkeypatch, capsys):
    """A ValueError escaping compile (a bug's symptom) is reported as a scene error, not a traceback."""
    from flexmb_core import cli
    from flexmb_core.model import compile as compile_mod

    def broken(scene, limits=None):
        raise ValueError("boom " + "x" * 10_000)

    monkeypatch.setattr(compile_mod, "compile_scene", broken)
    monkeypatch.delenv("FLEXMB_DEBUG", raising=False)
    path = write_case(tmp_path, "ok", BASE)
    assert cli.main(["check", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"flexmb check: scene error: {path}: the scene could not be compiled: ValueError: boom")
    assert "FLEXMB_DEBUG=1" in err and len(err) < 600


def test_excerpt_is_bounded_for_shared_and_recursive_values():
    from flexmb_core.errors import excerpt, name_list

    bomb = [1.0] * 9
    for _ in range(40):                                   # 9⁴¹ values if expanded
        bomb = [bomb] * 9
    loop: list = []
    loop.append(loop)
    t0 = time.perf_counter()
    texts = [excerpt(bomb), excerpt(loop), excerpt("x" * 10**7), excerpt(10**100_000), excerpt(list(range(10**6)))]
    assert time.perf_counter() - t0 < 0.1
    assert all(len(t) <= 80 for t in texts), texts
    assert texts[0].startswith("list of 9 items [[[[")
    assert texts[3] == "<int of 332 193 bits>"
    assert texts[4].startswith("list of 1 000 000 items [0, 1, 2,")
    assert name_list([f"n{i}" for i in range(12)]) == "['n0', 'n1', 'n2', 'n3', 'n4', 'n5', 'n6', 'n7', … and 4 more]"
    assert name_list(["a"]) == "['a']" and excerpt([1.0, 0.0]) == "[1.0, 0.0]"


if __name__ == "__main__":                               # print the table of the report
    with tempfile.TemporaryDirectory() as d:
        for name, (content, _) in CASES.items():
            p = write_case(Path(d), name, content)
            code, out, wall, cpu, rss = run_check(p)
            first = out.strip().splitlines()[0] if out.strip() else ""
            print(f"| {name} | {code} | {wall:.2f} | {cpu:.2f} | {rss:.0f} | {len(out.encode())} | "
                  f"{first.replace(d + '/', '')[:160]} |")
    sys.exit(0)
