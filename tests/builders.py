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


def extended_tangent_error(model, sim, q, mult, lam=None, h: float = 1e-6) -> float:
    """Largest entry of (system matrix − central finite difference of the system residual
    [f_int + Gᵀλ; c] in q and λ), relative to the matrix's largest entry."""
    import numpy as np
    import scipy.sparse as sp

    from flexmb_core.model.assembly import assemble
    ws = sim.ws
    lam = np.ones(0) if lam is None else lam

    def system_residual(qq, mm):
        assemble(model, ws, qq, lam, False, mm)
        return np.concatenate((ws.r[model.free], ws.rc))

    assemble(model, ws, q, lam, True, mult)
    k = sp.csr_matrix((ws.kdata.copy(), model.indices, model.indptr), shape=(model.nsys,) * 2).toarray()
    kfd = np.zeros_like(k)
    for j in range(model.nsys):
        qp, qm, mp, mm = q.copy(), q.copy(), mult.copy(), mult.copy()
        if j < model.nfree:
            qp[model.free[j]] += h
            qm[model.free[j]] -= h
        else:
            mp[j - model.nfree] += h
            mm[j - model.nfree] -= h
        kfd[:, j] = (system_residual(qp, mp) - system_residual(qm, mm)) / (2 * h)
    return float(np.abs(k - kfd).max() / np.abs(k).max())


def free_beam(eta: float = 0.0, **solver) -> dict:
    """A free steel beam (1 m, 20 × 40 mm, 4 cubic elements), no supports, no gravity: the hard
    cases' tumbling beam. ``solver`` entries go into the scene's solver block."""
    return {"name": "free_beam",
            "materials": {"steel": {"E": 2.0e11, "nu": 0.3, "rho": 7850.0, "eta": eta}},
            "sections": {"s": {"shape": "rectangle", "width": 0.02, "height": 0.04}},
            "nodes": {"a": [0.0, 0.0, 0.0], "b": [1.0, 0.0, 0.0]},
            "members": {"beam": {"kind": "frame", "from": "a", "to": "b", "elements": 4, "order": 3,
                                 "material": "steel", "section": "s", "up": [0, 0, 1]}},
            "supports": [], "loads": {},
            "solver": {"analysis": "dynamic", "until": 1.0, **solver},
            "outputs": {"e": {"kind": "energy"}}}
