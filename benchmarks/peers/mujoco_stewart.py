"""The Stewart platform twin (seed appendix, SPEC §6.1/§8) in MuJoCo with rigid legs, as a peer.

The same mechanism as ``scenes/stewart_platform_bars.yaml`` (geometry, leg tubes, payload, gravity,
commands from flexmb's appendix program, blends included), built from MuJoCo bodies:

* each leg: a rigid uniform steel tube (25 × 3 mm, the leg's mass and inertia about its base) on a
  ``ball`` joint at its base point, carrying a light slider (1 % of the leg's mass) on a ``slide``
  joint along the leg axis; the slider's end is the leg's top;
* leg axial stiffness and damping: a ``position`` actuator (kp = EA/L0, ctrl = L_cmd − L0) and a
  ``velocity`` actuator (kv = EA·τ/L0, ctrl = the commanded rate) on the slide joint — the bar
  actuator's axial spring and its Kelvin–Voigt damping acting on the extension *relative to the
  command*; no leg bending (rigid bodies);
* platform: one free rigid body with the mass and inertia of flexmb's three steel edge tubes plus the
  10 kg payload at the vertices (``exudyn_stewart._platform_inertia``); leg tops joined to the
  vertices by ``connect`` equality constraints (MuJoCo constraints are soft: ``solref`` time
  constant 2Δt, the smallest MuJoCo accepts without disabling its safety clamp, damping ratio 1,
  ``solimp = 0.9999 0.9999 0.001``);
* start: the commands held at L0 under gravity, settled with temporary joint damping for 1 s, then
  velocities zeroed and the clock reset (flexmb and Exudyn start from their static equilibrium);
* commands: set from Python before every step (L_cmd(t_{k+1}) and the mean rate over the step);
  pose sampled in the same loop from the platform's free-joint ``qpos`` (position, quaternion): after
  ``mj_step`` the body's ``xpos``/``xquat`` still hold the step's *start* (kinematics run before the
  integration), which would lag the pose by one step — an O(Δt) error of ~3e-4 m at Δt = 1 ms;
* solver: ``integrator="discrete"`` (the actuator stiffness is implicit), ``solver="Newton"``,
  tolerance 1e-10, contacts off, one thread.

MuJoCo is an optional peer: imported lazily, never a dependency of flexmb.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.peers.mujoco_stewart [--until 20 --dt 1e-3]
"""
from __future__ import annotations

import argparse
import math
import statistics
import time
from typing import Any

import numpy as np

PACKAGE = "mujoco"
SOLIMP = "0.9999 0.9999 0.001"
SLIDER_FRACTION = 0.01
SETTLE_S = 1.0
SETTLE_DAMPING = 2000.0       # N·s/m (N·m·s on the ball joints) while settling


def available() -> bool:
    """True if the optional peer ``mujoco`` can be imported."""
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return False
    return True


def _f(x: float) -> str:
    """A float for MJCF: full precision, no numpy repr."""
    return repr(float(x))


def _quat_z_to(axis: np.ndarray) -> np.ndarray:
    """Quaternion (w, x, y, z) rotating e_z onto the unit vector ``axis``."""
    z = np.array([0.0, 0.0, 1.0])
    c = float(z @ axis)
    v = np.cross(z, axis)
    q = np.array([1.0 + c, *v])
    return q / np.linalg.norm(q)


def mjcf(dt: float) -> tuple[str, dict]:
    """The MJCF text of the rigid-leg twin and the data it was built from."""
    from benchmarks.peers.exudyn_stewart import _platform_inertia, _scene_data
    from flexmb_core.commands import StewartAppendixProgram

    d = _scene_data()                      # the frame-leg scene's material, sections, payload, gravity
    prog = StewartAppendixProgram(d["scene"].commands)
    geo = prog.geometry
    lay = geo.layout()
    offsets = geo.vertex_offsets()                                          # (3, 3)
    l0 = float(lay.lengths0[0])
    ea = d["E"] * d["leg_area"]
    leg_mass = d["rho"] * d["leg_area"] * l0
    ro, ri = d["scene"].sections["leg"].dims
    i_t = leg_mass * (l0 * l0 / 12.0 + (ro * ro + ri * ri) / 4.0)        # about the centre, transverse
    i_a = leg_mass * (ro * ro + ri * ri) / 2.0                            # about the axis
    m_s = SLIDER_FRACTION * leg_mass
    mass, inertia = _platform_inertia(offsets, d["rho"] * d["edge_area"] * geo.side, d["payload"])
    kp, kv = ea / l0, ea * d["tau"] / l0
    g = " ".join(f"{_f(x)}" for x in d["gravity"])
    legs, eqs, acts = [], [], []
    for i in range(6):
        p0 = lay.base_points[i]
        axis = lay.vertices0[lay.leg_vertex[i]] - p0
        axis = axis / np.linalg.norm(axis)
        q = _quat_z_to(axis)
        legs.append(f"""
    <body name="leg{i + 1}" pos="{_f(p0[0])} {_f(p0[1])} {_f(p0[2])}" quat="{_f(q[0])} {_f(q[1])} {_f(q[2])} {_f(q[3])}">
      <joint name="base{i + 1}" type="ball"/>
      <inertial pos="0 0 {_f(l0 / 2)}" mass="{_f(leg_mass)}" diaginertia="{_f(i_t)} {_f(i_t)} {_f(i_a)}"/>
      <body name="slider{i + 1}">
        <joint name="slide{i + 1}" type="slide" axis="0 0 1"/>
        <inertial pos="0 0 {_f(l0)}" mass="{_f(m_s)}" diaginertia="1e-7 1e-7 1e-7"/>
      </body>
    </body>""")
        eqs.append(f'    <connect body1="slider{i + 1}" body2="platform" anchor="0 0 {_f(l0)}" '
                   f'solref="{_f(2 * dt)} 1" solimp="{SOLIMP}"/>')
        acts.append(f'    <position name="spring{i + 1}" joint="slide{i + 1}" kp="{_f(kp)}" ctrllimited="false"/>\n'
                    f'    <velocity name="damper{i + 1}" joint="slide{i + 1}" kv="{_f(kv)}" ctrllimited="false"/>')
    c = geo.centroid0()
    ixx, iyy, izz, ixy, ixz, iyz = inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]
    xml = f"""<mujoco model="stewart_rigid_legs">
  <option timestep="{_f(dt)}" gravity="{g}" integrator="discrete" solver="Newton" tolerance="1e-10" iterations="100">
    <flag contact="disable"/>
  </option>
  <worldbody>{''.join(legs)}
    <body name="platform" pos="{_f(c[0])} {_f(c[1])} {_f(c[2])}">
      <freejoint/>
      <inertial pos="0 0 0" mass="{_f(mass)}" fullinertia="{_f(ixx)} {_f(iyy)} {_f(izz)} {_f(ixy)} {_f(ixz)} {_f(iyz)}"/>
    </body>
  </worldbody>
  <equality>
{chr(10).join(eqs)}
  </equality>
  <actuator>
{chr(10).join(acts)}
  </actuator>
</mujoco>"""
    return xml, {"prog": prog, "l0": lay.lengths0.copy(), "kp": kp, "kv": kv, "leg_mass": leg_mass,
                 "platform_mass": mass}


