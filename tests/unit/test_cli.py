"""The ``flexmb`` command line (contract: verbs, flags, JSON keys, exit codes)."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FLEXMB = [sys.executable, "-m", "flexmb_core.cli"]


def run(*args, **kw):
    return subprocess.run(FLEXMB + list(args), capture_output=True, text=True, cwd=ROOT, timeout=300, **kw)


def test_run_writes_the_json_summary(tmp_path):
    out = tmp_path / "out.json"
    p = run("run", "scenes/cantilever_b1.yaml", "--until", "0.05", "--json", str(out), "--quiet")
    assert p.returncode == 0, p.stderr
    s = json.loads(out.read_text())
    for key in ("steps", "wall_time_s", "rtf", "newton_iterations_mean", "newton_iterations_max",
                "unconverged_steps", "outputs"):
        assert key in s
    assert s["steps"] == 50 and s["unconverged_steps"] == 0 and s["completed"] is True
    assert s["rtf"] > 0 and 1 <= s["newton_iterations_max"] <= 10
    assert len(s["outputs"]["tip"]) == 3 and s["outputs"]["tip"][2] < 0.0   # the tip goes down
    assert {"kinetic", "strain", "gravity", "total"} <= set(s["outputs"]["energy"])


def test_dt_flag_overrides_the_scene(tmp_path):
    out = tmp_path / "o.json"
    p = run("run", "scenes/cantilever_b1.yaml", "--until", "0.02", "--dt", "0.005", "--json", str(out), "--quiet")
    assert p.returncode == 0, p.stderr
    s = json.loads(out.read_text())
    assert s["steps"] == 4 and s["dt"] == 0.005


def test_check_prints_the_model_summary():
    p = run("check", "scenes/actuator_arm.yaml")
    assert p.returncode == 0, p.stderr
    assert "free_dofs" in p.stdout and "actuator(frame): 1" in p.stdout and "mass" in p.stdout


def test_bad_scene_exits_1_with_file_and_key(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text((ROOT / "scenes/cantilever_b1.yaml").read_text().replace("radius: 0.005", "radius: -1"))
    p = run("check", str(bad))
    assert p.returncode == 1
    assert f"{bad}:sections.rod.radius: expected a positive number (m), got -1.0" in p.stderr


def test_bad_flag_value_exits_1():
    p = run("run", "scenes/cantilever_b1.yaml", "--dt", "-1")
    assert p.returncode == 1 and "--dt must be a positive number" in p.stderr


def test_unconverged_run_exits_2_and_says_so(tmp_path):
    scene = tmp_path / "s.yaml"
    text = (ROOT / "scenes/cantilever_b1.yaml").read_text()
    scene.write_text(text.replace("tolerance: 1.0e-10", "tolerance: 1.0e-10\n  max_iterations: 1\n  max_substep_levels: 0"))
    out = tmp_path / "o.json"
    p = run("run", str(scene), "--until", "0.01", "--json", str(out), "--quiet")
    assert p.returncode == 2
    assert "did not converge" in p.stderr
    s = json.loads(out.read_text())
    assert s["unconverged_steps"] == 1 and s["completed"] is False


def test_commands_stewart_writes_a_table(tmp_path):
    out = tmp_path / "cmd.csv"
    p = run("commands", "stewart", "--out", str(out), "--dt", "0.01", "--until", "1")
    assert p.returncode == 0, p.stderr
    lines = out.read_text().splitlines()
    assert lines[0].startswith("t,leg1,leg2,leg3,leg4,leg5,leg6")
    assert len(lines) == 102


@pytest.mark.parametrize("flags,text", [
    (["--until", "30"], "flexmb commands: the appendix law is defined for 0 <= t <= 20.0 s (Eq. 54), --until asks "
                        "for times in [0, 30] s"),
    (["--blend-time", "-1"], "flexmb commands: --blend-time must be a positive duration in s, got -1.0"),
    (["--switch-blend", "50"], "flexmb commands: --switch-blend must be a duration in [0, 20] s"),
])
def test_commands_outside_the_appendix_law_exit_1_naming_the_flag(tmp_path, flags, text):
    p = run("commands", "stewart", "--out", str(tmp_path / "c.csv"), *flags)
    assert p.returncode == 1 and text in p.stderr and "Traceback" not in p.stderr
    assert not (tmp_path / "c.csv").exists()


def test_commands_to_an_unwritable_path_exit_1_naming_it(tmp_path):
    out = tmp_path / "no_such_dir" / "c.csv"
    p = run("commands", "stewart", "--out", str(out), "--until", "1")
    assert p.returncode == 1 and "Traceback" not in p.stderr
    assert f"flexmb commands: --out {out}: cannot write the table (No such file or directory)" in p.stderr


def test_play_and_demo_refuse_what_they_cannot_run_with_exit_1(tmp_path):
    """Before any DDS: the player without commands to play, the demo of a scene that does not load."""
    ros = [sys.executable, "-m", "flexmb.cli"]
    p = subprocess.run(ros + ["play", "--timeout", "2"], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert p.returncode == 1, p.stderr
    assert "flexmb play: give a SCENE (its commands) or --csv TABLE --names leg1,leg2,..." in p.stderr
    missing = tmp_path / "missing.yaml"
    p = subprocess.run(ros + ["demo", str(missing), "--out", str(tmp_path / "demo")], capture_output=True, text=True,
                       cwd=ROOT, timeout=120)
    assert p.returncode == 1, p.stderr
    assert f"flexmb demo: scene error: {missing}: cannot read scene file" in p.stderr and "Traceback" not in p.stderr


def test_a_flag_argparse_rejects_exits_1_with_the_usage():
    """Bad input exits 1 whoever finds it (README "Exit codes"): argparse's own 2 would read as a step
    that did not converge."""
    p = run("run", "scenes/cantilever_b1.yaml", "--integrator", "foo")
    assert p.returncode == 1
    assert "usage: flexmb run" in p.stderr and "invalid choice: 'foo'" in p.stderr
    p = run("run", "scenes/cantilever_b1.yaml", "--no-such-flag")
    assert p.returncode == 1 and "unrecognized arguments: --no-such-flag" in p.stderr


def test_sigterm_ends_a_run_after_its_step_with_130_and_the_json(tmp_path):
    """SIGTERM (and SIGINT) stop ``flexmb run`` after the step under way, without a recording hook
    too: exit 130, the JSON written with the state reached (a whole step: its time a multiple of Δt).
    stderr is a terminal so that the progress bar says when the run steps."""
    import os
    import pty
    import select
    import signal
    import time

    out = tmp_path / "o.json"
    master, slave = pty.openpty()
    argv = ["run", "scenes/stewart_platform_bars.yaml", "--until", "100000", "--json", str(out)]
    proc = subprocess.Popen(FLEXMB + argv, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=slave)
    os.close(slave)
    seen = b""
    try:
        deadline = time.monotonic() + 120
        while b" t = " not in seen:             # the progress bar: the run is stepping
            assert proc.poll() is None and time.monotonic() < deadline, seen.decode(errors="replace")[-2000:]
            if select.select([master], [], [], 0.5)[0]:
                seen += os.read(master, 4096)
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
        while select.select([master], [], [], 0.2)[0]:
            try:
                chunk = os.read(master, 4096)
            except OSError:                     # the terminal closed with the process
                break
            if not chunk:
                break
            seen += chunk
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
    err = seen.decode(errors="replace")
    assert proc.returncode == 130, err[-2000:]
    assert "flexmb run: interrupted at t =" in err
    s = json.loads(out.read_text())
    assert s["completed"] is False and s["error"].startswith("interrupted at t =")
    assert 0 < s["sim_time_s"] < 100000 and s["steps"] == round(s["sim_time_s"] / s["dt"])


def test_a_second_signal_interrupts_at_once():
    """The first signal waits for the step under way; a second one (a step that takes minutes)
    interrupts where it lands."""
    import pytest

    from flexmb_core.cli import _StopOnSignal

    stop = _StopOnSignal()
    stop._note(15, None)
    with pytest.raises(KeyboardInterrupt, match="signal 15"):
        stop.check()
    with pytest.raises(KeyboardInterrupt, match="again"):
        stop._note(2, None)


FULL_CLI = [sys.executable, "-m", "flexmb.cli"]      # with the adapters' verbs (replay, node, play, …)


def _refused(argv, *texts, cli=None):
    p = subprocess.run((cli or FLEXMB) + argv, capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.returncode == 1, (argv, p.returncode, p.stderr[-1500:])
    assert "Traceback" not in p.stderr, p.stderr[-1500:]
    for text in texts:
        assert text in p.stderr, (text, p.stderr[-1500:])
    return p


def test_output_paths_are_checked_before_the_work(tmp_path):
    """A directory or an unwritable place as an output file: refused at once, naming the flag — not
    after the run, whose results would then be lost."""
    _refused(["run", "scenes/cantilever_b1.yaml", "--until", "0.01", "--json", str(tmp_path)],
             f"flexmb run: --json {tmp_path}: is a directory (expected the path of a file to write)")
    _refused(["run", "scenes/cantilever_b1.yaml", "--until", "0.01", "--json", "/proc/flexmb/out.json"],
             "flexmb run: --json /proc/flexmb/out.json: cannot write there (")
    blocker = tmp_path / "file"
    blocker.write_text("x")
    _refused(["replay", "bags/boom_step", "--json", str(blocker / "r.json")], f"--json {blocker / 'r.json'}: cannot "
             "write there (", cli=FULL_CLI)
    _refused(["sweep", "scenes/cantilever_b1.yaml", "--param", "solver.tolerance=1e-8,1e-9", "--out", str(blocker)],
             f"flexmb sweep: --out {blocker}: exists and is not a directory")


def test_numbers_the_tools_cannot_honour_are_refused(tmp_path):
    _refused(["run", "scenes/cantilever_b1.yaml", "--until", "0.01", "--dt", "1e-300"],
             "scenes/cantilever_b1.yaml:solver.dt: expected a number ≥ 1e-09, got 1e-300")
    _refused(["commands", "stewart", "--out", str(tmp_path / "c.csv"), "--dt", "1e-12"],
             "flexmb commands: --dt 1e-12: 20 000 000 000 001 rows over --until 20 s; at most 10 000 000")
    sweep = ["sweep", "scenes/cantilever_b1.yaml", "--param", "materials.steel.E=1e11:2e11", "--out", str(tmp_path)]
    _refused(sweep + ["--samples", "0"], "flexmb sweep: --samples: expected 1 to 1000000 runs, got 0")
    _refused(sweep + ["--samples", "4", "--seed", "-1"], "flexmb sweep: --seed: expected a non-negative integer, got -1")
    _refused(sweep + ["--samples", "4", "--scheduler", "notanaddress"],
             "flexmb sweep: --scheduler 'notanaddress': expected a scheduler address such as tcp://127.0.0.1:8786")


def test_a_replay_scene_that_cannot_be_read_names_the_file(tmp_path):
    _refused(["replay", "bags/boom_step", "--scene", str(tmp_path / "nope.yaml")],
             f"{tmp_path / 'nope.yaml'}: cannot read scene file (No such file or directory)", cli=FULL_CLI)


def test_ros_verbs_refuse_bad_flags_before_any_dds(tmp_path):
    scene = "scenes/stewart_platform_bars.yaml"
    _refused(["play", scene, "--rate", "0"], "flexmb play: --rate: expected a positive number, got 0.0", cli=FULL_CLI)
    _refused(["play", scene, "--twin", "bad!name"], "flexmb play: --twin 'bad!name': Invalid node name", cli=FULL_CLI)
    _refused(["node", scene, "--name", "bad!name"], "flexmb node: --name 'bad!name': Invalid node name", cli=FULL_CLI)
    _refused(["node", scene, "--summary-json", str(tmp_path)], f"flexmb node: summary_json {tmp_path}: is a directory",
             cli=FULL_CLI)
    _refused(["replay-live", "bags/boom_step", "--out", str(tmp_path / "o"), "--abs-tol", "-1"],
             "flexmb replay-live: --abs-tol: expected a finite number ≥ 0, got -1.0", cli=FULL_CLI)
    existing = tmp_path / "bag"
    existing.mkdir()
    (existing / "metadata.yaml").write_text("keep me\n")
    _refused(["demo", scene, "--mcap", str(existing), "--out", str(tmp_path / "demo")],
             f"flexmb demo: --mcap {existing}: already exists (a recording is never overwritten", cli=FULL_CLI)
    assert (existing / "metadata.yaml").read_text() == "keep me\n"


def test_viewing_and_playing_flags_are_checked_up_front(tmp_path):
    _refused(["run", "scenes/cantilever_b1.yaml", "--until", "0.01", "--rrd", str(tmp_path / "a.rrd"),
              "--rrd-period", "nan"], "flexmb run: --rrd-period must be a time ≥ 0 s (0: every step), got nan",
             cli=FULL_CLI)
    _refused(["view", "bags/boom_step", "--png", str(tmp_path / "a.png"), "--window-size", "0x0"],
             "flexmb view: --window-size: expected WIDTHxHEIGHT in points (1 to 16384 each), e.g. 1600x900, got '0x0'",
             cli=FULL_CLI)
    (tmp_path / "f").write_text("")         # a --png under a file: refused before the rendering
    _refused(["view", "bags/boom_step", "--png", str(tmp_path / "f" / "a.png")],
             f"flexmb view: --png {tmp_path / 'f' / 'a.png'}: cannot write there (File exists)", cli=FULL_CLI)
    (tmp_path / "empty.rrd").write_bytes(b"")
    _refused(["view", str(tmp_path / "empty.rrd"), "--png", str(tmp_path / "b.png")],
             f"flexmb view: {tmp_path / 'empty.rrd'}: an empty file; expected a rerun recording (.rrd)", cli=FULL_CLI)
    table = tmp_path / "t.csv"
    table.write_text("0,1,1\n0.001,nan,1\n")
    _refused(["play", "--csv", str(table), "--names", "a,b"],
             f"flexmb play: {table}: data row 2 of the table holds a value that is not a finite number", cli=FULL_CLI)
    _refused(["play", "--csv", str(table), "--names", "a,a"],
             "flexmb play: --names 'a,a': expected distinct, non-empty actuator names", cli=FULL_CLI)


def _verbs():
    import argparse

    from flexmb.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices


def _long_flags(parser) -> list[str]:
    """Every ``--flag`` of a verb, its sub-verbs' included (``bag info --json``)."""
    import argparse

    flags = [o for a in parser._actions for o in a.option_strings if o.startswith("--") and o != "--help"]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            flags += [f for p in action.choices.values() for f in _long_flags(p)]
    return flags


