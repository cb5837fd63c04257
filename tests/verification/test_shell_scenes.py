"""Curved-shell problems posed as plain scene files (issue 16): the pinched hemisphere with an 18°
hole, the pinched cylinder (an octant, and the whole closed tube) and the open cylinder pulled out,
written with the spherical_cap / closed cylinder generators, symmetry and roller supports, mesh
points and ``include:`` with overrides (the coarser meshes include the shipped scene).

Each converges under mesh refinement towards its own finest mesh here; the published reference
values are kept out of the project (they stay an independent check)."""

import math
from pathlib import Path

import numpy as np
import pytest

from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene
from flexmb_core.simulator import Simulator

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"
DATA = ROOT / "tests" / "data" / "scenes"


def _solve(path: Path):
    """Run a static scene file to its end; (model, outputs)."""
    model = compile_scene(load_scene(path))
    sim = Simulator(model)
    sim.initialize()
    sim.run(sim.spec.until)
    assert sim.last.converged, path.name
    return model, sim.outputs()


def _refines(values: list[float], min_ratio: float) -> None:
    """Errors against the last (finest) value: each at least ``min_ratio`` times smaller than the
    one before, and the values approach it from one side (monotone)."""
    ref = values[-1]
    err = [abs(v - ref) for v in values[:-1]]
    assert all(e > 0 for e in err), values
    for coarse, fine in zip(err, err[1:]):
        assert coarse / fine >= min_ratio, (values, err)
    steps = np.diff(values)
    assert np.all(steps > 0) or np.all(steps < 0), values


def test_pinched_hemisphere_with_a_hole_converges_under_refinement():
    ua, ub = [], []
    for n in (4, 6, 8):
        _, out = _solve(DATA / f"shell_pinched_hemisphere_{n}.yaml")
        a, b = np.array(out["A"]), np.array(out["B"])
        assert a[1] == 0.0 and a[2] == 0.0           # the symmetry edge (y) and the roller (z) hold at A
        assert b[0] == 0.0                            # the symmetry edge x = 0 holds at B
        ua.append(a[0])
        ub.append(-b[1])
    # measured (×1e-3, loads 0.01), with the assumed strains: A 0.9316, 0.9369, 0.9364 — the steps shrink
    # from 5.3e-6 m to 5.5e-7 m (ratio 9.7); before them (issue 16) 0.5018, 0.8404, 0.9075 (a locked 4×4).
    # Against the 32×32 value: tests/verification/test_shell_locking.py
    for u in (ua, ub):
        assert abs(u[2] - u[1]) * 5.0 <= abs(u[1] - u[0]), u
    # the loads are antisymmetric under a quarter turn: in the linear range |u_A| = |u_B| up to the
    # mesh's diagonals (measured 1.1e-4)
    assert ua[-1] == pytest.approx(ub[-1], rel=1e-3)
    assert ua[-1] > 0.0                               # the pulled point moves out, the pushed one in


def test_pinched_cylinder_octant_converges_under_refinement():
    w = []
    for path in (DATA / "shell_pinched_cylinder_4.yaml", DATA / "shell_pinched_cylinder_6.yaml",
                 SCENES / "shell_pinched_cylinder.yaml"):
        _, out = _solve(path)
        c = np.array(out["C"])
        assert c[0] == 0.0 and c[1] == 0.0            # on the symmetry planes x = L/2 and y = 0
        w.append(-c[2])
    # measured (×1e-5), with the assumed strains: 1.564, 1.714, 1.780 — errors 0.216, 0.066 against 8×8
    # (ratio 3.3; R/t = 100); before them (issue 16) 0.951, 1.47, 1.67
    _refines(w, 2.5)
    assert w[-1] > 0.0


