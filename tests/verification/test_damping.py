"""Kelvin–Voigt material damping (``materials: {m: {eta: Pa·s}}``): free vibrations decay with the
closed-form modal damping ratio ζ = η ω / (2E), the dissipated power accounts for the lost energy,
rigid-body motion is not damped, full Newton keeps its quadratic convergence, and bad values are
rejected with the key named."""

import math

import numpy as np
import pytest

from builders import build, cantilever
from flexmb_core.errors import SceneError
from flexmb_core.modal import natural_modes
from flexmb_core.scene import scene_from_dict

E_BAR = 1.0e9
R_BAR = 0.01
L_BAR = 1.0
M_TIP = 1.0


def _bar_oscillator(eta, dt, until):
    """A light bar (fixed end a) carrying a point mass at b: the axial oscillator."""
    d = {
        "name": "bar_oscillator",
        "materials": {"m": {"E": E_BAR, "rho": 1e-3, "eta": eta}},
        "sections": {"rod": {"shape": "circle", "radius": R_BAR}},
        "nodes": {"a": [0.0, 0.0, 0.0], "b": [L_BAR, 0.0, 0.0]},
        "members": {"bar": {"kind": "truss", "from": "a", "to": "b", "material": "m", "section": "rod"}},
        "supports": [{"node": "a", "type": "ball"}],
        "point_masses": {"tip": {"node": "b", "mass": M_TIP}},
        "solver": {"analysis": "dynamic", "integrator": "newmark", "beta": 0.25, "gamma": 0.5, "dt": dt,
                   "until": until, "tolerance": 1e-13, "newton": "full"},
        "outputs": {"tip": {"kind": "node_position", "node": "b"}},
    }
    return build(d)


def _peaks(t, x):
    """Times and values of the local maxima of x (parabolic refinement)."""
    i = np.nonzero((x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:]))[0] + 1
    out_t, out_x = [], []
    for k in i:
        y0, y1, y2 = x[k - 1], x[k], x[k + 1]
        den = y0 - 2 * y1 + y2
        s = 0.5 * (y0 - y2) / den if den != 0 else 0.0
        out_t.append(t[k] + s * (t[1] - t[0]))
        out_x.append(y1 - 0.25 * (y0 - y2) * s)
    return np.array(out_t), np.array(out_x)


def _damping_ratio(peaks):
    """ζ from the logarithmic decrement δ over successive peaks: ζ = δ / √(4π² + δ²)."""
    delta = np.polyfit(np.arange(peaks.size), -np.log(peaks), 1)[0]
    return delta / math.sqrt(4 * math.pi**2 + delta**2)


def test_bar_free_vibration_decays_with_the_closed_form_damping_ratio():
    """Axial mode of a bar with a tip mass: ω = √(EA/(L M)), ζ = η ω / (2E) = ω τ / 2."""
    ea = E_BAR * math.pi * R_BAR**2
    omega = math.sqrt(ea / (L_BAR * M_TIP))
    zeta = 0.02
    eta = 2 * zeta * E_BAR / omega
    period = 2 * math.pi / omega
    model, sim = _bar_oscillator(eta, period / 400, 12 * period)
    sim.state.v[model.node_ydofs[1][0]] = 1e-3 * L_BAR * omega     # released from x = L with ẋ = 1e-3 L ω
    sim.initialize()                                                 # consistent a₀ = −(f_visc)/M
    ts, xs, power, energy = [], [], [], []
    sim.run(12 * period, callback=lambda s, r: (ts.append(s.state.t), xs.append(s.state.q[model.node_ydofs[1][0]] - L_BAR),
                                                  power.append(s.ws.dissipation), energy.append(r.total_energy)))
    tp, xp = _peaks(np.array(ts), np.array(xs))
    assert xp.size >= 10
    assert _damping_ratio(xp) == pytest.approx(zeta, rel=5e-3)          # measured 0.019994
    # damped period 2π/(ω√(1−ζ²)) (the trapezoidal rule lengthens it by (ωΔt)²/12 ≈ 2e-5)
    assert np.diff(tp).mean() == pytest.approx(period / math.sqrt(1 - zeta**2), rel=1e-3)
    # energy balance: mechanical energy lost = ∫ dissipated power dt (trapezoidal in time)
    dt = ts[1] - ts[0]
    lost = energy[0] - energy[-1]
    dissipated = dt * (np.sum(power[1:-1]) + 0.5 * (power[0] + power[-1]))
    assert lost > 0.9 * energy[0]
    assert dissipated == pytest.approx(lost, rel=1e-3)                  # measured 6e-5


