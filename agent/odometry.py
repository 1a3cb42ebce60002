"""Dead reckoning from wheel encoder positions, integrated exactly as arcs.

Encoder positions are in revolutions (as ODrive reports them), positive forward for both
wheels. Between two readings each wheel is assumed to turn at a constant rate, so the robot
follows one circular arc: this is exact for constant wheel speeds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from agent.kinematics import arc_step

Pose = tuple[float, float, float]


@dataclass
class Odometry:
    """Pose estimate (x, y, theta) [m, m, rad] of one robot from its wheel encoders."""

    wheel_radius: float   # m
    wheel_base: float     # m
    pose: Pose            # current estimate, plain floats (read every period: no numpy)
    _last: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        x, y, theta = self.pose
        self.pose = (float(x), float(y), float(theta))

    def update(self, pos_right_rev: float, pos_left_rev: float) -> Pose:
        """Advance with new encoder positions [rev]; the first call only sets the origin."""
        if self._last is not None:
            d_right = 2.0 * math.pi * self.wheel_radius * (pos_right_rev - self._last[0])
            d_left = 2.0 * math.pi * self.wheel_radius * (pos_left_rev - self._last[1])
            dist = 0.5 * (d_right + d_left)
            dtheta = (d_right - d_left) / self.wheel_base
            self.pose = arc_step(*self.pose, dist, dtheta)
        self._last = (pos_right_rev, pos_left_rev)
        return self.pose
