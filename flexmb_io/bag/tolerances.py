"""Replay tolerances: one per kind of field, stated with their units (``flexmb replay --tolerance``).

Tolerance keys (``flexmb replay --tolerance KEY=VALUE``) and defaults:

=============  ==========  ====================================================================
key            default     applies to
=============  ==========  ====================================================================
``length``     1e-9 m      actuator lengths and commanded lengths (``/joint_states`` position of
                           actuators, ``~/actuator_states`` lengths, commanded_lengths)
``position``   1e-9 m      platform centroid (``*platform_pose``, ``/tf`` translation) and every
                           ``~/shape`` node, as a distance
``angle``      1e-9 rad    passive joint angles (``/joint_states`` position of joints) and platform
                           orientation (rotation angle between recorded and replayed quaternions)
``velocity``   1e-6        actuator rates (m/s) and joint rates (rad/s): 1e-9 m over Δt = 1 ms
``force``      1e-6        axial forces (``effort``, ``axial_forces``), as a fraction of the
                           field's peak |value| over the whole bag
``energy``     1e-6        kinetic, strain and total energy (``~/status``), fraction of peak
``converged``  0           samples whose ``converged`` flag differs (a count)
=============  ==========  ====================================================================

A replay through the same code on the same machine is bit-exact (every deviation is 0); the
tolerances leave room for round-off from another BLAS, numba or CPU (a reordered sum in the truss
kernel moved the 20 s Stewart reference by 1.4e-14 m and 5e-9 of the peak force). They sit well
below what a physical change produces: +1 % on the steel modulus of bags/stewart_bars_appendix
moves its leg forces by 3e-4 of their peak (300× the tolerance), the platform by 7.8e-8 m and
1.4e-7 rad (80×, 140×).
"""

from __future__ import annotations

import math

DEFAULT_TOLERANCES = {"length": 1e-9, "position": 1e-9, "angle": 1e-9, "velocity": 1e-6, "force": 1e-6,
                      "energy": 1e-6, "converged": 0.0}
UNITS = {"length": "m", "position": "m", "angle": "rad", "velocity": "m/s|rad/s", "force": "× peak",
         "energy": "× peak", "converged": "samples"}
RELATIVE = {"force", "energy"}
# unit of a deviation as reported (relative kinds are reported in their physical unit)
REPORT_UNITS = {"length": "m", "position": "m", "angle": "rad", "velocity": "m/s|rad/s", "force": "N",
                "energy": "J", "converged": "samples"}


class ToleranceError(ValueError):
    """A ``KEY=VALUE`` tolerance that is not understood."""


def parse_tolerances(items: list[str] | None, base: dict | None = None) -> dict[str, float]:
    """Defaults, updated by ``base`` (a mapping, e.g. a manifest entry) and ``KEY=VALUE`` items.

    Raises
    ------
    ToleranceError
        On an unknown key, a value that is not a number ≥ 0, or an item without ``=``.
    """
    tol = dict(DEFAULT_TOLERANCES)
    pairs = list((base or {}).items())
    given: set[str] = set()
    for item in items or ():
        if "=" not in item:
            raise ToleranceError(f"--tolerance {item!r}: expected KEY=VALUE, e.g. length=1e-8")
        k, v = item.split("=", 1)
        if k.strip() in given:
            raise ToleranceError(f"--tolerance {k.strip()!r} given twice; give each key once")
        given.add(k.strip())
        pairs.append((k.strip(), v.strip()))
    for k, v in pairs:
        if k not in tol:
            raise ToleranceError(f"unknown tolerance {k!r}; expected one of {sorted(tol)}")
        try:
            x = float(v)
        except (TypeError, ValueError):
            raise ToleranceError(f"tolerance {k}={v!r} is not a number") from None
        if not (x >= 0 and math.isfinite(x)):
            raise ToleranceError(f"tolerance {k}={v!r} must be finite and ≥ 0")
        if k == "converged" and x != int(x):
            raise ToleranceError(f"tolerance converged={v!r} counts samples: expected a whole number ≥ 0")
        tol[k] = x
    return tol
