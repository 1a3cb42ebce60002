import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.kinematics import (body_velocity, integrate_arc, saturate_wheels, wheel_command,
                              wheel_commands, wheel_speeds, wrap_angle, wrap_scalar)


def test_wrap_angle_range():
    x = np.array([0.0, math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 7.0, -7.0])
    w = wrap_angle(x)
    assert np.all(w > -math.pi) and np.all(w <= math.pi)
    assert w[1] == math.pi and w[2] == math.pi
    assert np.allclose(np.cos(w), np.cos(x)) and np.allclose(np.sin(w), np.sin(x))


def test_arc_straight_and_full_circle():
    p = integrate_arc(np.array([1.0, 2.0, math.pi / 2]), 3.0, 0.0, 2.0)
    assert p == pytest.approx([1.0, 8.0, math.pi / 2])
    full = integrate_arc(np.array([0.0, 0.0, 0.3]), 2.0, 2 * math.pi, 1.0)
    assert full[:2] == pytest.approx([0.0, 0.0], abs=1e-12)


def test_arc_matches_fine_euler_integration():
    v, u, dt = 1.7, -0.9, 1.3
    pose = np.array([0.5, -1.0, 2.0])
    fine = pose.copy()
    h = dt / 5000
    for _ in range(5000):                                  # midpoint rule, error O(h^2)
        mid = fine[2] + 0.5 * h * u
        fine = fine + h * np.array([v * math.cos(mid), v * math.sin(mid), u])
    assert integrate_arc(pose, v, u, dt) == pytest.approx([fine[0], fine[1],
                                                           float(wrap_angle(fine[2]))], abs=1e-6)


def test_wheel_speeds_round_trip():
    wr, wl = wheel_speeds(np.array([1.0, -2.0]), np.array([0.5, 3.0]), 0.2, 0.8)
    v, u = body_velocity(wr, wl, 0.2, 0.8)
    assert v == pytest.approx([1.0, -2.0]) and u == pytest.approx([0.5, 3.0])


@given(st.floats(-20, 20), st.floats(-10, 10))
def test_saturation_keeps_curvature_and_limit(v, u):
    r_rev, l_rev = wheel_commands(np.array([v]), np.array([u]), 0.2, 0.8, 10.0)
    assert max(abs(r_rev[0]), abs(l_rev[0])) <= 10.0 + 1e-9
    v2, u2 = body_velocity(2 * math.pi * r_rev, 2 * math.pi * l_rev, 0.2, 0.8)
    # same direction of (v, u): the curvature u/v is kept
    assert v2[0] * u - u2[0] * v == pytest.approx(0.0, abs=1e-9)
    assert v2[0] * v >= 0 and u2[0] * u >= 0


def test_saturation_only_when_needed():
    wr, wl = saturate_wheels(np.array([5.0, 100.0]), np.array([-5.0, 50.0]), 62.8)
    assert wr == pytest.approx([5.0, 62.8]) and wl == pytest.approx([-5.0, 31.4])


@given(st.floats(-50, 50), st.floats(-50, 50), st.floats(-4, 4), st.floats(-5, 5),
       st.floats(-7, 7))
def test_scalar_arc_step_is_integrate_arc(x, y, theta, dist, dtheta):
    from agent.kinematics import arc_step
    want = integrate_arc(np.array([x, y, theta]), np.float64(dist), np.float64(dtheta), 1.0)
    got = arc_step(x, y, theta, dist, dtheta)
    assert np.allclose(got[:2], want[:2], atol=1e-9)
    assert abs(wrap_angle(got[2] - want[2])) < 1e-9 and -np.pi < got[2] <= np.pi


@given(st.floats(-50, 50), st.floats(-50, 50))
def test_one_robots_wheel_command_equals_the_vectorised_one(v, u):
    want = wheel_commands(np.array([v]), np.array([u]), 0.1, 0.5, 5.0)
    got = wheel_command(v, u, 0.1, 0.5, 5.0)
    assert got == pytest.approx((want[0][0], want[1][0]), rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("v, u", [(math.nan, 0.0), (0.0, math.nan), (math.inf, 0.0),
                                  (1.0, -math.inf)])
def test_one_robots_wheel_command_is_not_finite_for_bad_input(v, u):
    """The agent turns such a command into zero velocity; it must not look finite."""
    assert not all(map(math.isfinite, wheel_command(v, u, 0.1, 0.5, 5.0)))


@given(st.floats(-1e4, 1e4))
def test_wrap_scalar_equals_wrap_angle(angle):
    assert wrap_scalar(angle) == float(wrap_angle(angle))
