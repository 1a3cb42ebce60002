"""Unicycle and differential-drive kinematics, vectorised over robots.

World frame ENU: x east [m], y north [m], heading theta [rad] from +x, counter-clockwise.
Unicycle: x' = v cos(theta), y' = v sin(theta), theta' = u. Wheel speeds omega [rad/s]
are positive when the wheel drives the robot forward.
"""
from __future__ import annotations

import math

import numpy as np

TWO_PI = 2.0 * np.pi


def wrap_angle(angle: np.ndarray | float) -> np.ndarray:
    """Wrap angles [rad] into (-pi, pi]."""
    wrapped = np.mod(np.asarray(angle, dtype=float) + np.pi, TWO_PI) - np.pi
    return np.where(wrapped == -np.pi, np.pi, wrapped)


def wrap_scalar(angle: float) -> float:
    """:func:`wrap_angle` of one float [rad], in plain floats."""
    wrapped = (angle + math.pi) % math.tau - math.pi
    return math.pi if wrapped == -math.pi else wrapped


def integrate_arc(pose: np.ndarray, v: np.ndarray, u: np.ndarray, dt: float | np.ndarray
                  ) -> np.ndarray:
    """Exact unicycle motion over ``dt`` [s] at constant (v [m/s], u [rad/s]).

    ``pose`` is (..., 3) = (x, y, theta); returns the new poses (theta wrapped). The arc is
    exact for any u, including u = 0 (straight line) without division by zero.
    """
    pose = np.asarray(pose, dtype=float)
    x, y, th = pose[..., 0], pose[..., 1], pose[..., 2]
    dth = u * dt
    half = 0.5 * dth
    # chord length = v dt * sin(dth/2) / (dth/2), its series below 1e-4 rad (error < 1e-17)
    small = np.abs(half) < 1e-4
    sinc = np.where(small, 1.0 - half * half / 6.0, np.sin(half) / np.where(small, 1.0, half))
    chord = v * dt * sinc
    mid = th + half
    out = np.empty(np.broadcast_shapes(pose.shape, np.shape(v) + (3,)))
    out[..., 0] = x + chord * np.cos(mid)
    out[..., 1] = y + chord * np.sin(mid)
    out[..., 2] = wrap_angle(th + dth)
    return out


def arc_step(x: float, y: float, theta: float, dist: float, dtheta: float
             ) -> tuple[float, float, float]:
    """One robot's :func:`integrate_arc` with dt = 1, in plain floats: the pose after an arc
    of length ``dist`` [m] turning by ``dtheta`` [rad] (odometry, every period)."""
    half = 0.5 * dtheta
    sinc = 1.0 - half * half / 6.0 if abs(half) < 1e-4 else math.sin(half) / half
    mid = theta + half
    return (x + dist * sinc * math.cos(mid), y + dist * sinc * math.sin(mid),
            wrap_scalar(theta + dtheta))


def wheel_speeds(v: np.ndarray, u: np.ndarray, wheel_radius: float, wheel_base: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(omega_right, omega_left) [rad/s] for body velocities v [m/s], u [rad/s]."""
    half = 0.5 * wheel_base * np.asarray(u, dtype=float)
    return (v + half) / wheel_radius, (v - half) / wheel_radius


def body_velocity(omega_right: np.ndarray, omega_left: np.ndarray, wheel_radius: float,
                  wheel_base: float) -> tuple[np.ndarray, np.ndarray]:
    """(v [m/s], u [rad/s]) from wheel speeds [rad/s]; inverse of :func:`wheel_speeds`."""
    v = 0.5 * wheel_radius * (omega_right + omega_left)
    u = wheel_radius * (omega_right - omega_left) / wheel_base
    return v, u


def saturate_wheels(omega_right: np.ndarray, omega_left: np.ndarray, limit: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Scale both wheels by one common factor so neither exceeds ``limit`` [rad/s].

    Keeping the ratio keeps the curvature u/v of the commanded path; clamping each wheel
    separately would bend it.
    """
    peak = np.maximum(np.abs(omega_right), np.abs(omega_left))
    scale = np.where(peak > limit, limit / np.maximum(peak, 1e-300), 1.0)
    return omega_right * scale, omega_left * scale


def wheel_commands(v: np.ndarray, u: np.ndarray, wheel_radius: float, wheel_base: float,
                   speed_limit_rev_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Saturated (right, left) wheel set-points [rev/s] for (v, u), curvature kept."""
    wr, wl = wheel_speeds(v, u, wheel_radius, wheel_base)
    wr, wl = saturate_wheels(wr, wl, TWO_PI * speed_limit_rev_s)
    return wr / TWO_PI, wl / TWO_PI


def wheel_command(v: float, u: float, wheel_radius: float, wheel_base: float,
                  speed_limit_rev_s: float) -> tuple[float, float]:
    """:func:`wheel_commands` for one robot in plain floats (an agent, every period)."""
    half = 0.5 * wheel_base * u
    wr, wl = (v + half) / wheel_radius, (v - half) / wheel_radius
    limit = TWO_PI * speed_limit_rev_s
    peak = max(abs(wr), abs(wl))
    scale = limit / peak if peak > limit else 1.0
    return wr * scale / TWO_PI, wl * scale / TWO_PI
