"""What a step reports: data, never prints (adapters decide what to log or publish)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class StepResult:
    """Outcome of one time step (or static load step).

    Attributes
    ----------
    converged : bool — Newton met the tolerance on every sub-step.
    iterations : int — Newton iterations, summed over sub-steps.
    residual : float — relative residual ‖r‖/‖f_ref‖ at the accepted configuration.
    increment : float — last scaled Newton increment max|Δq_i|/scale_i (m/m, –).
    substeps : int — 1 unless the step was split after a failure.
    kinetic, strain, gravity : float — energies at the end of the step (J).
    message : str — why a step failed or was split ('' when all went well).
    guard : str — set when the step guard refused a converged Newton root in this step (the
        step failed, or was split after it): ``'energy'`` (the root raised the step's incremental
        potential), ``'inverted'`` (a frame section turned inside out), ``'svk_limit'`` (a fibre
        compressed past the Saint-Venant–Kirchhoff limit point); '' otherwise.
    """

    converged: bool
    iterations: int
    residual: float
    increment: float
    substeps: int = 1
    kinetic: float = 0.0
    strain: float = 0.0
    gravity: float = 0.0
    message: str = ""
    guard: str = ""

    @property
    def total_energy(self) -> float:
        return self.kinetic + self.strain + self.gravity
