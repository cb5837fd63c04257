"""The benchmarks import only what the packages still define.

The benchmarks run outside `make test` (peers, minutes of wall time), so a name they import from
flexmb that a later change renamed or removed went unseen until someone ran them: the Exudyn
Stewart peer imported ``flexmb_core.observers.quaternion_wxyz`` for a day after it was gone. Every
``from flexmb_core|flexmb_io|ros2_node… import name`` in ``benchmarks/`` — at module level or inside
a function — must resolve to a module or an attribute.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
OURS = ("flexmb_core", "flexmb_io", "ros2_node")


def _imports_of_ours(path: Path) -> list[tuple[int, str, str]]:
    """(line, module, name) of every absolute ``from <ours>… import name`` in ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                and node.module.split(".")[0] in OURS:
            found += [(node.lineno, node.module, alias.name) for alias in node.names]
    return found


def _resolves(module: str, name: str) -> bool:
    mod = importlib.import_module(module)
    if name == "*" or hasattr(mod, name):
        return True
    try:
        importlib.import_module(f"{module}.{name}")
    except ModuleNotFoundError:
        return False
    return True


SCRIPTS = sorted(ROOT.glob("benchmarks/**/*.py"))


def test_the_benchmarks_are_found_and_import_from_flexmb():
    assert len(SCRIPTS) > 20, SCRIPTS
    assert sum(bool(_imports_of_ours(p)) for p in SCRIPTS) > 20


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_name_a_benchmark_imports_from_flexmb_exists(script):
    missing = [f"{script.relative_to(ROOT)}:{line}: from {module} import {name}"
               for line, module, name in _imports_of_ours(script) if not _resolves(module, name)]
    assert not missing, "\n".join(missing)
