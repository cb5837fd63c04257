"""Evaluate scene time signals (:class:`~flexmb_core.scene.schema.Signal`)."""

from __future__ import annotations

import math

import numpy as np

from .scene.schema import Signal


def ramp_shape(shape: str, s: float) -> float:
    """Normalised ramp 0 → 1 for s in [0, 1]: linear, smooth (C² quintic) or cycloidal (C²)."""
    s = min(max(s, 0.0), 1.0)
    if shape == "linear":
        return s
    if shape == "smooth":
        return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
    return s - math.sin(2.0 * math.pi * s) / (2.0 * math.pi)


def evaluate(sig: Signal, t: float) -> float:
    """Value of ``sig`` at time ``t`` (s)."""
    if sig.kind == "constant":
        return sig.value
    if sig.kind == "ramp":
        return sig.start + (sig.end - sig.start) * ramp_shape(sig.shape, (t - sig.t0) / sig.duration)
    if sig.kind == "spin_up":
        # θ(t) = (ω/T)[t²/2 + (T/2π)²(cos(2πt/T) − 1)] for t ≤ T, ω t − ωT/2 after (Simo & Vu-Quoc 1986)
        w, T = sig.amplitude, sig.duration
        if t <= T:
            return w / T * (0.5 * t * t + (T / (2.0 * math.pi)) ** 2 * (math.cos(2.0 * math.pi * t / T) - 1.0))
        return w * t - 0.5 * w * T
    if sig.kind == "sine":
        return sig.offset + sig.amplitude * math.sin(2.0 * math.pi * sig.frequency * t + sig.phase)
    return float(np.interp(t, sig.table_t, sig.table_v))
