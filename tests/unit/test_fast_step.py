"""The numba step (flexmb_core.integrators.fast), the one Newton of dynamics, against the step
references of ``tests/step_cases.py``: every step's result and the final state of the runs that the
numba step and the Python Newton it replaced gave bit for bit alike — held tangents, refused roots
and the sub-stepping that follows, actuator stretches and their rates, material damping, bars,
several frame groups, shells, multipliers, moment loads, driven supports and the Chung–Hulbert
form.

Where the arithmetic is unchanged the runs are still bit-identical. Four runs met a tangent that
the skyline LU used to hand to SuperLU (a pivot below 1e-10 · max |diag|, or a zero leading
minor) and that it now solves itself, with static pivoting and refinement: the Stewart twins with
frame legs (their static start), the tendon arm and the right-angle cantilever in statics. There the
results equal the references to round-off in the node positions and to the Newton tolerance
elsewhere; the generalized vectors of the frame legs differ by up to 5e-5, a turn of each
ball-jointed leg of circular section about its own axis, a mode without stiffness that the two
solvers resolve to different round-off.
"""

import pytest

import step_cases as sc
from flexmb_core.errors import SceneError
from flexmb_core.integrators.fast import NumbaStep

@pytest.mark.parametrize("name", [n for n in sc.DYNAMIC if n.startswith("b1_")])
def test_b1_variants_equal_their_references(name):
    """Modified and full Newton, Newmark, gravity, Chung–Hulbert, moment loads, a driven support."""
    sc.check_against_reference(name)


def test_refused_roots_and_sub_steps_equal_their_references():
    """The tumbling beam under the trapezoidal rule: failed attempts from step 43 on, a root
    refused by the step guard at step 126, sub-steps after each."""
    rows = sc.check_against_reference("tumbling_substeps")
    assert any(r.substeps > 1 for r in rows) and rows[125].guard == "inverted"


def test_failed_steps_accepted_and_flagged_equal_their_references():
    """accept_flagged keeps a failed attempt's last iterate."""
    rows = sc.check_against_reference("tumbling_accept_flagged")
    assert sum(not r.converged for r in rows) > 0


@pytest.mark.parametrize("name", [n for n in sc.DYNAMIC if n.startswith("scene_")])
def test_shipped_scenes_equal_their_references(name):
    sc.check_against_reference(name)


def test_chung_hulbert_with_multipliers_is_refused_when_the_simulator_is_built():
    from pathlib import Path

    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene import scene_from_dict
    from flexmb_core.scene.loader import parse_yaml
    from flexmb_core.simulator import Simulator

    path = Path(__file__).resolve().parents[2] / "scenes" / "right_angle_cantilever.yaml"
    data = parse_yaml(path.read_text(), str(path))
    data["solver"]["integrator"] = "chung_hulbert"
    model = compile_scene(scene_from_dict(data, source=str(path)))
    with pytest.raises(SceneError, match=r"right_angle_cantilever.yaml:solver: the dynamic step cannot run this "
                                         r"model: the chung_hulbert integrator does not support rigid corners"):
        Simulator(model)
    model, sim = sc.build(sc.b1(integrator="chung_hulbert"))
    assert NumbaStep.unsupported(model, sim.spec) == ""


def test_the_augmented_system_has_the_solution_of_the_constrained_one():
    """factor_packed's remedy for a zero pivot of a multiplier model: K + ρGᵀG in the free block
    and ρGᵀc added to the right-hand side give the very solution of [K Gᵀ; G 0] (the rigid corner
    of the right-angle cantilever, at a perturbed state with multipliers)."""
    import numpy as np
    import scipy.sparse as sp
    from numba import njit

    from flexmb_core.integrators.packs import augment
    from flexmb_core.model.assembly import assemble

    sim = sc.scene_sim("right_angle_cantilever")
    m, ws = sim.model, sim.ws
    rng = np.random.default_rng(3)
    q = m.q0.copy()
    q[m.free] += 1e-3 * rng.standard_normal(m.nfree)
    mult = rng.standard_normal(m.n_multipliers)
    assemble(m, ws, q, sim.state.lam, True, mult)
    plain = sp.csr_matrix((ws.kdata, m.indices, m.indptr), shape=(m.nsys, m.nsys)).toarray()
    kdata = ws.kdata.copy()
    packs = sim._dynamic.fast.packs
    # augment reads the packs through their views, which exist in numba code only
    rho = njit(lambda *a: augment(*a))(kdata, np.abs(np.diag(plain)).max(), packs.packs[3], packs.lay)
    augmented = sp.csr_matrix((kdata, m.indices, m.indptr), shape=(m.nsys, m.nsys)).toarray()
    nf = m.nfree
    g = plain[nf:, :nf]
    assert rho > 0.0
    np.testing.assert_allclose(augmented[:nf, :nf] - plain[:nf, :nf], rho * g.T @ g, rtol=1e-12,
                               atol=1e-12 * rho * np.abs(g).max() ** 2)
    assert np.array_equal(augmented[nf:], plain[nf:]) and np.array_equal(augmented[:, nf:], plain[:, nf:])
    b = rng.standard_normal(m.nsys)
    b_aug = b.copy()
    b_aug[:nf] += rho * g.T @ b[nf:]
    x, x_aug = np.linalg.solve(plain, b), np.linalg.solve(augmented, b_aug)
    assert np.abs(x_aug - x).max() <= 1e-9 * np.abs(x).max()