def build(dt: float) -> dict[str, Any]:
    """Compile the model and settle it under gravity at the initial commands (t = 0)."""
    import mujoco

    xml, info = mjcf(dt)
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    d.ctrl[:] = 0.0
    damping = m.dof_damping.copy()
    m.dof_damping[:] = SETTLE_DAMPING
    mujoco.mj_step(m, d, nstep=int(round(SETTLE_S / dt)))
    m.dof_damping[:] = damping
    d.qvel[:] = 0.0
    d.time = 0.0
    mujoco.mj_forward(m, d)
    body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "platform")
    return {"mujoco": mujoco, "m": m, "d": d, "body": body, **info}


def _solve(model: dict[str, Any], dt: float, until: float, mark: float) -> dict:
    mujoco, m, d, body, prog, l0 = (model[k] for k in ("mujoco", "m", "d", "body", "prog", "l0"))
    steps = int(round(until / dt))
    every = max(1, int(round(mark / dt)))
    buf = np.empty(6)
    prev = l0.copy()
    ctrl = d.ctrl
    adr = m.jnt_qposadr[m.body_jntadr[body]]          # the platform's free joint: position, quaternion
    pose = d.qpos[adr:adr + 7]                         # (mj_step leaves xpos/xquat at the step's start)
    hist = [[0.0, *pose]]
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        prog.lengths(k * dt, buf)
        ctrl[0::2] = buf - l0
        ctrl[1::2] = (buf - prev) / dt
        prev[:] = buf
        mujoco.mj_step(m, d)
        if k % every == 0:
            hist.append([k * dt, *pose])
    wall = time.perf_counter() - t0
    return {"wall": wall, "history": np.array(hist), "finite": bool(np.all(np.isfinite(d.qpos))),
            "steps": steps}


def run(dt: float = 1e-3, until: float = 20.0, repeats: int = 1, *, mark: float = 0.1) -> dict:
    """Run the rigid-leg twin; returns ``label``, ``family``, ``code``, ``dt``, ``until``, ``steps``,
    ``wall_time_s`` (median of ``repeats``, stepping loop incl. the Python command update),
    ``walls_s``, ``steps_per_s``, ``rtf``, ``converged`` (the state stayed finite), ``history``
    (n, 8): t, platform centroid (m), quaternion (w, x, y, z) every ``mark`` s.
    """
    import mujoco

    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    runs = [_solve(build(dt), dt, until, mark) for _ in range(repeats)]
    last = runs[-1]
    wall = statistics.median(r["wall"] for r in runs)
    ok = last["finite"]
    return {"code": f"mujoco {mujoco.__version__}",
            "family": "MuJoCo rigid legs + axial servo spring",
            "label": f"MuJoCo {mujoco.__version__}, rigid legs (axial spring EA/L0 as a position servo), "
                     f"soft connect constraints, Δt = {dt * 1e3:g} ms, commands from Python every step",
            "integrator": "discrete (MuJoCo)", "dt": dt, "until": until, "steps": last["steps"],
            "wall_time_s": wall, "walls_s": [r["wall"] for r in runs],
            "steps_per_s": last["steps"] / wall if ok else math.nan, "rtf": until / wall if ok else math.nan,
            "converged": ok, "t_reached": until if ok else math.nan, "history": last["history"]}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--until", type=float, default=20.0)
    ap.add_argument("--dt", type=float, nargs="+", default=[1e-3, 5e-3])
    args = ap.parse_args(argv)
    if not available():
        print("mujoco is not installed (optional peer): skipped")
        return
    for dt in args.dt:
        r = run(dt, args.until)
        h = r["history"]
        print(f"{r['label']}: {r['steps_per_s']:.0f} steps/s, RTF {r['rtf']:.1f}, platform height at t = 0: "
              f"{h[0, 3]:.6f} m, max |z − z(0)| {np.abs(h[:, 3] - h[0, 3]).max():.4f} m")


if __name__ == "__main__":
    main()
