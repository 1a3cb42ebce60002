"""Dead reckoning from wheel encoder positions, integrated exactly as arcs.

Encoder positions are in revolutions (as ODrive reports them), positive forward for both
wheels. Between two readings each wheel is assumed to turn at a constant rate, so the robot
follows one circular arc: this is exact for constant wheel speeds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agent.kinematics import arc_step


@dataclass
class Odometry:
    """Pose estimate (x, y, theta) [m, m, rad] of one robot from its wheel encoders."""

    wheel_radius: float   # m
    wheel_base: float     # m
    pose: np.ndarray      # (3,), current estimate
    _last: tuple[float, float] | None = None

    def update(self, pos_right_rev: float, pos_left_rev: float) -> np.ndarray:
        """Advance with new encoder positions [rev]; the first call only sets the origin."""
        if self._last is not None:
            d_right = 2.0 * math.pi * self.wheel_radius * (pos_right_rev - self._last[0])
            d_left = 2.0 * math.pi * self.wheel_radius * (pos_left_rev - self._last[1])
            dist = 0.5 * (d_right + d_left)
            dtheta = (d_right - d_left) / self.wheel_base
            self.pose = np.array(arc_step(*map(float, self.pose), dist, dtheta))
        self._last = (pos_right_rev, pos_left_rev)
        return self.pose