@pytest.mark.parametrize("verb", sorted(_verbs()))
def test_every_flag_of_a_verb_is_in_its_readme_row(verb):
    """The README's command table is the CLI's contract (a tried-as-a-user check reads it): each
    verb has a row ``| `flexmb VERB …` |`` and every flag the verb accepts is written in one."""
    rows = [ln for ln in (ROOT / "README.md").read_text().splitlines()
            if ln.startswith((f"| `flexmb {verb} ", f"| `flexmb {verb}`"))]
    assert rows, f"no README row for flexmb {verb}"
    text = "\n".join(rows)      # whole flags only: --record is not written by --record-rate
    missing = [f for f in _long_flags(_verbs()[verb]) if not re.search(re.escape(f) + r"(?![\w-])", text)]
    assert not missing, f"flexmb {verb}: flags missing from its README row: {missing}"


def test_inputs_a_user_could_type_get_one_line_not_a_traceback(tmp_path):
    """Cases a CLI fuzz found (session 25): each is bad input with a clear one-line answer, exit 1."""
    scene = (ROOT / "scenes" / "actuator_arm.yaml").read_text()
    zero = tmp_path / "zero.yaml"           # an actuator commanded to no length: the elements divide by it
    zero.write_text(scene.replace("command: {kind: ramp, start: 1.0, end: 1.3, duration: 2.0, shape: cycloidal}",
                                  "command: 0.0"))
    _refused(["run", str(zero), "--until", "0.01", "--quiet"],
             f"flexmb run: scene error: {zero}:members.lift.actuator.command: actuator 'lift' is commanded to 0 m "
             "at t = 0 s; expected a positive, finite length (m)")
    own = tmp_path / "own.yaml"             # an output path that is the input would overwrite the scene
    own.write_text(scene)
    _refused(["run", str(own), "--until", "0.01", "--quiet", "--json", str(own)],
             f"flexmb run: --json {own}: is an input of this command; expected another path")
    assert own.read_text() == scene
    long_name = tmp_path / ("a" * 300 + ".json")     # a component past NAME_MAX: OSError from exists()
    _refused(["run", str(own), "--until", "0.01", "--quiet", "--json", str(long_name)],
             "cannot write there (File name too long)")
    _refused(["commands", "stewart", "--out", str(tmp_path / "c.csv"), "--until", "1e308"],
             "flexmb commands: --dt 0.001: inf rows over --until 1e+308 s; at most 10 000 000")
    values = ",".join(str(2e11 + i) for i in range(1000))
    _refused(["sweep", str(own), "--param", f"materials.steel.E={values}", f"materials.steel.rho={values}",
              "materials.steel.nu=0.3,0.31", "--until", "0.01", "--out", str(tmp_path / "sweep"), "--quiet"],
             "flexmb sweep: --param: 1000 × 1000 × 2 = 2 000 000 runs; at most 1 000 000")
    _refused(["sweep", str(own), "--param", "materials.steel.E=2e11,2.1e11", "--outputs", "nope,arm_end",
              "--until", "0.01", "--out", str(tmp_path / "sweep"), "--quiet"],
             f"flexmb sweep: --outputs ['nope']: {own} declares no such output (it declares ['arm_end', 'arm_mid',")


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_a_summary_that_cannot_be_written_is_printed_instead():
    p = _refused(["run", "scenes/actuator_arm.yaml", "--until", "0.01", "--quiet", "--json", "/dev/full"],
                 "flexmb run: --json /dev/full: cannot write the summary (No space left on device)")
    assert "lift_force" in p.stdout, p.stdout[-1500:]


def test_an_initial_equilibrium_that_does_not_converge_exits_2_with_the_json(tmp_path):
    """A mechanism (a base joint taken away) has no static equilibrium to start from: that is a step
    that did not converge (exit 2, README), with the JSON written and completed false — not bad input."""
    scene = tmp_path / "loose.yaml"
    scene.write_text((ROOT / "scenes" / "stewart_platform_bars.yaml").read_text()
                     .replace("  - {node: b1, type: ball}\n", ""))
    out = tmp_path / "run.json"
    p = subprocess.run(FLEXMB + ["run", str(scene), "--until", "0.01", "--quiet", "--json", str(out)],
                       capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert p.returncode == 2, p.stderr[-1500:]
    assert "flexmb run: initial static equilibrium did not converge" in p.stderr and "Traceback" not in p.stderr
    summary = json.loads(out.read_text())
    assert summary["completed"] is False and summary["steps"] == 0
    assert summary["error"].startswith("initial static equilibrium did not converge")