def test_closed_tube_matches_the_octant_and_its_seam_is_joined():
    """The whole tube as one closed mesh (seam joined) gives the octant's answer at the same mesh
    density; the same tube with the seam a hinge line is softer, left slit softer still."""
    _, octant = _solve(DATA / "shell_pinched_cylinder_2.yaml")              # 2 × 2 per octant
    model, closed = _solve(DATA / "shell_pinched_cylinder_closed_4x8.yaml")  # 4 × 8 on the whole tube
    w_octant, w_closed = -octant["C"][2], -closed["C"][2]
    # measured 1.5e-2 (8e-4 with the assumed-strain weights 0): on 2 × 2 cells per octant (45° per element)
    # the assumed strains make the answer depend on the diagonals' directions, and the tube's quarters are
    # the octant's mirror images
    assert w_closed == pytest.approx(w_octant, rel=2.5e-2)
    assert closed["D"][2] == pytest.approx(w_closed, rel=1e-6)               # the two pinches agree
    info = model.shell("tube")
    assert "start" not in info.edges and len(np.unique(info.nodes)) == info.nodes.size
    assert np.linalg.norm(info.x0[:, None] - info.x0[None], axis=2)[np.triu_indices(info.nodes.size, 1)].min() > 1.0

    hmodel, hinged = _solve(DATA / "shell_pinched_cylinder_hinged_seam.yaml")
    _, slit = _solve(DATA / "shell_pinched_cylinder_slit.yaml")
    w_hinged, w_slit = -hinged["C"][2], -slit["C"][2]
    assert w_closed < w_hinged < w_slit, (w_closed, w_hinged, w_slit)
    tube = hmodel.shell("tube")
    start, end = tube.edges["start"], tube.edges["end"]
    assert np.array_equal(tube.ydofs[start], tube.ydofs[end])               # the hinge shares positions
    assert not np.intersect1d(tube.gdofs[start], tube.gdofs[end]).size      # ... and no director


def test_open_cylinder_pulled_out_converges_under_refinement():
    ua, ub, uc = [], [], []
    for n in (2, 4, 6):
        _, out = _solve(DATA / f"shell_pulled_cylinder_{n}.yaml")
        ua.append(out["A"][2])
        ub.append(out["D"][2])
        uc.append(-out["C"][1])
    # measured (×1e-3, P/4 = 1), with the assumed strains: A 4.386, 4.507, 4.534 — errors 0.148, 0.026 against
    # 6×6 (ratio 5.6); D (the free end above A) 4.2998, 4.3114, 4.3171 (ratio 3.0, 2×2 already within 0.4 %);
    # before them (issue 16)
    # A 3.183, 4.364, 4.507
    _refines(ua, 2.5)
    _refines(ub, 2.5)
    _refines(uc, 2.5)
    assert ua[-1] > ub[-1] > 0.0 and uc[-1] > 0.0     # pulled out, the free end follows, the side pulls in



