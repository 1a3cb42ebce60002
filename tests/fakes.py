"""In-memory ports for agent tests on simulated time: no bus, no session, no wall clock."""
from __future__ import annotations

from types import MappingProxyType
from typing import Mapping

import numpy as np
from helpers import SimClock

from common.payloads import MissionMsg, ObstaclesMsg, Received, StateMsg
from common.vocabulary import WheelFeedback


class MirrorMotor:
    """Mock hardware: wheels follow the last command exactly while armed (ideal drivers)."""

    def __init__(self, clock: SimClock):
        self.clock = clock
        self.armed = False
        self.vel = np.zeros(2)            # right, left [rev/s]
        self.pos = np.zeros(2)            # [rev]
        self.last = clock.monotonic()
        self.commands = 0
        self.silent = False               # simulate lost feedback
        self.errors: tuple[str, ...] = ()

    def advance(self) -> None:
        now = self.clock.monotonic()
        self.pos += self.vel * (now - self.last)
        self.last = now

    def arm(self) -> None:
        self.armed = True

    def disarm(self) -> None:
        self.advance()
        self.armed = False
        self.vel[:] = 0.0

    def command(self, right: float, left: float) -> None:
        self.advance()
        self.commands += 1
        if self.armed:
            self.vel[:] = (right, left)

    def feedback(self) -> WheelFeedback | None:
        self.advance()
        if self.silent:
            return None
        # numpy scalars, as drivers may hand them (the agent must take them as floats)
        pos, vel = (self.pos[0], self.pos[1]), (self.vel[0], self.vel[1])
        return WheelFeedback(pos, vel, 0.0, self.armed, self.errors)

    def clear_errors(self) -> None:
        self.errors = ()


class SharedSwarm:
    """One in-memory 'network' that several agents publish to and read from."""

    def __init__(self, clock: SimClock):
        self.clock = clock
        self.states: dict[int, Received[StateMsg]] = {}
        self.mission_msg: MissionMsg | None = None
        self.obstacle_msgs: dict[int, ObstaclesMsg] = {}

    def port(self, robot_id: int) -> "SwarmView":
        return SwarmView(self, robot_id)


class SwarmView:
    def __init__(self, net: SharedSwarm, robot_id: int):
        self.net, self.robot_id = net, robot_id
        self.published: list[StateMsg] = []

    def publish(self, state: StateMsg) -> None:
        self.published.append(state)
        self.net.states[state.robot_id] = Received(state, self.net.clock.wall())

    def neighbours(self) -> Mapping[int, Received[StateMsg]]:
        return MappingProxyType({k: v for k, v in self.net.states.items()
                                 if k != self.robot_id})

    def obstacles(self) -> ObstaclesMsg | None:
        return self.net.obstacle_msgs.get(self.robot_id)

    def mission(self) -> MissionMsg | None:
        return self.net.mission_msg
