"""Verification helpers: reference solutions that are independent of the finite-element code."""

from .analytic import (
    euler_bernoulli_cantilever_frequencies,
    extensible_elastica_cantilever,
    linear_rollup_tip,
    section_moments_circle,
    section_moments_rectangle,
    svk_rollup_tip,
    timoshenko_cantilever_frequencies,
)

__all__ = [
    "euler_bernoulli_cantilever_frequencies",
    "timoshenko_cantilever_frequencies",
    "extensible_elastica_cantilever",
    "section_moments_rectangle",
    "section_moments_circle",
    "svk_rollup_tip",
    "linear_rollup_tip",
]
