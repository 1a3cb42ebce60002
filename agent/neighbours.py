"""Neighbour states as a robot's period reads them: the newest report heard from each robot,
and where a report puts its robot now.

A neighbour's state (x, y, theta [m, m, rad], v [m/s], u [rad/s], its place exchange)
arrives up to one period plus transport latency late. Before the law uses it, it is moved
forward along its own arc to the current time, for at most ``staleness`` seconds; a
neighbour older than that is a robot that may have stopped, so it is kept, conservatively,
as a static obstacle at its last known position (no extrapolation).

Plain floats and sequences (lists in an agent, arrays compiled); the arc is
:func:`agent.kinematics.arc_step`, the same exact arc the simulators integrate.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

from agent.kinematics import arc_step

if TYPE_CHECKING:
    from agent.avoidance import FloatBuf, IntBuf


class Reports(NamedTuple):
    """The newest state a robot has heard from each robot, one column per field and one
    row per robot (its own row, if any, is passed over). A row whose stamp is -inf holds
    no report yet."""

    robot: IntBuf       # robot id
    stamp: FloatBuf     # s, when it was stamped (the clock of the robot's period)
    x: FloatBuf         # m
    y: FloatBuf         # m
    theta: FloatBuf     # rad
    v: FloatBuf         # m/s, its command
    u: FloatBuf         # rad/s
    slot: IntBuf        # its place exchange (agent.exchange.Exchange): slot, partner and
    partner: IntBuf     # other (NOBODY: none)
    other: IntBuf


def extrapolate(x: float, y: float, theta: float, v: float, u: float, age: float,
                staleness: float) -> tuple[float, float, bool]:
    """(x, y, stale): where a neighbour reported at (x, y, theta) [m, m, rad] moving at
    (v [m/s], u [rad/s]) ``age`` [s] ago is now, moved along its arc; at its reported
    position and stale when older than ``staleness`` [s]. A negative age (clock skew) is 0."""
    if age > staleness:
        return x, y, True
    if age <= 0.0:                      # where it was reported: no arc (x + 0 is x)
        return x, y, False
    px, py, _ = arc_step(x, y, theta, v * age, u * age)
    return px, py, False
