"""The numba Newton of statics (flexmb_core.integrators.static_step), the one Newton of statics,
against the step references of ``tests/step_cases.py`` (recorded when it and the Python loop it
replaced were bit-identical): frames with moment loads and driven supports, multipliers, shells,
refused roots and bisected load increments, accept_flagged. The comparison is the one of
``test_fast_step.py`` (the right-angle cantilever's corner once went to SuperLU: see there)."""

import pytest

import step_cases as sc


def test_moments_and_a_driven_support_equal_their_reference():
    rows = sc.check_against_reference("static_moments_driven")
    assert all(r.converged for r in rows) and rows[-1].iterations > 1


@pytest.mark.parametrize("policy", ["substep", "accept_flagged"])
def test_bisected_and_flagged_increments_equal_their_references(policy):
    """One increment for a load that needs several: no convergence in 12 iterations, then the
    increment is split in 4 (substep), or kept and flagged (accept_flagged)."""
    rows = sc.check_against_reference(f"static_bisected_{policy}")
    if policy == "substep":
        assert rows[-1].substeps > 1 and rows[-1].converged
    else:
        assert not rows[-1].converged


@pytest.mark.parametrize("name", [n for n in sc.STATIC if n.startswith("static_shell")])
def test_shipped_shell_scenes_equal_their_references(name):
    sc.check_against_reference(name)


def test_rigid_corners_equal_their_reference():
    sc.check_against_reference("static_right_angle_cantilever")
    sim = sc.STATIC["static_right_angle_cantilever"]()
    sc.run_static(sim)
    assert sim.state.mult.any()           # the corner's multipliers carry moments
