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
which the agent's odometry integrates, are not read. The drivers count the same turns the
truth moves by (:mod:`firmware_sim.odrive_sim`), so in an ideal world the odometry errs only
by sampling the wheels apart in time, never by a drift of the plant's making.

The plant publishes on Zenoh what the real world would give the robot's sensors: obstacle
detections within sensing range (10 Hz), pose fixes of a simulated motion-capture system
when the scenario has one (:mod:`firmware_sim.mocap_sim`) and, SITL only, the ground truth
(every ``truth_every`` physics steps).

An imperfect world (:class:`firmware_sim.world.WorldParams`, docs/world.md "In the SITL")
applies here with the batch simulator's own functions (:mod:`firmware_sim.world_step`):
each wheel slips (the ground moves by (1 - s) of the wheel's turn, s a Gauss-Markov process
stepped once per control period of the plant's own clock, keyed by the robot's index in its
scenario: the batch's sequence of slips), and each detection goes missing or is off by
noise. The drivers' encoders still count the full turns (their noise is the drivers':
:class:`firmware_sim.odrive_sim.DriverPair`). The ideal world runs exactly the code, and
gives exactly the motion, of a plant without one.
"""
from __future__ import annotations

import logging
import select
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from agent.config import RobotParams
from agent.kinematics import TWO_PI, arc_step, body_velocity
from common.payloads import ObstaclesMsg, TruthMsg
from firmware_sim.mocap_sim import SimulatedMocap
from firmware_sim.world import Obstacles, WorldParams
from firmware_sim.world_step import TIME_EPS, detect, slip_next

log = logging.getLogger(__name__)


class DriverPair(Protocol):
    """The emulated drivers of one robot's two wheels on its bus."""

    def fileno(self) -> int | None: ...                 # CAN bus descriptor (None: always read)
    def service(self, now: float, receive: bool = True) -> None: ...
    # CAN in (unless receive is False: nothing waiting) and out, periodic frames, watchdog
    def step(self, dt: float) -> None: ...              # advance the axes by dt [s]
    def wheel_state(self) -> tuple[float, float, float, float] | None: ...
    # (right, left) positions [rev], then (right, left) actual speeds [rev/s]; None while
    # nothing is known yet. The plant reads the speeds of local drivers.
    def close(self) -> None: ...


class WheelReports(Protocol):
    """The reports of a robot's drivers that run on another host (multi-host world)."""

    def reports(self) -> list[tuple[float, float, float]]: ...
    # (stamp [s], right, left positions [rev]) of each report since the last call, oldest
    # first: the plant rolls the robot through every one, so a late burst of reports moves
    # it along the path its wheels took, not along one arc from the first to the last


@dataclass
class PlantRobot:
    robot_id: int
    pose: tuple[float, float, float]     # x [m], y [m], theta [rad]
    drivers: DriverPair
    v: float = 0.0            # m/s, actual (held over the last physics step)
    u: float = 0.0            # rad/s, actual (held over the last physics step)
    # remote drivers (multi-host world): the robot rolls through the arc its wheels turned
    # between each two reports (a late report delays the motion, a lost one merges two
    # arcs, none loses it), and its truth is stamped at the last report: where the robot
    # was then, not a late view of it stamped now
    remote: WheelReports | None = None
    last_turns: tuple[float, float] | None = None     # rev, (right, left) last applied
    reported_at: float | None = None                  # s, wall time of the last report


