"""Programmatic scenes for tests (dicts that go through the same strict loader as YAML files)."""

from __future__ import annotations

import copy

from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import scene_from_dict
from flexmb_core.simulator import Simulator


def cantilever(*, length=1.0, elements=8, order=3, section=None, E=200e9, nu=0.0, rho=7850.0,
               G=None, forces=None, moments=None, solver=None, damping=0.0, arc_center=None,
               tip=None, up=None, section_extra=None):
    """A straight (or arc) frame clamped at ``root``, free at ``tip``."""
    mat = {"E": E, "nu": nu, "rho": rho}
    if G is not None:
        mat["G"] = G
    sec = dict(section or {"shape": "rectangle", "width": 0.01, "height": 0.02})
    sec.update(section_extra or {})
    member = {"kind": "frame", "from": "root", "to": "tip", "elements": elements, "order": order,
              "material": "m", "section": "s"}
    if arc_center is not None:
        member["arc"] = {"center": list(arc_center)}
    if up is not None:
        member["up"] = list(up)
    d = {
        "name": "test_cantilever",
        "materials": {"m": mat},
        "sections": {"s": sec},
        "nodes": {"root": [0.0, 0.0, 0.0], "tip": list(tip or [length, 0.0, 0.0])},
        "members": {"beam": member},
        "supports": [{"node": "root", "type": "clamp"}],
        "loads": {},
        "damping": {"mass_proportional": damping},
        "solver": dict(solver or {"analysis": "static"}),
        "outputs": {"tip": {"kind": "node_position", "node": "tip"}},
    }
    if forces:
        d["loads"]["forces"] = forces
    if moments:
        d["loads"]["moments"] = moments
    return d


def build(d, **solver_overrides):
    """Scene dict → (model, simulator)."""
    d = copy.deepcopy(d)
    d.setdefault("solver", {}).update(solver_overrides)
    model = compile_scene(scene_from_dict(d, source="<test>"))
    return model, Simulator(model)
