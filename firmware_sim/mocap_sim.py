"""A simulated motion-capture system for the SITL: pose fixes from the plant's truth.

The optional ``[mocap]`` table of a scenario (:class:`MocapParams`, docs/formats.md) makes
the SITL plant publish a fix of each of its robots (common.payloads.FixMsg on
``boundswarm/<swarm>/robot/<id>/fix``) ``rate`` times a second: the true pose at the
capture, off by Gaussian noise, stamped with the capture time and published ``latency``
seconds later; each fix is lost with probability ``dropout``, and every fix of a robot in
an outage (``[[mocap.outage]]``, in mission time) is lost. The agents then get a ``[pose]``
table (agent.pose) with ``fix_timeout``. The fixes go where the plant's truth goes: the
SITL's loopback router.
"""
from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from common.payloads import FixMsg
from common.schema import ConfigError, setting, tables, validate

MIN_ERROR = 0.001     # m, the error bound a noiseless simulated fix states


@dataclass(frozen=True)
class Outage:
    """A robot whose fixes stop (occluded markers, a bridge that hangs)."""

    robot: int = setting(doc="id of the robot whose fixes stop", lo=0)
    at: float = setting(doc="from when, in mission time", unit="s", lo=0.0)
    duration: float = setting(doc="for how long", unit="s", lo=0.0, open_lo=True)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class MocapParams:
    """A simulated motion-capture system (the SITL plant; the batch: firmware_sim.batch_pose)."""

    rate: float = setting(100.0, unit="Hz", lo=1.0, hi=1000.0, doc="fixes of each robot "
                          "per second")
    noise: float = setting(0.001, unit="m", lo=0.0, hi=0.1, doc="standard deviation of each "
                           "position coordinate of a fix")
    heading_noise: float = setting(0.002, unit="rad", lo=0.0, hi=0.5,
                                   doc="standard deviation of a fix's heading")
    latency: float = setting(0.01, unit="s", lo=0.0, hi=0.5,
                             doc="from the capture to the publication")
    dropout: float = setting(0.0, lo=0.0, hi=0.99, doc="fraction of fixes lost")
    fix_timeout: float = setting(0.5, unit="s", lo=0.0, open_lo=True,
                                 doc="the agents' [pose] fix_timeout")
    seed: int = setting(0, lo=0, doc="seed of the noise and dropouts")
    outage: tuple[Outage, ...] = tables(doc="robots whose fixes stop ([[mocap.outage]] "
                                        "robot, at, duration)")

    def __post_init__(self) -> None:
        validate(self)
        if self.fix_timeout <= self.latency:
            raise ConfigError(f"MocapParams.fix_timeout: must exceed the latency "
                              f"({self.latency:g} s), got {self.fix_timeout:g}")

    @property
    def error(self) -> float:
        """The position error bound [m] each fix states: three standard deviations."""
        return max(3.0 * self.noise, MIN_ERROR)

    def out(self, robot_id: int, t: float) -> bool:
        """Whether ``robot_id``'s fixes are stopped at mission time ``t`` [s]."""
        return any(o.robot == robot_id and o.at <= t < o.at + o.duration
                   for o in self.outage)

    def fix(self, robot_id: int, seq: int, stamp: float, pose: Sequence[float],
            z: Sequence[float]) -> FixMsg:
        """The fix of a robot at true ``pose`` (x, y, theta), captured at ``stamp`` [s], off
        by ``z`` (three standard normal draws) times the noise."""
        return FixMsg(robot_id, seq, stamp, float(pose[0] + self.noise * z[0]),
                      float(pose[1] + self.noise * z[1]),
                      float(pose[2] + self.heading_noise * z[2]), self.error)


class Tracked(Protocol):
    """What the system sees of a robot (firmware_sim.sitl_plant.PlantRobot)."""

    robot_id: int
    pose: tuple[float, float, float]


class SimulatedMocap:
    """Fixes of ``robots`` (publish(robot_id, payload)); ``epoch()`` gives the mission's epoch
    (UNIX [s], None before the mission) that outages count from."""

    def __init__(self, params: MocapParams, publish: Callable[[int, bytes], None],
                 epoch: Callable[[], float | None]):
        self.p, self.publish, self.epoch = params, publish, epoch
        self._rng = np.random.default_rng(params.seed)
        self._next = -math.inf        # s, UNIX time of the next capture
        self._queue: deque[tuple[float, int, bytes]] = deque()   # (due, robot id, payload)
        self._seq = 0
        self._epoch: float | None = None
        self.published = 0
        self.lost = 0

    def _out(self, robot_id: int, now: float) -> bool:
        if self._epoch is None:
            self._epoch = self.epoch()
            if self._epoch is None:
                return False
        return self.p.out(robot_id, now - self._epoch)

    def step(self, now: float, robots: Sequence[Tracked]) -> None:
        """Capture ``robots`` if a capture is due at ``now`` (UNIX [s]); publish the fixes
        whose latency has passed."""
        p = self.p
        if now >= self._next:
            self._next = max(self._next + 1.0 / p.rate, now)
            self._seq += 1
            noise = self._rng.normal(size=(len(robots), 3))
            lost = self._rng.random(len(robots)) < p.dropout
            for k, rb in enumerate(robots):
                if lost[k] or self._out(rb.robot_id, now):
                    self.lost += 1
                    continue
                msg = p.fix(rb.robot_id, self._seq, now, rb.pose, noise[k])
                self._queue.append((now + p.latency, rb.robot_id, msg.encode()))
        while self._queue and self._queue[0][0] <= now:
            _, rid, payload = self._queue.popleft()
            self.publish(rid, payload)
            self.published += 1
