"""The packages form layers by dependency; each imports only the layers before it.

``flexmb_core`` (numerics) ← ``flexmb_io`` (recordings, rerun, the twin runner; no rclpy) ←
``ros2_node`` (rclpy) ← ``flexmb`` (the command line). Read from the sources with :mod:`ast`, so an
import inside a function counts as much as one at the top. Optional dependencies (rclpy and the ROS
interface packages, rerun, mcap, rosbags) may only be imported inside functions: a module-level
import would make ``flexmb run`` or ``flexmb --help`` need them. A subprocess then builds the whole
command line with those dependencies unimportable.
"""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LAYERS = ("flexmb_core", "flexmb_io", "ros2_node", "flexmb")
THIRD_PARTY_OPTIONAL = {"rclpy", "rcl_interfaces", "lifecycle_msgs", "rerun", "rerun_cli", "mcap", "mcap_ros2",
                        "rosbags"}
ROS_INTERFACE = re.compile(r"^[a-z0-9_]+_(msgs|srvs|interfaces)$")       # e.g. sensor_msgs, std_srvs
# top-level modules each layer must never import
FORBIDDEN = {
    "flexmb_core": {"rclpy", "rcl_interfaces", "rerun", "rerun_cli", "mcap", "mcap_ros2", "rosbags", "benchmarks",
                    "flexmb_io", "ros2_node", "flexmb"},
    "flexmb_io": {"rclpy", "rcl_interfaces", "ros2_node", "flexmb", "benchmarks"},
    "ros2_node": {"flexmb", "benchmarks"},
}


def _imports(path: Path) -> list[tuple[str, int, bool]]:
    """(absolute top-level module, line, at module level) of every import in ``path``; relative
    imports stay inside their own package and are skipped."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    out = []

    def visit(node: ast.AST, top: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.Import):
                out.extend((a.name.split(".")[0], child.lineno, top) for a in child.names)
            elif isinstance(child, ast.ImportFrom) and child.level == 0 and child.module:
                out.append((child.module.split(".")[0], child.lineno, top))
            inner = top and not isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            visit(child, inner)

    visit(tree, True)
    return out


def _sources(package: str) -> list[Path]:
    files = sorted((ROOT / package).rglob("*.py"))
    assert files, f"no Python files under {ROOT / package}"
    return files


def _where(path: Path, line: int) -> str:
    return f"{path.relative_to(ROOT)}:{line}"


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_a_layer_imports_no_later_layer_and_not_what_it_must_not_need(package):
    bad = [f"{_where(p, line)} imports {mod}" for p in _sources(package) for mod, line, _ in _imports(p)
           if mod in FORBIDDEN[package] or (package != "ros2_node" and ROS_INTERFACE.match(mod))]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("package", LAYERS)
def test_optional_dependencies_are_imported_inside_functions(package):
    bad = [f"{_where(p, line)} imports {mod} at module level" for p in _sources(package)
           for mod, line, top in _imports(p) if top and (mod in THIRD_PARTY_OPTIONAL or ROS_INTERFACE.match(mod))]
    assert not bad, "\n".join(bad)


def test_the_checker_sees_imports_inside_functions_and_from_imports(tmp_path):
    src = tmp_path / "m.py"
    src.write_text("import os\nfrom rerun import x\n\ndef f():\n    import rclpy.node\n    from . import y\n")
    assert _imports(src) == [("os", 1, True), ("rerun", 2, True), ("rclpy", 5, False)]


def test_the_command_line_builds_without_ros_rerun_or_mcap():
    # every verb registers (bench from the source checkout) with the optional dependencies unimportable,
    # and none of them is loaded by it
    blocked = sorted(THIRD_PARTY_OPTIONAL | {"std_msgs", "sensor_msgs", "flexmb_msgs", "tf2_msgs"})
    code = (
        "import sys\n"
        f"BLOCKED = {blocked!r}\n"
        "class Block:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] in BLOCKED:\n"
        "            raise ModuleNotFoundError(f'blocked: {name}', name=name)\n"
        "sys.meta_path.insert(0, Block())\n"
        "from flexmb.cli import build_parser\n"
        "p = build_parser()\n"
        "print(sorted(p.verbs.choices))\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & set(BLOCKED)))\n"
    )
    env = dict(os.environ, NUMBA_CACHE_DIR=os.environ.get("NUMBA_CACHE_DIR", str(ROOT / ".cache" / "numba")))
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    verbs, loaded = proc.stdout.splitlines()[-2:]
    for verb in ("check", "run", "bench", "node", "play", "replay", "bag", "calibrate", "view"):
        assert f"'{verb}'" in verbs, verbs
    assert loaded == "[]", loaded


def test_bench_says_where_it_lives_when_benchmarks_is_absent(monkeypatch, tmp_path, capsys):
    from flexmb import cli

    monkeypatch.setattr(cli, "BENCH_CLI", tmp_path / "benchmarks" / "workprecision" / "cli.py")
    monkeypatch.setattr(cli, "ROOT", tmp_path)
    assert cli.main(["bench", "--case", "b1", "--quick"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("flexmb bench: needs a source checkout: benchmarks/workprecision/cli.py was not found in ")
    assert str(tmp_path) in err and "\n" not in err
