"""The SITL plant: emulated wheel drivers on CAN moving simulated robots, over real time.

For each hosted robot the plant serves its two emulated drivers on the robot's own CAN bus
and, every physics step, moves the robot by its own physics: the unicycle driven by the
wheels' actual speeds (what the drivers apply after their limits, ramps, watchdogs and
faults), integrated exactly as an arc by :func:`agent.kinematics.arc_step`, the batch
simulator's integrator.

Integration rule: over a step of ``dt`` the wheels turn at the speed the drivers reached at
the step's end (after advancing their ramp by ``dt``), held over the whole step, as the batch
simulator's wheels plant (:func:`firmware_sim.swarm_step.advance`) holds its ramped wheel
speeds: given the same wheel set-points both plants move a robot alike, to rounding.

The truth never depends on what the robot measures or believes: the encoder positions,
which the agent's odometry integrates, are not read. The drivers integrate their encoders
with the speed's mean over each step, so a wheel's encoder and its turns in the truth differ
by half a step's worth of the wheel's speed change since the start: an offset that does not
grow with time.

The plant publishes on Zenoh what the real world would give the robot's sensors: obstacle
detections within sensing range (10 Hz) and, SITL only, the ground truth (every
``truth_every`` physics steps).
"""
from __future__ import annotations

import logging
import select
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from agent.config import RobotParams
from agent.kinematics import TWO_PI, arc_step, body_velocity
from common.payloads import ObstaclesMsg, TruthMsg
from firmware_sim.world import Obstacles

log = logging.getLogger(__name__)


class DriverPair(Protocol):
    """The emulated drivers of one robot's two wheels on its bus."""

    def fileno(self) -> int | None: ...                 # CAN bus descriptor (None: always read)
    def service(self, now: float, receive: bool = True) -> None: ...
    # CAN in (unless receive is False: nothing waiting) and out, periodic frames, watchdog
    def step(self, dt: float) -> None: ...              # advance the axes by dt [s]
    def wheel_state(self) -> tuple[float, float, float, float] | None: ...
    # (right, left) positions [rev], then (right, left) actual speeds [rev/s]; None while
    # nothing is known yet (remote drivers not heard from). The plant reads the speeds of
    # local drivers and the positions of remote ones (PlantRobot.reported_at).
    def close(self) -> None: ...


@dataclass
class PlantRobot:
    robot_id: int
    pose: tuple[float, float, float]     # x [m], y [m], theta [rad]
    drivers: DriverPair
    v: float = 0.0            # m/s, actual (held over the last physics step)
    u: float = 0.0            # rad/s, actual (held over the last physics step)
    # remote drivers (multi-host world): the wall time [s] of their last report. The robot
    # rolls through the arc its wheels' reported positions turned since the last report (a
    # late or lost report delays the motion but never loses it), and its truth is stamped
    # at the report: where the robot was then, not a late view of it stamped now
    reported_at: Callable[[], float | None] | None = None
    last_turns: tuple[float, float] | None = None     # rev, (right, left) last applied


class SitlPlant:
    """Robots ``ids`` of a scenario; ``publish(key_kind, robot_id, payload)`` sends on Zenoh."""

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
        # one poll for every robot's bus per step, not an empty read of each
        self._poll = select.poll()
        self._fds = {}
        for rb in robots:
            fd = rb.drivers.fileno()
            if fd is not None:
                self._poll.register(fd, select.POLLIN)
                self._fds[rb.robot_id] = fd

    def step(self, dt: float, now_m: float, now_w: float) -> None:
        """Serve the drivers at ``now_m`` (monotonic [s]), advance them and the robots by
        ``dt`` [s]; publish what is due, stamped ``now_w`` (wall clock [s])."""
        r = self.params
        waiting = {fd for fd, _ in self._poll.poll(0)} if self._fds else ()
        for rb in self.robots:
            fd = self._fds.get(rb.robot_id)
            rb.drivers.service(now_m, receive=fd is None or fd in waiting)
            rb.drivers.step(dt)
            state = rb.drivers.wheel_state()
            if state is None:
                continue
            if rb.reported_at is not None:
                self._roll_to(rb, state[0], state[1], dt)
                continue
            _, _, right, left = state            # speeds at the step's end [rev/s]
            v, u = body_velocity(TWO_PI * right, TWO_PI * left, r.wheel_radius, r.wheel_base)
            rb.v, rb.u = float(v), float(u)
            rb.pose = arc_step(*rb.pose, rb.v * dt, rb.u * dt)
        self._steps += 1
        if self._steps % self.truth_every == 0:
            self._seq += 1
            for rb in self.robots:
                stamp = rb.reported_at() if rb.reported_at is not None else None
                self.publish("truth", rb.robot_id,
                             TruthMsg(rb.robot_id, self._seq, stamp or now_w, *rb.pose,
                                      rb.v, rb.u).encode())
        if now_m >= self._next_obstacles:
            self._next_obstacles = now_m + self.obstacles_period
            self.publish_obstacles(now_w)

    def _roll_to(self, rb: PlantRobot, right: float, left: float, dt: float) -> None:
        """Move ``rb`` through the arc its wheels turned from ``rb.last_turns`` to (right,
        left) [rev]."""
        last, rb.last_turns = rb.last_turns, (right, left)
        if last is None:
            return
        r = self.params
        dist, dtheta = body_velocity(TWO_PI * (right - last[0]), TWO_PI * (left - last[1]),
                                     r.wheel_radius, r.wheel_base)
        rb.v, rb.u = dist / dt, dtheta / dt
        rb.pose = arc_step(*rb.pose, dist, dtheta)

    def publish_obstacles(self, now_w: float) -> None:
        """Each robot's detections: obstacles whose surface is within sensing range."""
        if not len(self.obstacles):
            return
        pos = np.array([rb.pose[:2] for rb in self.robots])
        seen = self.obstacles.clearance(pos) <= self.sensing_range
        self._seq += 1
        for rb, mask in zip(self.robots, seen):
            self.publish("obstacles", rb.robot_id,
                         ObstaclesMsg(rb.robot_id, self._seq, now_w, self.obstacles.centers[mask],
                                      self.obstacles.radii[mask]).encode())

    def close(self) -> None:
        for rb in self.robots:
            rb.drivers.close()
