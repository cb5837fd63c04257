"""Stand-ins for ROS 2's ``launch`` / ``launch_ros`` (not on PyPI), to run a launch file's Python here.

:func:`load_launch_file` imports a ``*.launch.py`` with these stand-ins in ``sys.modules`` (only
while it imports: the real packages, where installed, are untouched). Each stand-in accepts only the
keyword arguments the real class accepts for what flexmb's launch file uses, so a misspelt keyword
fails here as it would in ``ros2 launch``; it records what it was given for the test to inspect.
:func:`evaluate` runs the description's ``OpaqueFunction`` with given launch arguments and returns
the actions it makes. :func:`node_command` is the command line ``launch_ros`` runs for a ``Node``.
"""

from __future__ import annotations

import importlib.util
import sys
import types
from pathlib import Path

import yaml

# keyword arguments of the real classes (launch / launch_ros, Humble … Kilted) that flexmb may use
_NODE_KW = {"package", "executable", "name", "namespace", "exec_name", "parameters", "remappings",
            "ros_arguments", "arguments", "output", "emulate_tty", "respawn", "respawn_delay", "condition",
            "additional_env", "env", "cwd", "prefix", "sigterm_timeout", "sigkill_timeout", "on_exit"}
_KWARGS = {
    "DeclareLaunchArgument": {"default_value", "description", "choices", "condition"},
    "OpaqueFunction": {"function", "args", "kwargs"},
    "RegisterEventHandler": {"event_handler", "condition"},
    "EmitEvent": {"event", "condition"},
    "OnProcessExit": {"target_action", "on_exit"},
    "Shutdown": {"reason"},
    "Node": _NODE_KW,
}


class _Recorded:
    """A stand-in action: its positional and keyword arguments, checked against the real signature."""

    kind = ""

    def __init__(self, *args, **kwargs):
        unknown = set(kwargs) - _KWARGS[self.kind]
        if unknown:
            raise TypeError(f"{self.kind}() got unexpected keyword arguments {sorted(unknown)}")
        self.args, self.kwargs = args, kwargs

    def __repr__(self) -> str:
        return f"{self.kind}({self.args}, {self.kwargs})"


def _recorded(kind: str) -> type:
    return type(kind, (_Recorded,), {"kind": kind})


class LaunchConfiguration:
    def __init__(self, variable_name: str, default=None):
        self.name, self.default = variable_name, default

    def perform(self, context) -> str:
        value = context.launch_configurations.get(self.name, self.default)
        if value is None:
            raise KeyError(f"launch configuration '{self.name}' is not set")
        return value


class LaunchDescription:
    def __init__(self, initial_entities=None):
        self.entities = list(initial_entities or [])


class Context:
    """What an OpaqueFunction's body receives: the launch arguments, as strings."""

    def __init__(self, launch_configurations: dict[str, str]):
        self.launch_configurations = dict(launch_configurations)


def _modules() -> dict[str, types.ModuleType]:
    mods = {name: types.ModuleType(name) for name in (
        "launch", "launch.actions", "launch.event_handlers", "launch.events", "launch.substitutions",
        "launch_ros", "launch_ros.actions")}
    mods["launch"].LaunchDescription = LaunchDescription
    for name in ("DeclareLaunchArgument", "OpaqueFunction", "RegisterEventHandler", "EmitEvent"):
        setattr(mods["launch.actions"], name, _recorded(name))
    mods["launch.event_handlers"].OnProcessExit = _recorded("OnProcessExit")
    mods["launch.events"].Shutdown = _recorded("Shutdown")
    mods["launch.substitutions"].LaunchConfiguration = LaunchConfiguration
    mods["launch_ros.actions"].Node = _recorded("Node")
    for full, mod in mods.items():
        if "." in full:
            parent, child = full.rsplit(".", 1)
            setattr(mods[parent], child, mod)
    return mods


def load_launch_file(path: Path) -> types.ModuleType:
    """The launch file as a module, imported against the stand-ins."""
    stand_ins = _modules()
    saved = {name: sys.modules.get(name) for name in stand_ins}
    sys.modules.update(stand_ins)
    try:
        spec = importlib.util.spec_from_file_location(f"launch_file_{path.stem.replace('.', '_')}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    finally:
        for name, old in saved.items():
            if old is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = old


def evaluate(module: types.ModuleType, **arguments: str) -> tuple[dict[str, str], list]:
    """(declared defaults, actions) of the launch description for ``name:=value`` arguments."""
    description = module.generate_launch_description()
    defaults = {e.args[0]: e.kwargs.get("default_value", "") for e in description.entities
                if e.kind == "DeclareLaunchArgument"}
    unknown = set(arguments) - set(defaults)
    if unknown:
        raise KeyError(f"not launch arguments of {module.__name__}: {sorted(unknown)}")
    context = Context({**defaults, **arguments})
    actions = []
    for e in description.entities:
        if e.kind == "OpaqueFunction":
            actions += e.kwargs["function"](context, *e.kwargs.get("args", ()), **e.kwargs.get("kwargs", {}))
        elif e.kind != "DeclareLaunchArgument":
            actions.append(e)
    return defaults, actions


def node_command(node: _Recorded, prefix: Path, params_file: Path) -> list[str]:
    """The command line launch_ros runs for ``node``: ``<prefix>/lib/<package>/<executable>``, its
    arguments, then ``--ros-args`` with the node name, namespace and a parameters file."""
    kw = node.kwargs
    cmd = [str(prefix / "lib" / kw["package"] / kw["executable"]), *kw.get("arguments", [])]
    ros = []
    if kw.get("name"):
        ros += ["-r", f"__node:={kw['name']}"]
    if kw.get("namespace"):
        ros += ["-r", f"__ns:=/{kw['namespace'].strip('/')}"]
    params = {}
    for p in kw.get("parameters", []):
        params.update(p)
    if params:
        params_file.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
        ros += ["--params-file", str(params_file)]
    return cmd + (["--ros-args", *ros] if ros else [])
