"""Actuator servos (flexmb_core.servo): step response, limits, any Δt, rollback, strict schema."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from flexmb_core.errors import SceneError
from flexmb_core.model.compile import compile_scene
from flexmb_core.scene.loader import parse_yaml, scene_from_dict
from flexmb_core.servo import Servo, ServoParams, transition
from flexmb_io.twin import TwinRunner

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "stewart_platform_bars.yaml"


def _servo(f=10.0, zeta=0.5, vmax=1e9, amax=1e12, stroke=(0.0, 10.0), n=1) -> Servo:
    a = lambda x: np.full(n, float(x))   # noqa: E731
    return Servo(ServoParams(np.arange(n, dtype=np.int64), a(2 * math.pi * f), a(zeta), a(vmax), a(amax),
                             np.tile(np.array(stroke, dtype=float), (n, 1))))


def _step(servo: Servo, u: float, t_end: float, dt: float, x0: float = 0.0):
    x, v = np.array([x0]), np.array([0.0])
    xs, vs = [], []
    for _ in range(int(round(t_end / dt))):
        servo.advance(np.array([u]), x, v, dt)
        xs.append(x[0])
        vs.append(v[0])
    return np.array(xs), np.array(vs)


def test_transition_equals_the_matrix_exponential():
    from scipy.linalg import expm
    for zeta in (0.0, 0.3, 1.0, 1.0 + 1e-9, 2.5):
        w = 2 * math.pi * 7.0
        A = np.array([[0.0, 1.0], [-w * w, -2 * zeta * w]])
        np.testing.assert_allclose(transition(np.array([w]), np.array([zeta]), 3e-3)[0], expm(A * 3e-3),
                                   rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("zeta", [0.3, 0.5, 0.7])
def test_step_response_overshoot_and_peak_time(zeta):
    f, dt = 10.0, 1e-4
    x, _ = _step(_servo(f, zeta), 1.0, 0.5, dt)
    wn = 2 * math.pi * f
    overshoot = math.exp(-math.pi * zeta / math.sqrt(1 - zeta * zeta))
    assert x.max() - 1.0 == pytest.approx(overshoot, rel=1e-3)
    t_peak = math.pi / (wn * math.sqrt(1 - zeta * zeta))
    assert (x.argmax() + 1) * dt == pytest.approx(t_peak, abs=dt)
    assert abs(x[-1] - 1.0) < 1e-4


def test_bandwidth_sets_the_time_scale():
    """Critically damped: x(t) = 1 − (1 + ωn t) e^{−ωn t}, at any Δt (state-exact)."""
    for f in (2.0, 20.0):
        for dt in (1e-4, 5e-3):
            x, _ = _step(_servo(f, 1.0), 1.0, 0.3, dt)
            t = dt * np.arange(1, x.size + 1)
            wn = 2 * math.pi * f
            np.testing.assert_allclose(x, 1 - (1 + wn * t) * np.exp(-wn * t), atol=1e-12)


def test_rate_and_acceleration_limits_are_respected():
    vmax, amax, dt = 0.05, 0.5, 1e-3
    x, v = _step(_servo(20.0, 0.7, vmax=vmax, amax=amax), 0.2, 6.0, dt)   # 4 s at the rate limit
    assert np.abs(v).max() <= vmax + 1e-15
    assert np.abs(v).max() == pytest.approx(vmax)           # the limit is reached: it is what binds
    a = np.diff(np.concatenate(([0.0], v))) / dt
    assert np.abs(a).max() <= amax * (1 + 1e-12)
    assert abs(x[-1] - 0.2) < 1e-6                           # and it still arrives


@pytest.mark.parametrize("dt", [1e-4, 1e-3, 5e-3, 2e-2])
def test_stable_for_coarse_steps(dt):
    x, v = _step(_servo(50.0, 0.2), 1.0, 2.0, dt)            # ωn Δt up to 6.3
    assert np.all(np.isfinite(x)) and np.abs(x).max() < 2.0 and abs(x[-1] - 1.0) < 1e-6


def test_stroke_is_a_hard_stop():
    x, v = _step(_servo(10.0, 0.2, stroke=(0.0, 1.05)), 1.0, 0.3, 1e-3)
    assert x.max() == 1.05 and v[x.argmax()] == 0.0


def _servo_scene(servo: dict | None = None, extra_key: dict | None = None):
    data = parse_yaml(SCENE.read_text())
    block = dict(servo or {"bandwidth_hz": 15.0, "damping_ratio": 0.8, "max_rate": 0.5, "max_accel": 10.0})
    block.update(extra_key or {})
    data["members"]["leg1"]["actuator"]["servo"] = block      # the anchor: every leg
    data["solver"]["until"] = 0.3
    return scene_from_dict(data, source="stewart_servo.yaml")


def test_scene_servo_is_compiled_and_rolls_back_with_the_state():
    model = compile_scene(_servo_scene())
    sv = model.actuators.servo
    assert sv.size == 6 and sv.wn[0] == pytest.approx(2 * math.pi * 15.0) and sv.max_rate[0] == 0.5
    runner = TwinRunner(model)
    runner.start(warmup=False)
    L = runner.sample().actuator_commands.copy()
    names = list(model.actuators.names)
    assert runner.schedule.max_rate[0] == 0.5                # the servo's max_rate limits commanded rates
    assert runner.command_named("/a", names[:1], [L[0] + 0.01], [0.6]).kind == "rate"
    assert runner.command_array("/c", L + 0.01) is None      # a 10 mm step
    for _ in range(5):
        runner.step()
    st = runner.sim.state
    assert np.all(st.servo_x > L) and np.all(st.servo_x < L + 0.01) and np.all(st.servo_v > 0)
    # the actuator's length is the servo's output, not the command
    np.testing.assert_allclose(st.lam * model.actuators.l0, st.servo_x, rtol=0, atol=1e-15)
    saved = st.copy()
    runner.step()
    x1, v1 = st.servo_x.copy(), st.servo_v.copy()
    assert not np.array_equal(x1, saved.servo_x)
    st.assign(saved)                                          # what a rejected step does
    np.testing.assert_array_equal(st.servo_x, saved.servo_x)
    np.testing.assert_array_equal(st.servo_v, saved.servo_v)
    runner.step()                                             # the retried step repeats it exactly
    np.testing.assert_array_equal(st.servo_x, x1)
    np.testing.assert_array_equal(st.servo_v, v1)


def test_servo_smooths_a_100_hz_staircase():
    """With a servo even the old step hold of a 100 Hz stream stays within the quasi-static forces."""
    from flexmb_core.simulator import Simulator
    from flexmb_io.twin import RunnerOptions
    model = compile_scene(_servo_scene({"bandwidth_hz": 10.0, "damping_ratio": 0.9, "max_rate": 1.0,
                                        "max_accel": 20.0}))
    prog = Simulator(model)
    runner = TwinRunner(model, options=RunnerOptions(command_hold="step"))
    runner.start(warmup=False)
    peak = 0.0
    while runner.t < 1.0 - 1e-9:
        k = round(runner.t * 1000)
        if k % 10 == 0:
            assert runner.command_array("/c", prog.command_lengths(runner.t)) is None
        assert runner.step().advanced
        peak = max(peak, float(np.abs(runner.sample(full=False).actuator_forces).max()))
    assert peak < 300.0, peak                                 # without the servo: ~1e5 N


@pytest.mark.parametrize("extra,message", [
    ({"bandwith_hz": 3.0}, "stewart_servo.yaml:members.leg1.actuator.servo: unknown key(s) ['bandwith_hz'] (did you "
                           "mean 'bandwidth_hz' for 'bandwith_hz'?); allowed keys: ['bandwidth_hz', 'damping_ratio', "
                           "'max_accel', 'max_rate']"),
    ({"max_rate": -1.0}, "stewart_servo.yaml:members.leg1.actuator.servo.max_rate: expected a positive number "
                         "(m/s), got -1.0"),
    ({"damping_ratio": float("nan")}, "stewart_servo.yaml:members.leg1.actuator.servo.damping_ratio: expected a "
                                      "finite number, got nan"),
    ({"bandwidth_hz": "fast"}, "stewart_servo.yaml:members.leg1.actuator.servo.bandwidth_hz: expected a number in "
                               "Hz, got 'fast'"),
])
def test_servo_schema_is_strict(extra, message):
    with pytest.raises(SceneError) as exc:
        _servo_scene(extra_key=extra)
    assert str(exc.value) == message


def test_servo_keys_are_all_required():
    with pytest.raises(SceneError) as exc:
        _servo_scene({"bandwidth_hz": 10.0, "damping_ratio": 0.7, "max_rate": 1.0})
    assert str(exc.value) == "stewart_servo.yaml:members.leg1.actuator.servo: missing required key(s) ['max_accel']"
