"""Neighbour states as the law uses them: extrapolated to now, stale ones held still.

A neighbour's state (x, y, theta [m, m, rad], v [m/s], u [rad/s]) arrives up to one period
plus transport latency late. Before the law uses it, it is moved forward along its own arc
to the current time, for at most ``staleness`` seconds; a neighbour older than that is a
robot that may have stopped, so it is kept, conservatively, as a static obstacle at its last
known position (no extrapolation).

One agent sees a few dozen states per period, so this runs in plain floats (numpy's cost
per call would dominate); the arc is :func:`agent.kinematics.arc_step`, the same exact arc
the simulators integrate.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterable, Protocol

from agent.kinematics import arc_step


class NeighbourState(Protocol):
    """What a neighbour reports (common.payloads.StateMsg has it). Read-only members: the
    messages are frozen dataclasses."""

    @property
    def robot_id(self) -> int: ...
    @property
    def stamp(self) -> float: ...       # s, UNIX time
    @property
    def x(self) -> float: ...           # m
    @property
    def y(self) -> float: ...           # m
    @property
    def theta(self) -> float: ...       # rad
    @property
    def v(self) -> float: ...           # m/s
    @property
    def u(self) -> float: ...           # rad/s


@dataclass
class InRange:
    """Neighbours within range of a robot: positions [m] at ``now``, as the law takes them."""

    fresh_x: list[float] = field(default_factory=list)  # extrapolated to now
    fresh_y: list[float] = field(default_factory=list)
    fresh_id: list[int] = field(default_factory=list)   # their robot ids
    stale_x: list[float] = field(default_factory=list)  # at their last position
    stale_y: list[float] = field(default_factory=list)
    stale: list[int] = field(default_factory=list)   # index of each stale one in the input
    ages: list[float] = field(default_factory=list)  # s, now - stamp of each fresh one
    fresh: list[int] = field(default_factory=list)   # index of each fresh one in the input


def extrapolate(x: float, y: float, theta: float, v: float, u: float, age: float,
                staleness: float) -> tuple[float, float, bool]:
    """(x, y, stale): where a neighbour reported at (x, y, theta) [m, m, rad] moving at
    (v [m/s], u [rad/s]) ``age`` [s] ago is now, moved along its arc; at its reported
    position and stale when older than ``staleness`` [s]. A negative age (clock skew) is 0.
    Plain floats: the batch simulator compiles this very function."""
    if age > staleness:
        return x, y, True
    dt = 0.0 if 0.0 > age else age      # max(age, 0.0), cheaper interpreted
    px, py, _ = arc_step(x, y, theta, v * dt, u * dt)
    return px, py, False


def in_range(states: Iterable[NeighbourState], x: float, y: float, now: float,
             staleness: float, reach: float) -> InRange:
    """The neighbours within ``reach`` [m] of (x, y) at time ``now`` [s].

    Fresh ones are moved along their arcs to ``now``; ones older than ``staleness`` [s] are
    stale and stay where they were last seen. A stamp in the future (clock skew) is treated
    as age 0.
    """
    out = InRange()
    for i, m in enumerate(states):
        age = now - m.stamp
        # out of reach wherever its arc took it (an arc is at least as long as its chord;
        # a micrometre for rounding): not moved at all
        travel = 0.0 if age > staleness else abs(m.v) * (0.0 if 0.0 > age else age)
        if math.hypot(m.x - x, m.y - y) - travel > reach + 1e-6:
            continue
        px, py, stale = extrapolate(m.x, m.y, m.theta, m.v, m.u, age, staleness)
        if math.hypot(px - x, py - y) <= reach:
            if stale:
                out.stale_x.append(px)
                out.stale_y.append(py)
                out.stale.append(i)
            else:
                out.fresh_x.append(px)
                out.fresh_y.append(py)
                out.fresh_id.append(m.robot_id)
                out.ages.append(age)
                out.fresh.append(i)
    return out
