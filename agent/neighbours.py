"""Neighbour states as the law uses them: extrapolated to now, stale ones held still.

A neighbour's state (x, y, theta [m, m, rad], v [m/s], u [rad/s]) arrives up to one period
plus transport latency late. Before the law uses it, it is moved forward along its own arc
to the current time, for at most ``staleness`` seconds; a neighbour older than that is a
robot that may have stopped, so it is kept, conservatively, as a static obstacle at its last
known position (no extrapolation).
"""
from __future__ import annotations

import numpy as np

from agent.kinematics import integrate_arc


def extrapolate(states: np.ndarray, stamps: np.ndarray, now: float, staleness: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """(positions (M, 2) [m] at ``now``, stale (M,) bool) for neighbour ``states`` (M, 5).

    ``stamps`` (M,) [s] are the states' timestamps on the same clock as ``now``. A stamp in
    the future (clock skew) is treated as age 0.
    """
    states = np.asarray(states, dtype=float).reshape(-1, 5)
    age = np.maximum(now - np.asarray(stamps, dtype=float), 0.0)
    stale = age > staleness
    dt = np.where(stale, 0.0, age)
    moved = integrate_arc(states[:, :3], states[:, 3], states[:, 4], dt)
    return moved[:, :2], stale
