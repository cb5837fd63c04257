"""Benchmark B1 (SPEC §8) run in MuJoCo, as a peer baseline for flexmb.

B1: steel cantilever (E = 200 GPa, ρ = 7850 kg/m³, L = 1 m, circular section r = 5 mm), clamped at
x = 0 along +x, dead tip load in −z ramped with the C² quintic 10s³ − 15s⁴ + 6s⁵ (s = t / 0.5 s) to
P = 2EI/L², then held; mass-proportional damping c_m = 10 1/s; 2 s. Error = |tip − reference| / L.

The MuJoCo model (MuJoCo ≥ 3.17: 1D flex bending elasticity; 4.0 removed the ``cable`` plugin):

* rod: ``<flexcomp type="direct" dim="1">`` with ``<elasticity young=E poisson=0.3>``, a
  *discrete elastic rod* (bending energy EI|κb|²/(ℓ₀ + ℓ₁) at each interior vertex, torsion on
  per-edge twist joints); ``n`` edges of length L/n over 0 ≤ x ≤ L; vertices are point masses on
  three slide joints each.
* inextensibility: the rod model has no stretching energy, so ``<edge equality="true">`` keeps the
  edge lengths (soft constraints). ``solref`` time constant = 2Δt (the smallest MuJoCo accepts
  without disabling its safety clamp), damping ratio 1, ``solimp = 0.9999 0.9999 0.001`` (as hard as
  the solver allows; the default 0.9–0.95 lets the rod stretch by 1e-2·L at Δt = 1 ms).
* clamp: the first edge is clamped by ``<pin id="0 1"/>`` (its material frame follows the world).
  ``clamp="short"`` (default) puts that edge *outside* the beam as a ghost edge of length 0.01·L/n
  ending at the root, so the root vertex's bending energy covers the beam's first half-edge only.
  ``clamp="grid"`` is the plain ``type="grid"`` layout with a full-length ghost edge: the root
  vertex's Voronoi region then reaches L/(2n) outside the beam and the clamp is too soft, an O(h)
  error (3.7e-2·L at 16 edges against 6.7e-4·L with the short ghost edge).
* mass: ρA·L/n on every free vertex, half at the tip (set after compile; flexcomp spreads ``mass``
  evenly over all vertices, pinned ones included).
* damping: c_m·m_i on each vertex slide joint (``dof_damping``): exact mass-proportional damping
  of the lumped mass; the twist joints are undamped.
* load: ``xfrc_applied`` on the tip body, set from Python before every step to P·s(t_{k+1}).
* output: ``mj_step`` computes the kinematics (``xpos``) *before* integrating, so after a step
  ``xpos`` is one step old; the tip is read after ``mj_kinematics`` (at the marks only).
* solver: ``integrator="discrete"`` (implicit; MuJoCo's recommended integrator for flex
  elasticity), ``solver="Newton"``, tolerance 1e-10, gravity off, contacts off, one thread.

MuJoCo is an optional peer: imported lazily, never a dependency of flexmb.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.peers.mujoco_b1 [--elements 16 64 --dt 1e-3]
"""
from __future__ import annotations

import argparse
import math
import statistics
import time
from typing import Any

import numpy as np

PACKAGE = "mujoco"
E = 200e9                     # Pa
NU = 0.3
RHO = 7850.0                  # kg/m^3
LENGTH = 1.0                  # m
RADIUS = 5e-3                 # m
AREA = math.pi * RADIUS**2
INERTIA = math.pi * RADIUS**4 / 4.0
EI = E * INERTIA
P_TIP = 2.0 * EI / LENGTH**2  # k = 2
T_RAMP = 0.5                  # s
C_MASS = 10.0                 # 1/s
GHOST = 0.01                  # ghost-edge length / (L/n) of the "short" clamp
SOLIMP = "0.9999 0.9999 0.001"
ELASTICA_K2 = (0.839358279175, -0.493457480397)
CLAMPS = ("short", "grid")


def available() -> bool:
    """True if the optional peer ``mujoco`` can be imported."""
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return False
    return True


