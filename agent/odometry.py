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


def odometry_step(x: float, y: float, theta: float, d_right_rev: float, d_left_rev: float,
                  wheel_radius: float, wheel_base: float) -> Pose:
    """The pose [m, m, rad] after the wheels turned by (d_right_rev, d_left_rev) [rev] along
    one arc. Plain floats: the batch simulator compiles this very function."""
    d_right = 2.0 * math.pi * wheel_radius * d_right_rev
    d_left = 2.0 * math.pi * wheel_radius * d_left_rev
    return arc_step(x, y, theta, 0.5 * (d_right + d_left), (d_right - d_left) / wheel_base)


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
        """Advance with new encoder positions [rev]; the first call only sets the origin.
        Taken as plain floats, whatever number type the drivers' port gives."""
        pos_right_rev, pos_left_rev = float(pos_right_rev), float(pos_left_rev)
        if self._last is not None:
            self.pose = odometry_step(*self.pose, pos_right_rev - self._last[0],
                                      pos_left_rev - self._last[1], self.wheel_radius,
                                      self.wheel_base)
        self._last = (pos_right_rev, pos_left_rev)
        return self.pose