class SitlPlant:
    """Robots ``ids`` of a scenario; ``publish(key_kind, robot_id, payload)`` sends on Zenoh."""

    def __init__(self, robots: list[PlantRobot], robot: RobotParams, obstacles: Obstacles,
                 sensing_range: float, publish: Callable[[str, int, bytes], None],
                 truth_every: int = 2, obstacles_period: float = 0.1,
                 world: WorldParams | None = None, period: float = 0.02,
                 index: Mapping[int, int] | None = None,
                 mocap: SimulatedMocap | None = None):
        """``truth_every``: publish truth every this many physics steps. ``world``: its wheel
        slip and detection noise and dropout apply (None: the ideal world); ``period`` [s]
        steps the slip (the scenario's control period); ``index`` maps robot ids to their
        indices in the scenario, the keys of the draws (default: their order in
        ``robots``). ``mocap``: captures the robots after every step (None: no pose
        fixes)."""
        self.robots, self.params, self.obstacles = robots, robot, obstacles
        self.sensing_range, self.publish = sensing_range, publish
        self.truth_every, self.obstacles_period = truth_every, obstacles_period
        self._steps = 0
        self._seq = 0
        self._next_obstacles = -np.inf
        self.world = world or WorldParams()
        self.mocap = mocap
        self.period = period
        self._keys = [index[rb.robot_id] if index is not None else j
                      for j, rb in enumerate(robots)]
        # (right, left) slip fraction of each robot's wheels; None: no slip
        self.slip: np.ndarray | None = (np.zeros((len(robots), 2))
                                        if self.world.wheel_slip > 0 else None)
        self._time = 0.0              # s, the plant's own clock (sum of its steps)
        self._slip_next = 0           # the next control period whose slip is to draw
        self._publications = 0        # detections published so far (key of their draws)
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
        slip = self.slip
        if slip is not None:
            self._advance_slip(slip)
        waiting = {fd for fd, _ in self._poll.poll(0)} if self._fds else ()
        for j, rb in enumerate(self.robots):
            fd = self._fds.get(rb.robot_id)
            grip = (1.0 - slip[j, 0], 1.0 - slip[j, 1]) if slip is not None else None
            if rb.remote is not None:
                for stamp, right, left in rb.remote.reports():
                    self._roll_to(rb, stamp, right, left, grip)
                continue
            rb.drivers.service(now_m, receive=fd is None or fd in waiting)
            rb.drivers.step(dt)
            state = rb.drivers.wheel_state()
            if state is None:
                continue
            _, _, right, left = state            # speeds at the step's end [rev/s]
            if grip is not None:                 # the ground moves by (1 - s) of the turn
                right, left = right * grip[0], left * grip[1]
            v, u = body_velocity(TWO_PI * right, TWO_PI * left, r.wheel_radius, r.wheel_base)
            rb.v, rb.u = float(v), float(u)
            rb.pose = arc_step(*rb.pose, rb.v * dt, rb.u * dt)
        self._time += dt
        self._steps += 1
        if self.mocap is not None:
            self.mocap.step(now_w, self.robots)
        if self._steps % self.truth_every == 0:
            self._seq += 1
            for rb in self.robots:
                at = rb.reported_at if rb.remote is not None else None
                self.publish("truth", rb.robot_id,
                             TruthMsg(rb.robot_id, self._seq, now_w if at is None else at,
                                      *rb.pose,
                                      rb.v, rb.u).encode())
        if now_m >= self._next_obstacles:
            self._next_obstacles = now_m + self.obstacles_period
            self.publish_obstacles(now_w)

    def _advance_slip(self, slip: np.ndarray) -> None:
        """Draw the slip of every control period begun by the plant's clock (the slip of
        period k is in force from k T to (k + 1) T, as in the batch simulator)."""
        w = self.world
        due = int((self._time + TIME_EPS) / self.period)      # a sum of steps: rounded
        while self._slip_next <= due:
            for j, key in enumerate(self._keys):
                for wheel in range(2):
                    slip[j, wheel] = slip_next(slip[j, wheel], self.period, w.seed,
                                               w.wheel_slip, key, wheel, self._slip_next)
            self._slip_next += 1

    def _roll_to(self, rb: PlantRobot, stamp: float, right: float, left: float,
                 grip: tuple[float, float] | None = None) -> None:
        """Move ``rb`` through the arc its wheels turned from ``rb.last_turns`` to (right,
        left) [rev], reported at ``stamp`` [s], the ground moving by ``grip`` (right, left)
        of each turn (None: 1)."""
        last, rb.last_turns = rb.last_turns, (right, left)
        since, rb.reported_at = rb.reported_at, stamp
        if last is None or since is None:
            return
        r = self.params
        turn_r, turn_l = right - last[0], left - last[1]
        if grip is not None:
            turn_r, turn_l = turn_r * grip[0], turn_l * grip[1]
        dist, dtheta = body_velocity(TWO_PI * turn_r, TWO_PI * turn_l,
                                     r.wheel_radius, r.wheel_base)
        span = stamp - since
        if span > 0.0:
            rb.v, rb.u = dist / span, dtheta / span
        rb.pose = arc_step(*rb.pose, dist, dtheta)

    def publish_obstacles(self, now_w: float) -> None:
        """Publish each robot's :meth:`detections`, stamped ``now_w`` [s]."""
        if not len(self.obstacles):
            return
        for msg in self.detections(now_w):
            self.publish("obstacles", msg.robot_id, msg.encode())

    def detections(self, now_w: float) -> list[ObstaclesMsg]:
        """Each robot's detections, stamped ``now_w`` [s]: the obstacles whose surface is
        within sensing range of its true position; in an imperfect world each is missing
        with probability ``detection_dropout``, the others' centre and radius [m] off by
        N(0, ``detection_noise``) (:func:`firmware_sim.world_step.detect`, keyed by the
        robot's scenario index, the obstacle's index and the count of publications)."""
        pos = np.array([rb.pose[:2] for rb in self.robots]).reshape(-1, 2)
        seen = self.obstacles.clearance(pos) <= self.sensing_range
        self._seq += 1
        w, out = self.world, []
        for key, rb, mask in zip(self._keys, self.robots, seen):
            centers, radii = self.obstacles.centers[mask], self.obstacles.radii[mask]
            if w.detections:
                o_k = np.flatnonzero(mask)
                o_x, o_y, o_r = centers[:, 0].copy(), centers[:, 1].copy(), radii.copy()
                kept = detect(key, self._publications, w.seed, w.detection_noise,
                              w.detection_dropout, len(o_k), o_x, o_y, o_r, o_k)
                centers, radii = np.column_stack([o_x[:kept], o_y[:kept]]), o_r[:kept]
            out.append(ObstaclesMsg(rb.robot_id, self._seq, now_w, centers, radii))
        self._publications += 1
        return out

    def close(self) -> None:
        for rb in self.robots:
            rb.drivers.close()
