"""Names every layer shares: the law's modes, the agent's modes, the state flags and what the
wheel drivers report."""
from __future__ import annotations

import enum
from dataclasses import dataclass


class Mode(enum.IntEnum):
    """The law's mode in one period (docs/controller.md)."""

    TRACK = 0
    AVOID = 1
    ROTATE = 2


class AgentMode(enum.Enum):
    """The agent's mode: drivers idle, standing still, or following the law."""

    DISARMED = "DISARMED"
    HOLD = "HOLD"
    FORMATION = "FORMATION"


class StateFlags(enum.IntFlag):
    """Bits of a published state (common.payloads.StateMsg)."""

    ARMED = 1
    HOLD = 2          # commanded to stand still
    FAILSAFE = 4      # a timeout or fault put the agent in its safe state
    GOVERNED = 8      # the safety governor lowered the speed this period
    DEADLOCKED = 16   # no progress toward the reference (agent.progress)


@dataclass(frozen=True)
class WheelFeedback:
    """What the two wheel drivers last reported."""

    pos_rev: tuple[float, float]      # (right, left) encoder positions [rev], + forward, at
    #                                   the newer estimate's arrival
    vel_rev_s: tuple[float, float]    # (right, left) encoder velocities [rev/s]
    age: float                        # s since the older of the two encoder estimates
    closed_loop: bool                 # both axes in CLOSED_LOOP_CONTROL
    errors: tuple[str, ...]           # names of the active axis errors, both axes
