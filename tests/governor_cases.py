"""What the safety governor's tests share (tests/test_discs.py, tests/test_governor.py): a
neighbour's limits, the governor's speed limits among a few hazards, and a trail and a
neighbour drawn at random."""
from __future__ import annotations

import math
from collections.abc import Sequence

from hypothesis import strategies as st

from agent.governor import NO_GAPS, Braking, Limits, fold_hazard, frame_limits, limit_frame
from agent.trail import SPLITS, Splits, Trail, own_motion

A, ACCEL, TOP, STALE, STOP = 1.0, 2.0, 3.0, 0.5, 0.12


def speed_limits(x: float, y: float, theta: float, v_now: float, u_now: float,
                 haz_x: Sequence[float], haz_y: Sequence[float], haz_r: Sequence[float],
                 haz_half: Sequence[float], haz_moving: Sequence[float], accel: float,
                 period: float, latency: float, turn_rate: float, wheel_base: float,
                 top_speed: float = math.inf, margin: float = 0.0,
                 turn_up: float = math.inf) -> Limits:
    """The :class:`agent.governor.Limits` (forward and backward speed limits [m/s], room
    [m]) of a robot at (x, y, theta) [m, m, rad] moving at (v_now [m/s], u_now [rad/s])
    among hazards (centre; exclusion radii [m] of the whole free distance and of the half
    this robot owns; 1 for a neighbour that moves, 0 for a static disc), stopping as
    :class:`agent.governor.Braking` (accel, period, latency, turn_rate, wheel_base,
    top_speed, margin, turn_up) says: :func:`agent.governor.limit_frame`, each hazard folded
    in (:func:`agent.governor.fold_hazard`), then :func:`agent.governor.frame_limits`."""
    frame = limit_frame(theta, v_now, u_now, Braking(accel, period, latency, turn_rate,
                                                     wheel_base, top_speed, margin, turn_up))
    gaps = NO_GAPS
    for h in range(len(haz_r)):
        gaps = fold_hazard(gaps, frame, haz_x[h] - x, haz_y[h] - y, haz_r[h], haz_half[h],
                           haz_moving[h])
    return frame_limits(gaps, frame)


def walk(lengths: list[float], turn: float) -> Splits:
    """The splits (agent.trail.own_motion) of a robot that walked the pieces ``lengths``
    [m], one a second (the stamp's first), turning by ``turn`` [rad] between them."""
    trail, x, y, heading = Trail(10.0), 0.0, 0.0, 0.0
    trail.record(0.0, x, y)
    for k, d in enumerate(lengths):
        x, y, heading = x + d * math.cos(heading), y + d * math.sin(heading), heading + turn
        trail.record(k + 1.0, x, y)
    out = Splits(*([0.0] * SPLITS for _ in Splits._fields))
    own_motion(trail.path(), 0.0, float(len(lengths)), [-1] * (2 * SPLITS), out)
    return out


# a neighbour's report (rel_x, rel_y, heading, speed, turn rate, age) and this robot's
# walk since (its pieces and the turn between them, :func:`walk`)
neighbour = st.tuples(st.floats(-9.0, 9.0), st.floats(-9.0, 9.0), st.floats(-4.0, 4.0),
                      st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(0.0, 0.6),
                      st.lists(st.floats(0.0, 0.5), min_size=SPLITS, max_size=SPLITS),
                      st.floats(-1.0, 1.0))