def ramp(t: float) -> float:
    """The C² quintic load factor s(t) ∈ [0, 1] (1 after T_RAMP)."""
    s = min(max(t / T_RAMP, 0.0), 1.0)
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


def mjcf(n_elements: int, dt: float, clamp: str = "short", solimp: str | None = SOLIMP) -> str:
    """The MJCF text of the B1 rod with ``n_elements`` edges over [0, L]; ``solimp=None`` keeps
    MuJoCo's default constraint impedance (0.9 0.95 0.001)."""
    if n_elements < 2:
        raise ValueError(f"n_elements must be >= 2 (a rod needs an interior vertex), got {n_elements}")
    if clamp not in CLAMPS:
        raise ValueError(f"clamp must be one of {CLAMPS}, got {clamp!r}")
    h = LENGTH / n_elements
    ghost = GHOST * h if clamp == "short" else h
    points = [-ghost] + [i * h for i in range(n_elements + 1)]
    pts = " ".join(f"{x:.17g} 0 0" for x in points)
    elems = " ".join(f"{i} {i + 1}" for i in range(n_elements + 1))
    return f"""<mujoco model="b1">
  <option timestep="{dt!r}" gravity="0 0 0" integrator="discrete" solver="Newton" tolerance="1e-10"
          iterations="100"/>
  <worldbody>
    <flexcomp name="rod" type="direct" dim="1" point="{pts}" element="{elems}" radius="{RADIUS!r}" mass="1">
      <elasticity young="{E!r}" poisson="{NU!r}"/>
      <edge equality="true" solref="{2 * dt!r} 1"{'' if solimp is None else f' solimp="{solimp}"'}/>
      <pin id="0 1"/>
      <contact contype="0" conaffinity="0"/>
    </flexcomp>
  </worldbody>
</mujoco>"""


def build_model(n_elements: int, dt: float, clamp: str = "short", solimp: str | None = SOLIMP) -> dict[str, Any]:
    """Compile the rod and set the lumped masses and mass-proportional damping."""
    import mujoco

    m = mujoco.MjModel.from_xml_string(mjcf(n_elements, dt, clamp, solimp))
    h = LENGTH / n_elements
    bodies = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"rod_{i}") for i in range(2, n_elements + 2)]
    if min(bodies) < 0:
        raise RuntimeError(f"MuJoCo {mujoco.__version__}: expected vertex bodies rod_2 … rod_{n_elements + 1}")
    for k, b in enumerate(bodies):
        m.body_mass[b] = RHO * AREA * h * (0.5 if k == n_elements - 1 else 1.0)
        for j in range(m.body_jntadr[b], m.body_jntadr[b] + m.body_jntnum[b]):
            m.dof_damping[m.jnt_dofadr[j]] = C_MASS * m.body_mass[b]
    d = mujoco.MjData(m)
    mujoco.mj_setConst(m, d)
    return {"mujoco": mujoco, "m": m, "d": d, "tip": bodies[-1], "bodies": bodies}


def _solve(model: dict[str, Any], dt: float, t_end: float, history_period: float | None) -> dict:
    mujoco, m, d, tip = model["mujoco"], model["m"], model["d"], model["tip"]
    steps = int(round(t_end / dt))
    every = int(round(history_period / dt)) if history_period else 0
    hist = [[0.0, *d.xpos[tip]]] if every else []
    xfrc = d.xfrc_applied
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        xfrc[tip, 2] = -P_TIP * ramp(k * dt)
        mujoco.mj_step(m, d)
        if every and k % every == 0:
            mujoco.mj_kinematics(m, d)          # mj_step leaves xpos at the step's start
            hist.append([k * dt, *d.xpos[tip]])
    wall = time.perf_counter() - t0
    mujoco.mj_kinematics(m, d)
    pos = np.vstack([np.zeros(3)] + [d.xpos[b] for b in model["bodies"]])
    stretch = float(np.linalg.norm(np.diff(pos, axis=0), axis=1).sum() - LENGTH)
    finite = bool(np.all(np.isfinite(d.qpos)))
    return {"wall": wall, "steps": steps, "tip": (float(d.xpos[tip, 0]), float(d.xpos[tip, 2])),
            "history": np.array(hist), "stretch": stretch, "finite": finite,
            "solver_iterations": int(d.solver_niter[0])}