def test_frame_bending_mode_decays_with_the_closed_form_damping_ratio():
    """First bending mode of a steel cantilever with a tip mass (4 cubic elements): ζ₁ = η ω₁/(2E),
    ω₁ from the linearized modes; the higher modes, damped ∝ ω, die out first. Full Newton stays
    quadratic with the damped (non-symmetric) tangent: ≤ 3 iterations per step."""
    E = 200e9
    d = cantilever(elements=4, order=3, E=E, nu=0.3, section={"shape": "rectangle", "width": 0.02, "height": 0.01},
                   forces={"push": {"node": "tip", "force": [0.0, 0.0, -20.0],
                                    "signal": {"kind": "ramp", "start": 1.0, "end": 0.0, "duration": 1e-9}}})
    d["point_masses"] = {"m": {"node": "tip", "mass": 0.5}}
    model0, _ = build(d)
    omega = natural_modes(model0, n_modes=1).omega[0]
    zeta = 0.015
    d["materials"]["m"]["eta"] = 2 * zeta * E / omega
    period = 2 * math.pi / omega
    model, sim = build(d, analysis="dynamic", integrator="newmark", beta=0.25, gamma=0.5, dt=period / 200,
                       until=15 * period, initial_state="static", tolerance=1e-12, newton="full")
    assert model.material_damping
    sim.initialize()
    tip = model.node_ydofs[model.node("tip")][2]
    ts, zs, its = [], [], []
    sim.run(15 * period, callback=lambda s, r: (ts.append(s.state.t), zs.append(s.state.q[tip]), its.append(r.iterations)))
    tp, zp = _peaks(np.array(ts), np.array(zs))
    assert zp.size >= 12
    assert _damping_ratio(zp[2:]) == pytest.approx(zeta, rel=5e-3)      # measured 0.014997
    assert np.diff(tp).mean() == pytest.approx(period / math.sqrt(1 - zeta**2), rel=1e-3)
    assert max(its) <= 3


def test_rigid_motion_is_not_damped():
    """A stiff bar pendulum swinging under gravity keeps its energy with strong material damping
    (ζ = 0.3 in its axial mode), while mass-proportional damping that barely touches the axial mode
    (c_m = 0.5/s: ζ = 1e-4 there) drains the swing."""
    def swing(material_eta, c_m):
        d = {
            "name": "pendulum",
            "materials": {"m": {"E": 2e11, "rho": 7850.0, "eta": material_eta}},
            "sections": {"rod": {"shape": "circle", "radius": 0.005}},
            "nodes": {"o": [0.0, 0.0, 0.0], "p": [0.5, 0.0, -0.866025403784439]},
            "members": {"rod": {"kind": "truss", "from": "o", "to": "p", "material": "m", "section": "rod"}},
            "supports": [{"node": "o", "type": "ball"}],
            "point_masses": {"bob": {"node": "p", "mass": 2.0}},
            "loads": {"gravity": [0.0, 0.0, -9.81]},
            "damping": {"mass_proportional": c_m},
            "solver": {"analysis": "dynamic", "integrator": "newmark", "beta": 0.25, "gamma": 0.5, "dt": 1e-3,
                       "until": 4.0, "tolerance": 1e-12},
        }
        model, sim = build(d)
        sim.initialize()
        e = []
        sim.run(4.0, callback=lambda s, r: e.append(r.total_energy))
        return np.array(e), model

    ea = 2e11 * math.pi * 0.005**2
    omega_axial = math.sqrt(ea / (1.0 * 2.0))
    eta = 2 * 0.3 * 2e11 / omega_axial
    e_kv, model = swing(eta, 0.0)
    e_mass, _ = swing(0.0, 0.5)
    swing_energy = 2.0 * 9.81 * (1.0 - math.cos(math.pi / 6))     # m g L (1 − cos 30°)
    assert np.abs(e_kv - e_kv[0]).max() < 1e-5 * swing_energy
    assert e_mass[0] - e_mass[-1] > 0.5 * swing_energy


@pytest.mark.parametrize("value, message", [
    (-1.0, "materials.m.eta: expected the Kelvin–Voigt viscosity as a finite number ≥ 0 in Pa·s, got -1.0"),
    ("lots", "materials.m.eta: expected the Kelvin–Voigt viscosity as a finite number ≥ 0 in Pa·s, got 'lots'"),
    (float("nan"), "materials.m.eta: expected the Kelvin–Voigt viscosity as a finite number ≥ 0 in Pa·s, got nan"),
    (True, "materials.m.eta: expected the Kelvin–Voigt viscosity"),
])
def test_bad_viscosity_is_rejected(value, message):
    d = cantilever(elements=1)
    d["materials"]["m"]["eta"] = value
    with pytest.raises(SceneError, match=message.replace("(", r"\(").replace(")", r"\)")):
        scene_from_dict(d, source="s.yaml")


def test_material_damping_in_the_damping_block_points_to_the_material():
    d = cantilever(elements=1)
    d["damping"] = {"eta": 1e6}
    with pytest.raises(SceneError, match=r"s.yaml:damping: material \(Kelvin–Voigt\) damping is a material property"):
        scene_from_dict(d, source="s.yaml")
