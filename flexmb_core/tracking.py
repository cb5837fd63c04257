"""Tracking error of a platform against the pose its command program asks for."""

from __future__ import annotations

import math

import numpy as np

from .model.model import Model
from .observers import platform_pose


class PoseTracker:
    """Accumulates position / orientation errors of the scene's ``platform_pose`` output.

    Active only when the scene has such an output and its command program knows the commanded
    pose (``reference_pose(t)``); otherwise :attr:`active` is False and nothing is computed.
    """

    def __init__(self, model: Model):
        self.model = model
        outs = [o for o in model.scene.outputs if o.kind == "platform_pose"]
        self.output = outs[0] if outs else None
        self.active = self.output is not None and hasattr(model.program, "reference_pose")
        self.max_position = 0.0
        self.max_angle = 0.0
        self.t_max_position = 0.0
        self._sq_position = 0.0
        self.samples = 0

    def update(self, t: float, q: np.ndarray) -> None:
        if not self.active:
            return
        pos, quat = platform_pose(self.model, q, self.output.nodes)
        p_ref, q_ref = self.model.program.reference_pose(t)
        dp = float(np.linalg.norm(pos - p_ref))
        ang = 2.0 * math.acos(min(1.0, abs(float(quat @ q_ref))))
        if dp > self.max_position:
            self.max_position, self.t_max_position = dp, t
        self.max_angle = max(self.max_angle, ang)
        self._sq_position += dp * dp
        self.samples += 1

    def summary(self) -> dict:
        if not self.active or not self.samples:
            return {}
        return {"output": self.output.name, "max_position_error_m": self.max_position,
                "t_of_max_position_error_s": self.t_max_position,
                "rms_position_error_m": math.sqrt(self._sq_position / self.samples),
                "max_orientation_error_rad": self.max_angle}
