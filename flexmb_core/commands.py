"""Command programs: generators of actuator lengths that a scene names (``commands:`` block).

A program drives several actuators together (e.g. the six legs of the Stewart appendix law) and
is evaluated once per step for all of them. Per-actuator ``command`` signals cover the simple cases;
an external source (the ROS node, ``Simulator.set_commands``) overrides both.
"""

from __future__ import annotations

import numpy as np

from .errors import SceneError
from .scene.schema import CommandProgramSpec


class StewartAppendixProgram:
    """Leg lengths of Siqueira & Coda (2019), appendix Eqs. 52–60, held after 20 s."""

    n_actuators = 6

    def __init__(self, spec: CommandProgramSpec):
        from .mechanisms import stewart

        self._stewart = stewart
        self.start = spec.start
        self.blend_time = spec.blend_time
        self.geometry = stewart.StewartGeometry.default()
        self.lengths0 = self.geometry.layout().lengths0
        self._t = np.zeros(1)

    def lengths(self, t: float) -> np.ndarray:
        """Commanded lengths (m) of the six legs at ``t`` (s)."""
        self._t[0] = min(max(t, 0.0), self._stewart.T_END)
        lengths, _ = self._stewart.appendix_leg_lengths(self._t, self.geometry, start=self.start,
                                                        blend_time=self.blend_time)
        return lengths[0]

    def reference_pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Commanded platform centroid (m) and orientation (w, x, y, z) at ``t`` (s)."""
        self._t[0] = min(max(t, 0.0), self._stewart.T_END)
        p, quat = self._stewart.appendix_platform_outputs(self._t, self.geometry, start=self.start,
                                                          blend_time=self.blend_time)
        return p[0], quat[0]


PROGRAMS = {"stewart_appendix": StewartAppendixProgram}


def build_program(spec: CommandProgramSpec, l0: np.ndarray, where: str):
    """Instantiate the program and check it against the scene's actuators (count, lengths)."""
    prog = PROGRAMS[spec.program](spec)
    if len(spec.actuators) != prog.n_actuators:
        raise SceneError(where, f"program '{spec.program}' drives {prog.n_actuators} actuators, "
                                f"got {len(spec.actuators)}: {list(spec.actuators)}")
    if not np.allclose(prog.lengths0, l0, rtol=1e-9, atol=0.0):
        raise SceneError(where, f"program '{spec.program}' starts from lengths {prog.lengths0.tolist()} m "
                                f"but the scene's actuators measure {l0.tolist()} m: the scene geometry "
                                "must match the program's")
    return prog