def run_b1(n_elements: int, dt: float = 1e-3, t_end: float = 2.0, reference=ELASTICA_K2, repeats: int = 3,
           *, clamp: str = "short", solimp: str | None = SOLIMP, history_period: float | None = None) -> dict:
    """Run B1 with ``n_elements`` rod edges; the stepping loop timed ``repeats`` times (median).

    Returns the keys of :func:`benchmarks.peers.exudyn_b1.run_b1` (``code``, ``model``,
    ``n_elements``, ``dt``, ``steps``, ``wall_time_s``, ``steps_per_s``, ``rtf``, ``tip`` [x, z] (m),
    ``tip_error``, ``converged``, ``t_reached``, ``wall_times_s``) plus ``family``, ``integrator``,
    ``stretch`` (sum of edge lengths − L at the end, m: the soft inextensibility constraint;
    ``solimp=None`` leaves MuJoCo's default impedance, under which the rod stretches visibly),
    ``history`` (n, 4: t, x, y, z every ``history_period`` s, when given) and ``note``.
    MuJoCo never reports a failure: ``converged`` only says the state stayed finite, which is why
    ``note`` flags a tip farther than 0.1·L from the reference as *silently wrong*.
    """
    import mujoco

    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    runs = [_solve(build_model(n_elements, dt, clamp, solimp), dt, t_end, history_period) for _ in range(repeats)]
    last = runs[-1]
    wall = statistics.median(r["wall"] for r in runs)
    tip = np.array(last["tip"]) / LENGTH
    error = float(np.linalg.norm(tip - np.asarray(reference, dtype=float)))
    ok = last["finite"]
    note = f"edge stretch {last['stretch']:.1e} m"
    if ok and error > 0.1:
        note = f"silently wrong: tip {error:.2f}·L from the elastica, no warning; " + note
    clamp_txt = "short ghost edge" if clamp == "short" else "grid ghost edge (L/n)"
    return {
        "code": f"mujoco {mujoco.__version__}",
        "family": f"MuJoCo 1D flex (DER), {n_elements} el." + ("" if clamp == "short" else ", grid clamp")
                  + ("" if solimp is not None else ", default solimp"),
        "model": f"flexcomp dim=1, {n_elements} edges, discrete integrator, edge equality "
                 f"(solref {2 * dt:g} s), clamp: {clamp_txt}",
        "integrator": "discrete (MuJoCo)", "n_elements": n_elements, "dt": dt, "steps": last["steps"],
        "wall_time_s": wall, "wall_times_s": [r["wall"] for r in runs],
        "steps_per_s": last["steps"] / wall if ok else math.nan, "rtf": t_end / wall if ok else math.nan,
        "tip": [last["tip"][0], last["tip"][1]], "tip_error": error if ok else math.nan,
        "converged": ok, "t_reached": t_end if ok else math.nan, "stretch": last["stretch"],
        "history": last["history"], "note": note,
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--elements", type=int, nargs="+", default=[8, 16, 32, 64])
    ap.add_argument("--dt", type=float, default=1e-3)
    ap.add_argument("--clamp", choices=CLAMPS, default="short")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    if not available():
        print("mujoco is not installed (optional peer): skipped")
        return
    for n in args.elements:
        r = run_b1(n, dt=args.dt, repeats=args.repeats, clamp=args.clamp)
        print(f"{r['family']:40s} Δt {args.dt:g}: {r['steps_per_s']:8.0f} steps/s  RTF {r['rtf']:7.2f}  "
              f"tip {r['tip'][0]:.6f} {r['tip'][1]:.6f}  error/L {r['tip_error']:.2e}  {r['note']}")


if __name__ == "__main__":
    main()
