"""Braking: how far a robot goes before it stands, and how fast it may go to stop in a
distance.

A robot holds its command for a reaction time, then ramps each wheel to rest on its own
(as its drivers do should its agent die): the safety governor's braking model
(docs/controller.md A10). Plain floats: agents run this interpreted, the batch simulator
compiled.
"""
from __future__ import annotations

import math


def stopping(speed: float, accel: float, delay: float, turn: float = 0.0) -> float:
    """The longest path [m] of the centre of a robot moving at ``speed`` [m/s] with its
    wheels ``turn`` [m/s] apart (their ground speeds speed +- turn) that holds its command
    for ``delay`` [s], then ramps each wheel to rest on its own at ``accel`` [m/s^2]. The
    centre moves at the mean of the wheels' speeds: while both turn the same way the path
    is the mean of their braking distances, (v^2 + w^2) / (2 accel), more than
    v^2 / (2 accel) as the slower wheel stops first; when they turn opposite ways (a robot
    spinning) the mean holds at v until the slower one stops, then the faster one alone
    drags the centre: v w / accel. At 2 m/s^2, a robot at v = 0.6 m/s spinning with its
    wheels 1.5 m/s apart brakes over 0.45 m, not 0.09 m."""
    speed, turn = abs(speed), abs(turn)
    if math.isinf(accel):
        return speed * delay
    brake = (speed * speed + turn * turn if turn <= speed else 2.0 * speed * turn)
    return speed * delay + brake / (2.0 * accel)


def braking_speed(free: float, accel: float, reaction: float, turn: float = 0.0) -> float:
    """The largest v [m/s] whose path :func:`stopping` (v, accel, reaction, turn) fits in
    free [m] (0 when free <= 0); ``turn`` [m/s] as there, the wheels' half difference."""
    if free <= 0.0:
        return 0.0
    turn = abs(turn)
    if math.isinf(accel):
        return free / reaction if reaction > 0.0 else math.inf
    if reaction + turn / accel > 0.0:              # (a turn of a few ulp is no turn)
        slow = free / (reaction + turn / accel)    # v <= turn: path v reaction + v turn / a
        if slow <= turn:
            return slow
    rest = free - turn * turn / (2.0 * accel)      # v > turn: (v^2 + turn^2) / (2 a)
    return accel * (math.sqrt(reaction * reaction + 2.0 * rest / accel) - reaction)

