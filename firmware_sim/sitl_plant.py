"""The SITL plant: emulated wheel drivers on CAN moving simulated robots, over real time.

For each hosted robot the plant serves its two emulated drivers on the robot's own CAN bus
and, every physics step, moves the robot along the exact arc its wheels turned through
(the drivers' encoder positions, after their limits, ramps, watchdogs and faults; the arcs
:class:`agent.odometry.Odometry` would integrate, in plain floats), so the
ground truth and the agent's odometry differ only by what the agent has not read yet. It
publishes on Zenoh what the real world would give the robot's sensors: obstacle detections
within sensing range (10 Hz) and, SITL only, the ground truth (every ``truth_every`` physics
steps).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from agent.config import RobotParams
from agent.kinematics import arc_step, body_velocity
from firmware_sim.world import Obstacles
from transport.payloads import ObstaclesMsg, TruthMsg

log = logging.getLogger(__name__)


class DriverPair(Protocol):
    """The emulated drivers of one robot's two wheels on its bus."""

    def service(self, now: float) -> None: ...          # CAN in/out, periodic frames, watchdog
    def step(self, dt: float) -> None: ...              # advance the axes by dt [s]
    def wheel_state(self) -> tuple[float, float, float, float] | None: ...
    # (right, left) positions [rev], then (right, left) actual speeds [rev/s]; None while
    # nothing is known yet (remote drivers not heard from)
    def close(self) -> None: ...


@dataclass
class PlantRobot:
    robot_id: int
    pose: np.ndarray          # (3,) x [m], y [m], theta [rad]; in a plant, a row of its
                              # pose array, updated in place every step
    drivers: DriverPair
    v: float = 0.0            # m/s, actual
    u: float = 0.0            # rad/s, actual


class SitlPlant:
    """Robots ``ids`` of a scenario; ``publish(key_kind, robot_id, payload)`` sends on Zenoh.
    Each robot's ``pose`` becomes a row of the plant's own pose array, updated in place."""

    def __init__(self, robots: list[PlantRobot], robot: RobotParams, obstacles: Obstacles,
                 sensing_range: float, publish: Callable[[str, int, bytes], None],
                 truth_every: int = 2, obstacles_period: float = 0.1):
        """``truth_every``: publish truth every this many physics steps."""
        self.robots, self.params, self.obstacles = robots, robot, obstacles
        self.sensing_range, self.publish = sensing_range, publish
        self.truth_every, self.obstacles_period = truth_every, obstacles_period
        self._steps = 0
        self._seq = 0
        self._next_obstacles = -np.inf
        self._poses = [tuple(map(float, rb.pose)) for rb in robots]     # (x, y, theta)
        self._wheels: list[tuple[float, float] | None] = [None] * len(robots)
        # (right, left) positions [rev] at the last step; None until the drivers are heard from
        self._pose_array = np.array(self._poses, float).reshape(len(robots), 3)
        for rb, pose in zip(robots, self._pose_array):
            rb.pose = pose

    def step(self, dt: float, now_m: float, now_w: float) -> None:
        for rb in self.robots:
            rb.drivers.service(now_m)
            rb.drivers.step(dt)
        self._move()
        self._steps += 1
        if self._steps % self.truth_every == 0:
            self._seq += 1
            for rb, pose in zip(self.robots, self._poses):
                self.publish("truth", rb.robot_id,
                             TruthMsg(rb.robot_id, self._seq, now_w, *pose, rb.v, rb.u).encode())
        if now_m >= self._next_obstacles:
            self._next_obstacles = now_m + self.obstacles_period
            self.publish_obstacles(now_w)

    def _move(self) -> None:
        """Each robot rolls along the exact arc its wheels turned through since the last step
        (the first wheel state heard only sets the origin); v [m/s] and u [rad/s] from the
        wheels' actual speeds. Robots whose drivers are not heard from yet stay put. Plain
        floats: numpy's per-call overhead outweighs its gain for a few dozen robots."""
        r = self.params
        metres = 2.0 * math.pi * r.wheel_radius          # per wheel revolution
        for i, rb in enumerate(self.robots):
            state = rb.drivers.wheel_state()
            if state is None:
                continue
            right_pos, left_pos, right, left = state
            rb.v, rb.u = body_velocity(math.tau * right, math.tau * left, r.wheel_radius,
                                       r.wheel_base)
            last = self._wheels[i]
            if last is not None:
                d_right, d_left = metres * (right_pos - last[0]), metres * (left_pos - last[1])
                self._poses[i] = arc_step(*self._poses[i], 0.5 * (d_right + d_left),
                                          (d_right - d_left) / r.wheel_base)
            self._wheels[i] = (right_pos, left_pos)
        if self._poses:                                   # (no robots: nothing to copy)
            self._pose_array[:] = self._poses

    def publish_obstacles(self, now_w: float) -> None:
        """Each robot's detections: obstacles whose surface is within sensing range."""
        if not len(self.obstacles):
            return
        seen = self.obstacles.clearance(self._pose_array[:, :2]) <= self.sensing_range
        self._seq += 1
        for rb, mask in zip(self.robots, seen):
            self.publish("obstacles", rb.robot_id,
                         ObstaclesMsg(rb.robot_id, self._seq, now_w, self.obstacles.centers[mask],
                                      self.obstacles.radii[mask]).encode())

    def close(self) -> None:
        for rb in self.robots:
            rb.drivers.close()
