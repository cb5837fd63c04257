"""ament_python build of the flexmb twin for colcon (``colcon build`` in a ROS 2 workspace).

The Python sources are the repository's own ``flexmb_core``, ``flexmb_io``, ``ros2_node`` and ``flexmb``
(the CLI), symlinked into this
directory (so ``colcon build --symlink-install``, i.e. ``setup.py develop``, works too);
``pip install -e .`` at the repository root (``pyproject.toml``) installs the same packages for a
venv. This file only adds what ``ros2 run`` and ``ros2 launch`` need:

- executables in ``lib/flexmb/`` (``setup.cfg``): ``flexmb_node`` (the twin), ``flexmb_player``
  (the command player) and ``flexmb`` (the whole CLI);
- ``share/ament_index/resource_index/packages/flexmb`` (the package marker), ``share/flexmb/
  package.xml``, the launch files in ``share/flexmb/launch`` and the shipped scenes in
  ``share/flexmb/scenes``.

Dependencies are declared in ``package.xml`` (rosdep keys), as ament_python packages do; colcon
installs none from here.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "flexmb"
HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
PY_PACKAGES = ("flexmb_core", "flexmb_io", "ros2_node", "flexmb")


def _version() -> str:
    # pyproject.toml's [project] version (no tomllib: ROS 2 Humble's Python is 3.10)
    match = re.search(r'^version\s*=\s*"([^"]+)"', (REPO / "pyproject.toml").read_text(), re.M)
    if match is None:
        raise SystemExit(f"{REPO / 'pyproject.toml'}: no [project] version = \"...\" line")
    return match.group(1)


def _package_data() -> dict[str, list[str]]:
    # non-Python files inside the packages (e.g. py.typed)
    data = {}
    for top in PY_PACKAGES:
        files = [p.relative_to(REPO / top).as_posix() for p in (REPO / top).rglob("*")
                 if p.is_file() and p.suffix not in (".py", ".pyc") and "__pycache__" not in p.parts]
        if files:
            data[top] = sorted(files)
    return data


def _relative(paths) -> list[str]:
    # setuptools wants relative paths, resolved from the working directory: colcon runs this file in
    # the source directory, or (--symlink-install) as a symlink in its build directory
    return sorted(os.path.relpath(p) for p in paths)


setup(
    name=PACKAGE,
    version=_version(),
    description="flexmb: a real-time flexible digital twin of actuated spatial mechanisms as a ROS 2 node",
    license="Apache-2.0",
    # the packages here are symlinks to the repository's packages (setuptools' develop,
    # i.e. colcon --symlink-install, refuses packages outside the setup directory)
    packages=find_packages(where=str(HERE), include=[q for p in PY_PACKAGES for q in (p, f"{p}.*")]),
    package_data=_package_data(),
    data_files=[
        ("share/ament_index/resource_index/packages", _relative([HERE / "resource" / PACKAGE])),
        (f"share/{PACKAGE}", _relative([HERE / "package.xml"])),
        (f"share/{PACKAGE}/launch", _relative(HERE.glob("launch/*.launch.py"))),
        (f"share/{PACKAGE}/scenes", _relative(REPO.glob("scenes/*.yaml"))),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    entry_points={
        "console_scripts": [
            "flexmb_node = flexmb.ros_entry:node_main",
            "flexmb_player = flexmb.ros_entry:player_main",
            "flexmb = flexmb.cli:main",
        ],
    },
)
