"""The mass matrix in block form (``energy.mass_blocks``): ``M_s ⊗ I₃`` exactly where the model's
mass is that, the scalar CSR otherwise, and the products of the step the same bits either way."""

from pathlib import Path

import numpy as np
import pytest

from flexmb_core.integrators.energy import _energies, compact_csr, mass_blocks
from flexmb_core.integrators.fused import inertial_residual
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene import load_scene

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def _model(name):
    return compile_scene(load_scene(SCENES / f"{name}.yaml"))


def _products(model, mass, seed=0):
    """(rf, norms, ½vᵀMv) of the inertial residual and the energies for random state rows."""
    rng = np.random.default_rng(seed)
    n = model.ndof
    q, q_hat, at_n, a_n, v_n, r_int, f_ext = (rng.standard_normal(n) for _ in range(7))
    rf, g_out, w_buf = np.zeros(model.nsys), np.zeros(n), np.zeros(n)
    norms = inertial_residual(q, q_hat, at_n, a_n, v_n, 1e6, 0.1, 0.2, 0.6, 1e-3, 10.0, *mass, r_int, f_ext,
                              model.free_index, w_buf, rf, True, g_out)
    kin = _energies(*mass, v_n, q, model.q0, model.gravity_vector)
    return rf, g_out, norms, kin


@pytest.mark.parametrize("name, blocks", [("stewart_platform_1el_truss", 3), ("cantilever_b1", 3),
                                          ("right_angle_cantilever", 3), ("stewart_platform_shell", 1)])
def test_block_form_gives_the_scalar_products_bit_for_bit(name, blocks):
    model = _model(name)
    scalar = compact_csr(*model.mass_csr)
    mass = mass_blocks(*scalar)
    assert mass[0] == blocks
    if blocks == 3:     # M_s has a third of the rows and a ninth of the entries of the stored M ⊗ I₃
        assert mass[1].size - 1 == model.ndof // 3 and 3 * mass[3].size == scalar[2].size
    a, b = _products(model, mass), _products(model, (1, *scalar))
    for x, y in zip(a, b):
        assert np.array_equal(x, y)


def test_a_mass_that_is_not_a_kronecker_product_stays_scalar():
    model = _model("cantilever_b1")
    ptr, idx, val = compact_csr(*model.mass_csr)
    assert mass_blocks(ptr, idx, val)[0] == 3
    val = val.copy()
    val[4] *= 1.0 + 1e-15                  # one component's entry differs from its siblings'
    assert mass_blocks(ptr, idx, val)[0] == 1
    assert mass_blocks(ptr[:-1], idx[:ptr[-2]], val[:ptr[-2]])[0] == 1      # not a multiple of 3 rows
