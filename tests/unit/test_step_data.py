"""The run's one mutable object (flexmb_core.model.step_data.StepData): a copy and an assign of
it are the whole run state — a rollback restores the stretch history, the held tangent's
bookkeeping and the guard's ledger with the unknowns, so the steps after it repeat bit for bit —
and a tangent factored after the copy it restores is not reused."""

from pathlib import Path

import numpy as np
import pytest

from flexmb_core.model.compile import compile_scene
from flexmb_core.model.step_data import C_T_HIST, T_COUNT, T_HELD, BoundState, StepData
from flexmb_core.model.workspace import State
from flexmb_core.scene.loader import load_scene
from flexmb_core.simulator import Simulator

SCENES = Path(__file__).resolve().parents[2] / "scenes"


@pytest.fixture(scope="module")
def stewart_bars():
    """Damped bar legs driven by the appendix law: the stretch rate is a backward difference
    over the stretch history, and the guard's energy ledger runs."""
    return compile_scene(load_scene(SCENES / "stewart_platform_bars.yaml"))


def _run(sim, steps):
    """The states after each of ``steps`` steps, stacked (q, v, a, λ, λ̇)."""
    rows = []
    for _ in range(steps):
        sim.step()
        s = sim.state
        rows.append(np.concatenate((s.q, s.v, s.a, s.lam, s.lam_rate)))
    return np.array(rows)


def _started(model, steps):
    """A simulator warmed up, initialized and ``steps`` steps on."""
    sim = Simulator(model)
    sim.warmup()
    sim.initialize()
    _run(sim, steps)
    return sim


def test_the_state_is_a_view_of_the_buffer_and_its_copy_is_independent(stewart_bars):
    sim = Simulator(stewart_bars)
    assert isinstance(sim.state, BoundState) and sim.state is sim.data.state
    sim.state.t = 0.25
    assert sim.data.clock[0] == 0.25 and sim.state.t == 0.25
    sim.state.q[0] += 1.0
    assert sim.data.buf[sim.data.lay[1, 0]] == sim.state.q[0]
    plain = sim.state.copy()
    assert type(plain) is State
    plain.q[0] -= 1.0
    assert plain.q[0] != sim.state.q[0]


def test_a_rollback_of_the_data_repeats_the_steps_bit_for_bit(stewart_bars):
    sim = _started(stewart_bars, 40)
    saved = sim.data.copy()
    first = _run(sim, 30)
    sim.data.assign(saved)
    again = _run(sim, 30)
    assert np.array_equal(first, again)
    # the state alone is not the run state: restored without the stretch history (and the
    # ledger), the damped legs' rates come from a first-order difference and the steps differ
    history_time = saved.clock[C_T_HIST]
    sim.data.assign(saved)
    sim.data.clock[C_T_HIST] = np.nan
    assert sim.state.t == history_time
    assert not np.array_equal(first, _run(sim, 30))


def test_assign_drops_a_tangent_factored_after_the_copy(stewart_bars):
    sim = _started(stewart_bars, 5)
    saved = sim.data.copy()
    held_count = sim.data.tan[T_COUNT]
    integ = sim._dynamic
    integ._factored_coef = None                 # the next step refactors
    _run(sim, 1)
    count = sim.data.tan[T_COUNT]
    assert count == held_count + 1 and sim.data.tan[T_HELD] == 1.0
    sim.data.assign(saved)
    assert sim.data.tan[T_HELD] == 0.0           # the factors belong to a state the run has left
    assert sim.data.tan[T_COUNT] == count        # the count of factorizations never rolls back
    # a copy taken since the last factorization keeps the held tangent through a rollback
    _run(sim, 1)                                 # refactors (nothing held), then holds it
    assert sim.data.tan[T_HELD] == 1.0
    saved = sim.data.copy()
    sim.state.q[:] += 1e-3                       # anything the run did since, without refactoring
    sim.data.assign(saved)
    assert sim.data.tan[T_HELD] == 1.0 and np.array_equal(sim.data.buf, saved.buf)


def test_copies_own_no_factors(stewart_bars):
    data = StepData(stewart_bars)
    copy = data.copy()
    assert data.owns_factors and not copy.owns_factors
    data.tan[T_COUNT] = 7.0
    copy.assign(data)
    assert copy.tan[T_COUNT] == 7.0


def test_a_rollback_of_the_shell_twin_repeats_its_corotated_steps_bit_for_bit():
    """With shells the held tangent's solves turn by each shell's rotation since ``q_ref``, the
    state it was formed at: ``q_ref`` is in the data, so a rollback (here across 50 steps that
    reuse one tangent) repeats them exactly, and a wrong ``q_ref`` would not."""
    sim = _started(compile_scene(load_scene(SCENES / "stewart_platform_shell.yaml")), 620)
    saved = sim.data.copy()
    count = sim.data.tan[T_COUNT]
    first = _run(sim, 50)
    assert sim.data.tan[T_COUNT] == count and saved.q_ref.size == sim.state.q.size
    sim.data.assign(saved)
    assert sim.data.tan[T_HELD] == 1.0
    assert np.array_equal(first, _run(sim, 50))
    sim.data.assign(saved)
    sim.data.q_ref[:] = sim.state.q              # as if formed now: other rotations, other steps
    assert not np.array_equal(first, _run(sim, 50))
