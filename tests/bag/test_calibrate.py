"""``flexmb calibrate`` (issue 17): identify scene parameters from a recording, on Dask.

A synthetic "measured" run: the calibration rig (tests/data/calibration/stewart_bars_step.yaml, the
bar-leg Stewart twin ringing after two leg steps) recorded with known perturbed parameters (E +3 %,
eta ×2, payload +1 kg), then Gaussian noise added to every recorded output. The fit starts 20 % off
and must recover each value within 1 % and within 2 of its reported standard errors. Every cluster
is local (2 worker processes on 127.0.0.1) and shared by the module; runs are 0.3 s of simulated time.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from flexmb_core.study.calibrate import CalibrationError, FitParam, bounds, fit, parse_fit
from flexmb_core.scene.overrides import OverrideError
from flexmb_io import messages as M
from flexmb_io import topics as T
from flexmb_io.bag.calibrate import read_measurements, residuals, start_values
from flexmb_io import wire
from flexmb_io.bag.reader import BagReader, recover
from flexmb.cli import main

from bag_helpers import ROOT

pytest.importorskip("distributed")

RIG = ROOT / "tests/data/calibration/stewart_bars_step.yaml"
KEYS = ("materials.steel.E", "materials.steel.eta", "point_masses.payload_a.mass")
NOMINAL = (210.0e9, 2.75e6, 3.3333333333)
TRUTH = (NOMINAL[0] * 1.03, NOMINAL[1] * 2.0, NOMINAL[2] + 1.0)
START = tuple(v * f for v, f in zip(TRUTH, (0.8, 1.2, 0.8)))      # 20 % off
# measurement noise (1σ): load cells, leg encoders, a tracker
NOISE = {"lengths": 5e-7, "axial_forces": 40.0, "velocities": 1e-3, "position": 1e-6, "orientation": 1e-6}


def _scene_with(values) -> str:
    text = RIG.read_text(encoding="utf-8")
    old = ("steel: {E: 210.0e9, nu: 0.3, rho: 7850.0, eta: 2.75e6}", "payload_a: {node: A, mass: 3.3333333333}")
    assert all(o in text for o in old)
    return (text.replace(old[0], f"steel: {{E: {values[0]!r}, nu: 0.3, rho: 7850.0, eta: {values[1]!r}}}")
            .replace(old[1], f"payload_a: {{node: A, mass: {values[2]!r}}}"))


def add_noise(src: Path, dst: Path, seed: int = 1) -> None:
    """Copy a bag with Gaussian noise (:data:`NOISE`) on the actuator states and platform poses."""
    from mcap_ros2.decoder import DecoderFactory
    from scipy.spatial.transform import Rotation

    from flexmb_io.bag.reader import obj_to_dict

    r = BagReader(src)
    decoders = {ch.topic: DecoderFactory().decoder_for("cdr", r.schemas[ch.schema_id]) for ch in r.channels.values()}
    rng = np.random.default_rng(seed)

    def edit(topic: str, type_name: str, data: bytes) -> bytes:
        if type_name not in ("flexmb_msgs/msg/ActuatorState", "geometry_msgs/msg/PoseStamped"):
            return data
        m = obj_to_dict(decoders[topic](data))
        if type_name == "flexmb_msgs/msg/ActuatorState":
            for k in ("lengths", "axial_forces", "velocities"):
                m[k] = (np.asarray(m[k]) + NOISE[k] * rng.standard_normal(len(m[k]))).tolist()
        else:
            p, o = m["pose"]["position"], m["pose"]["orientation"]
            for k in "xyz":
                p[k] += NOISE["position"] * rng.standard_normal()
            q = Rotation.from_rotvec(NOISE["orientation"] * rng.standard_normal(3)) * \
                Rotation.from_quat([o["x"], o["y"], o["z"], o["w"]])
            o["x"], o["y"], o["z"], o["w"] = (float(v) for v in q.as_quat())
        return wire.serialize(type_name, wire.make(type_name, m))

    recover(src, dst, edit=edit)


@pytest.fixture(scope="module")
def measured(tmp_path_factory) -> Path:
    """The rig run with the TRUTH parameters, every output at 1 kHz, plus sensor noise."""
    d = tmp_path_factory.mktemp("calib")
    scene = d / "stewart_bars_step.yaml"
    scene.write_text(_scene_with(TRUTH), encoding="utf-8")
    assert main(["run", str(scene), "--quiet", "--record-rate", "1000", "--mcap", str(d / "exact")]) == 0
    add_noise(d / "exact", d / "noisy")
    return d / "noisy"


def _start_overrides() -> list[str]:
    return [f"{k}={v!r}" for k, v in zip(KEYS, START)]


# -- the identification ---------------------------------------------------------------------------

def test_recovers_perturbed_parameters_within_2_sigma_and_1_percent(measured, client, tmp_path, capsys):
    out = tmp_path / "cal"
    rc = main(["calibrate", str(measured), "--fit", *KEYS, "--override", *_start_overrides(),
               "--scheduler", client.scheduler.address, "--out", str(out), "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0, text
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["success"] is True
    for p, truth, start in zip(doc["parameters"], TRUTH, START):
        assert p["start"] == pytest.approx(start, rel=1e-12)
        assert abs(p["value"] / truth - 1.0) < 0.01, p
        assert abs(p["value"] - truth) < 2.0 * p["std_error"], p
        assert not p["at_bound"]
    # the estimated noise levels are the ones added (within 10 %)
    noise = {c["name"]: c["noise"] for c in doc["channels"]}
    assert noise["actuators.force"] == pytest.approx(NOISE["axial_forces"], rel=0.1)
    assert noise["platform.position"] == pytest.approx(NOISE["position"], rel=0.1)
    assert noise["platform.orientation"] == pytest.approx(NOISE["orientation"], rel=0.1)   # per rotation-vector axis
    # the calibrated scene holds the identified values and runs
    scene = Path(doc["calibrated_scene"])
    assert main(["check", str(scene)]) == 0
    from flexmb_core.scene.loader import parse_yaml

    data = parse_yaml(scene.read_text())
    assert data["materials"]["steel"]["E"] == pytest.approx(doc["parameters"][0]["value"], rel=1e-12)
    assert data["point_masses"]["payload_a"]["mass"] == pytest.approx(doc["parameters"][2]["value"], rel=1e-12)
    assert "materials.steel.E" in text and "converged" in text


def test_residuals_vanish_at_the_recorded_parameters(tmp_path):
    """Bit-identical replay: at the values the bag was recorded with, every residual is exactly 0."""
    assert main(["run", str(RIG), "--quiet", "--until", "0.05", "--record-rate", "1000", "--mcap",
                 str(tmp_path / "b")]) == 0
    meas = read_measurements(tmp_path / "b", list(KEYS))
    theta = start_values(meas.setup, None, list(KEYS))
    assert tuple(theta) == pytest.approx(NOMINAL, rel=1e-15)
    r = residuals(meas, theta)
    assert set(r) == {"actuators.length", "actuators.force", "actuators.velocity", "platform.position",
                      "platform.orientation"}
    assert all(np.all(v == 0.0) for v in r.values())
    moved = residuals(meas, theta * np.array([1.0, 1.0, 1.1]))
    assert np.abs(moved["actuators.force"]).max() > 0.1          # a heavier payload is seen (N)


def test_calibrates_a_node_style_bag_from_its_joint_states(tmp_path, client):
    """A bag as the live node writes it (named, stamped commands at 100 Hz under the node's default
    smooth hold; /joint_states only, as a ros2_control system records): the payload is identified
    from the efforts (noise-free: to 1e-4)."""
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene import load_scene
    from flexmb_io.bag.recorder import BagRecorder
    from flexmb_io.twin import RunnerOptions, TwinRunner, apply_message

    truth = (NOMINAL[0], NOMINAL[1], NOMINAL[2] + 1.0)
    scene = tmp_path / "truth.yaml"
    scene.write_text(_scene_with(truth), encoding="utf-8")
    runner = TwinRunner(compile_scene(load_scene(scene)), options=RunnerOptions())
    runner.start()
    names, rest = list(runner.model.actuators.names), runner.model.actuators.l0.copy()
    n = T.DEFAULT_NODE_NAME
    settings = {"dt": runner.dt, "integrator": runner.sim.spec.integrator, "mode": "lockstep", "node_name": n,
                "runner_options": vars(runner.options), "source": "flexmb node"}
    with BagRecorder(tmp_path / "node", scene_path=str(scene), scene_text=None, settings=settings) as rec:
        for k in range(200):
            t = runner.t
            if k % 10 == 0:
                cmd = M.actuator_command(t, names, rest + 1e-3 * np.sin(2 * np.pi * 2.0 * t), [])
                rec.write(T.ACTUATOR_COMMANDS.resolved(n), T.ACTUATOR_COMMANDS.type, cmd, t)
                assert apply_message(runner, "actuator_commands", T.ACTUATOR_COMMANDS.resolved(n), cmd) is None
            assert runner.step().advanced
            if k % 10 == 9:
                s = runner.sample()
                rec.write(T.JOINT_STATES.resolved(n), T.JOINT_STATES.type, M.joint_state(s), s.t)
    key = KEYS[2]
    rc = main(["calibrate", str(tmp_path / "node"), "--fit", key, "--override", f"{key}={0.8 * truth[2]!r}",
               "--outputs", "force", "--scheduler", client.scheduler.address, "--out", str(tmp_path / "cal"),
               "--quiet"])
    assert rc == 0
    doc = json.loads((tmp_path / "cal" / "calibration.json").read_text())
    assert [c["name"] for c in doc["channels"]] == ["actuators.force"]
    assert doc["channels"][0]["samples"] == 20 * 6
    assert doc["parameters"][0]["value"] == pytest.approx(truth[2], rel=1e-4)


# -- the numerics, on a model with a known answer ---------------------------------------------------

_T = np.linspace(0.0, 2.0, 200)
_SIGMA = 0.01


def _decay(data, theta):
    """Residual of y = a·exp(−b t) against data (a Dask task: module level, picklable)."""
    y = data
    return {"y": theta[0] * np.exp(-theta[1] * _T) - y}


def test_fit_of_a_known_model_gives_the_linearized_standard_errors(client):
    rng = np.random.default_rng(3)
    a, b = 2.0, 1.5
    y = a * np.exp(-b * _T) + _SIGMA * rng.standard_normal(_T.size)
    params = [FitParam("a"), FitParam("b", 0.1, 10.0)]
    res = fit(_decay, y, params, np.array([1.6, 1.2]), client, measured_rms={"y": 1.0}, units={"y": "-"},
              noise={"y": _SIGMA})
    assert res.success
    # the exact Jacobian at the solution gives the textbook covariance σ² (JᵀJ)⁻¹
    ah, bh = res.values
    J = np.column_stack([np.exp(-bh * _T), -ah * _T * np.exp(-bh * _T)])
    se = np.sqrt(np.diag(_SIGMA ** 2 * np.linalg.inv(J.T @ J)))
    assert res.std_errors == pytest.approx(se, rel=1e-2)
    assert abs(ah - a) < 3 * se[0] and abs(bh - b) < 3 * se[1]
    assert res.channels[0].sigma_given and res.channels[0].sigma == _SIGMA


def test_estimated_noise_matches_the_added_noise(client):
    rng = np.random.default_rng(4)
    y = 2.0 * np.exp(-1.5 * _T) + _SIGMA * rng.standard_normal(_T.size)
    res = fit(_decay, y, [FitParam("a"), FitParam("b")], np.array([2.4, 1.8]), client, measured_rms={"y": 1.0},
              units={"y": "-"})
    assert res.channels[0].sigma == pytest.approx(_SIGMA, rel=0.15)
    assert not res.channels[0].sigma_given and res.passes >= 2


# -- bad input --------------------------------------------------------------------------------------

@pytest.mark.parametrize("item, message", [
    ("materials.steel.E=1:", "bounds must be LO:HI with finite numbers LO < HI, got '1:'"),
    ("materials.steel.E=3:2", "bounds must be LO:HI with finite numbers LO < HI, got '3:2'"),
    ("=1:2", "expected KEY or KEY=LO:HI"),
    ("materials.steel.E=", "expected KEY or KEY=LO:HI"),
])
def test_bad_fit_items_are_refused(item, message):
    with pytest.raises(OverrideError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_fit(item)


def test_bounds_default_to_a_decade_and_refuse_a_start_outside():
    lo, hi = bounds([FitParam("x"), FitParam("y", -1.0, 1.0)], np.array([-2.0, 0.5]))
    assert tuple(lo) == (-20.0, -1.0) and tuple(hi) == (-0.2, 1.0)
    with pytest.raises(CalibrationError, match="its start is 0; give bounds KEY=LO:HI"):
        bounds([FitParam("x")], np.array([0.0]))
    with pytest.raises(CalibrationError, match=r"the start 3 lies outside the bounds \[1, 2\]"):
        bounds([FitParam("x", 1.0, 2.0)], np.array([3.0]))


@pytest.mark.parametrize("args, message", [
    (["--fit", "materials.steel.G"], "--fit materials.steel.G: the scene has no such key"),
    (["--fit", "materials.steel"], "--fit materials.steel: not a number in the scene"),
    (["--fit", "materials.steel.E", "--outputs", "torque"], "--outputs 'torque': no such measured channel"),
    (["--fit", "materials.steel.E", "--noise", "actuators.force=-1"], "expected CHANNEL=SIGMA with SIGMA > 0"),
    (["--fit", "materials.steel.E", "materials.steel.E"], "--fit names a key twice"),
    (["--fit", "materials.steel.E", "--until", "5"], "--until 5 s is beyond the recording"),
])
def test_bad_calibrate_flags_exit_1_with_the_reason(measured, args, message, capsys):
    assert main(["calibrate", str(measured), *args, "--quiet"]) == 1
    assert message in capsys.readouterr().err


def test_a_bag_without_commands_is_refused(tmp_path, capsys):
    from flexmb_io.bag.recorder import BagRecorder
    from flexmb_io.twin import TwinRunner
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.scene import load_scene

    runner = TwinRunner(compile_scene(load_scene(RIG)))
    s = runner.start(warmup=False)
    with BagRecorder(tmp_path / "b", scene_path=str(RIG), scene_text=None, settings={"dt": 1e-3}) as rec:
        rec.write(T.ACTUATOR_STATES.resolved("flexmb_twin"), T.ACTUATOR_STATES.type, M.actuator_state(s), 0.0)
    assert main(["calibrate", str(tmp_path / "b"), "--fit", "materials.steel.E"]) == 1
    assert "no recorded commands" in capsys.readouterr().err
