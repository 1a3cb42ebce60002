"""Unicycle and differential-drive kinematics of one robot, in plain floats.

World frame ENU: x east [m], y north [m], heading theta [rad] from +x, counter-clockwise.
Unicycle: x' = v cos(theta), y' = v sin(theta), theta' = u. Wheel speeds omega [rad/s]
are positive when the wheel drives the robot forward. Agents, odometry and the SITL plant
run these interpreted; the batch simulator compiles the same source
(:mod:`firmware_sim.compiled`), so they use only floats and ``math``.
"""
from __future__ import annotations

import math

TWO_PI = 2.0 * math.pi


def wrap_angle(angle: float) -> float:
    """Wrap an angle [rad] into (-pi, pi]."""
    wrapped = (angle + math.pi) % TWO_PI - math.pi
    return math.pi if wrapped == -math.pi else wrapped


def arc_step(x: float, y: float, theta: float, dist: float, dtheta: float
             ) -> tuple[float, float, float]:
    """The pose after an exact arc of length ``dist`` [m] turning by ``dtheta`` [rad].

    Constant (v, u) over dt is ``arc_step(x, y, theta, v * dt, u * dt)``. Exact for any
    turn, straight lines included (the chord's sinc by its series below 1e-4 rad; error
    < 1e-17).
    """
    half = 0.5 * dtheta
    sinc = 1.0 - half * half / 6.0 if abs(half) < 1e-4 else math.sin(half) / half
    mid = theta + half
    return (x + dist * sinc * math.cos(mid), y + dist * sinc * math.sin(mid),
            wrap_angle(theta + dtheta))


def body_velocity(omega_right: float, omega_left: float, wheel_radius: float,
                  wheel_base: float) -> tuple[float, float]:
    """(v [m/s], u [rad/s]) from wheel speeds [rad/s]."""
    v = 0.5 * wheel_radius * (omega_right + omega_left)
    u = wheel_radius * (omega_right - omega_left) / wheel_base
    return v, u


def wheel_command(v: float, u: float, wheel_radius: float, wheel_base: float,
                  speed_limit_rev_s: float) -> tuple[float, float]:
    """Saturated (right, left) wheel set-points [rev/s] for (v [m/s], u [rad/s]).

    Both wheels are scaled by one common factor so neither exceeds the limit: keeping their
    ratio keeps the curvature u/v of the commanded path (clamping each wheel separately
    would bend it).
    """
    half = 0.5 * wheel_base * u
    wr, wl = (v + half) / wheel_radius, (v - half) / wheel_radius
    limit = TWO_PI * speed_limit_rev_s
    peak = max(abs(wr), abs(wl))
    scale = limit / peak if peak > limit else 1.0
    return wr * scale / TWO_PI, wl * scale / TWO_PI
