"""Robot motion: unicycles integrated exactly as arcs, with or without wheel limits.

Both plants share one ``step(pose, v_cmd, u_cmd, dt) -> (pose, v, u)`` signature, returning
the new poses (N, 3) and the body velocities (v [m/s], u [rad/s]) actually applied:

* :class:`IdealPlant` applies the commands exactly, as the paper's kinematic model assumes;
* :class:`WheelPlant` passes them through the motor drivers' contract: wheel set-points
  saturated with curvature kept, clamped to the velocity limit and ramped at the driver's
  ramp rate. Wheel speeds are piecewise constant over each (sub)step, so call it with the
  physics step, not the control period.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from agent.config import RobotParams
from agent.kinematics import TWO_PI, body_velocity, integrate_arc, wheel_commands


class PlantKind(str, enum.Enum):
    IDEAL = "ideal"
    WHEELS = "wheels"


class IdealPlant:
    """Commands applied exactly: (v, u) held constant over dt."""

    def step(self, pose: np.ndarray, v_cmd: np.ndarray, u_cmd: np.ndarray, dt: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return integrate_arc(pose, v_cmd, u_cmd, dt), v_cmd, u_cmd


@dataclass
class WheelPlant:
    """Wheels with the emulated drivers' speed limit [rev/s] and ramp [rev/s^2]."""

    robot: RobotParams
    n: int
    wheel_rev_s: np.ndarray = field(init=False)   # (N, 2) actual (right, left) [rev/s]

    def __post_init__(self) -> None:
        self.wheel_rev_s = np.zeros((self.n, 2))

    def step(self, pose: np.ndarray, v_cmd: np.ndarray, u_cmd: np.ndarray, dt: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r = self.robot
        target = np.column_stack(wheel_commands(v_cmd, u_cmd, r.wheel_radius, r.wheel_base,
                                                r.wheel_speed_limit))
        max_step = r.wheel_ramp * dt
        self.wheel_rev_s = self.wheel_rev_s + np.clip(target - self.wheel_rev_s,
                                                      -max_step, max_step)
        v, u = body_velocity(TWO_PI * self.wheel_rev_s[:, 0], TWO_PI * self.wheel_rev_s[:, 1],
                             r.wheel_radius, r.wheel_base)
        return integrate_arc(pose, v, u, dt), v, u


def make_plant(kind: PlantKind, robot: RobotParams, n: int) -> IdealPlant | WheelPlant:
    return IdealPlant() if kind is PlantKind.IDEAL else WheelPlant(robot, n)
