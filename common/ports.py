"""The seams between the agent and the world: what it needs from its links.

The agent depends only on these protocols; the process wiring (agent.process) hands in the
real implementations (python-can + ODrive drivers, a Zenoh session) and tests hand in fakes,
so SITL and hardware differ only in what is injected.
"""
from __future__ import annotations

from typing import Mapping, Protocol

from common.payloads import FixMsg, MissionMsg, ObstaclesMsg, Received, StateMsg
from common.vocabulary import WheelFeedback


class MotorPort(Protocol):
    """The host side of the robot's two wheel drivers."""

    def arm(self) -> None: ...                          # velocity mode, limits, closed loop
    def disarm(self) -> None: ...                       # zero velocity, then IDLE
    def command(self, right_rev_s: float, left_rev_s: float) -> None: ...
    def feedback(self) -> WheelFeedback | None: ...     # drains the bus; None before any
    def clear_errors(self) -> None: ...


class SwarmPort(Protocol):
    """The agent's view of the swarm: its neighbours, obstacles and the mission."""

    def publish(self, state: StateMsg) -> None: ...
    def neighbours(self) -> Mapping[int, Received[StateMsg]]: ...
    def obstacles(self) -> ObstaclesMsg | None: ...
    def mission(self) -> MissionMsg | None: ...


class FixPort(Protocol):
    """The robot's pose fixes from an external source (motion capture), when it has one."""

    def fix(self) -> FixMsg | None: ...     # the newest, by capture time; None before any