def test_open_cylinder_pulled_out_far_snaps_and_is_traced_through_it():
    """The pull-out at large deflection (P up to 40 000, the octant carrying P/4), traced by arc length
    on 4 × 4 cells: the free end's section snaps near P/P_max = 0.48 — a load maximum, then a load
    minimum, reported as limit points — and the path carries on to P_max, where the pulled point has
    moved out by about half the radius while the mid-plane's side has come in by almost the radius."""
    from flexmb_core.integrators.path_following import PathFollower
    from flexmb_core.scene import scene_from_dict
    from flexmb_core.scene.loader import parse_yaml

    path = SCENES / "shell_pulled_cylinder.yaml"
    data = parse_yaml(path.read_text(), str(path))
    data["shells"]["tube"]["mesh"]["divisions"] = [4, 4]
    data["loads"]["forces"]["pull"]["force"] = [0.0, 0.0, 10000.0]
    data["solver"] = {"analysis": "static", "control": "arc_length",
                      "arc_length": {"initial": 0.05, "max": 1.0, "target_iterations": 5},
                      "monitor": {"node": "tube.A", "component": "z"}, "until_load_factor": 1.0, "max_steps": 200}
    model = compile_scene(scene_from_dict(data, source=str(path)))
    sim = Simulator(model)
    pf = PathFollower(sim)
    pf.initialize()
    pf.run()
    rep = pf.report()
    kinds = [c["kind"] for c in rep["limit_points"]]
    assert kinds == ["load_maximum", "load_minimum"], rep["limit_points"]
    top, bottom = rep["limit_points"]
    # measured: λ 0.4791 at w_A 2.375, then 0.4714 at 2.387 (8 × 8 cells: 0.5125, 0.5115)
    assert 0.40 < bottom["load_factor"] < top["load_factor"] < 0.55, rep["limit_points"]
    assert rep["load_factor"] >= 1.0 and rep["finished"] == "load factor reached 1"
    lam = np.array(rep["path"]["load_factor"])
    w_a = np.array(rep["path"]["displacement"])
    assert np.all(np.diff(w_a) > 0.0)               # the pulled point moves out all the way
    grid = model.node_ydofs
    u_b = sim.state.q[grid[model.node("tube.B"), 1]] - model.q0[grid[model.node("tube.B"), 1]]
    # measured at λ = 1.076: w_A 2.664, −u_B 4.376 (8 × 8 at λ = 1.053: 2.727, 4.517)
    assert 0.5 < w_a[-1] / 4.953 < 0.6 and 0.85 < -u_b / 4.953 < 0.95, (lam[-1], w_a[-1], u_b)

def test_spherical_cap_closed_at_the_pole_covers_the_sphere_exactly():
    """A cap closed at the pole (a fan of triangles there) and a full turn (closed seam): every node
    on the sphere, outward unit normals, total area 2πR²(1 − cos α1) to the cubic geometry's accuracy."""
    from flexmb_core.model.shell_geometry import shell_element_geometry, shell_rule
    from flexmb_core.model.shell_mesh import spherical_cap

    radius, alpha1 = 2.0, 1.2
    mesh = spherical_cap([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], radius, (0.0, alpha1),
                         (0.0, 2.0 * math.pi), (4, 12), closed=True)
    assert np.allclose(np.linalg.norm(mesh.x, axis=1), radius, rtol=1e-14)
    assert np.allclose(mesh.normal, mesh.x / radius, atol=1e-14)
    assert set(mesh.edges) == {"rim"} and mesh.edges["rim"][0] == mesh.edges["rim"][-1]
    assert np.unique(mesh.tri).size == mesh.x.shape[0]               # no orphan grid points
    rule = shell_rule(4, 3)
    h = 1e-3
    area = sum(shell_element_geometry(mesh.x[t], mesh.normal[t], h / 2, *rule, "cap")[1].sum() / h
               for t in mesh.tri)
    assert area == pytest.approx(2.0 * math.pi * radius ** 2 * (1.0 - math.cos(alpha1)), rel=1e-4)


def test_cap_closed_at_the_pole_quarter_and_whole_agree():
    """A clamped spherical cap closed at its pole (the fan of triangles there) under a pole load: the
    quarter with two symmetry edges meeting at the pole and the whole cap (closed around, no
    symmetry) give the same displacements at the same mesh density."""
    _, quarter = _solve(DATA / "shell_cap_pole_load.yaml")              # 4 × 4 cells
    _, whole = _solve(DATA / "shell_cap_pole_load_full.yaml")           # 4 × 16 cells
    for key in ("pole", "mid"):
        q, w = np.array(quarter[key]["displacement"]), np.array(whole[key]["displacement"])
        # measured 1e-9, 9e-5 (3e-6 before the assumed strains: their projection sees the two meshes' different
        # diagonals)
        assert np.linalg.norm(w - q) <= 3e-4 * np.linalg.norm(q), (key, q, w)
    assert quarter["pole"]["displacement"][2] < 0.0
