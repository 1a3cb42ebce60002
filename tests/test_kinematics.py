import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.kinematics import arc_step, body_velocity, wheel_command, wrap_angle


@pytest.mark.parametrize("angle", [0.0, math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 7.0,
                                   -7.0])
def test_wrap_angle_range(angle):
    w = wrap_angle(angle)
    assert -math.pi < w <= math.pi
    assert math.cos(w) == pytest.approx(math.cos(angle))
    assert math.sin(w) == pytest.approx(math.sin(angle), abs=1e-12)


def test_wrap_angle_maps_minus_pi_to_pi():
    assert wrap_angle(-math.pi) == math.pi and wrap_angle(math.pi) == math.pi


def test_arc_straight_and_full_circle():
    assert arc_step(1.0, 2.0, math.pi / 2, 6.0, 0.0) == pytest.approx((1.0, 8.0, math.pi / 2))
    full = arc_step(0.0, 0.0, 0.3, 2.0, 2 * math.pi)
    assert full[:2] == pytest.approx((0.0, 0.0), abs=1e-12)


def test_arc_matches_fine_integration():
    v, u, dt = 1.7, -0.9, 1.3
    x, y, th = 0.5, -1.0, 2.0
    steps = 5000
    h = dt / steps
    for _ in range(steps):                                 # midpoint rule, error O(h^2)
        mid = th + 0.5 * h * u
        x, y, th = x + h * v * math.cos(mid), y + h * v * math.sin(mid), th + h * u
    got = arc_step(0.5, -1.0, 2.0, v * dt, u * dt)
    assert got == pytest.approx((x, y, wrap_angle(th)), abs=1e-6)


@given(st.floats(-4, 4), st.floats(-5, 5),
       st.floats(-1e-4, 1e-4).filter(lambda d: d == 0.0 or abs(d) > 1e-9))
def test_arc_is_continuous_through_a_straight_line(theta, dist, dtheta):
    """The chord's series below 1e-4 rad agrees with the closed form (where that is
    accurate: not for tiny turns, where sin(h)/h loses its digits)."""
    got = arc_step(0.0, 0.0, theta, dist, dtheta)
    half = dtheta / 2
    chord = dist * math.sin(half) / half if half else dist
    mid = theta + half
    assert got[:2] == pytest.approx((chord * math.cos(mid), chord * math.sin(mid)), abs=1e-12)


@given(st.floats(-20, 20), st.floats(-10, 10))
def test_saturation_keeps_curvature_and_limit(v, u):
    r_rev, l_rev = wheel_command(v, u, 0.2, 0.8, 10.0)
    assert max(abs(r_rev), abs(l_rev)) <= 10.0 + 1e-9
    v2, u2 = body_velocity(2 * math.pi * r_rev, 2 * math.pi * l_rev, 0.2, 0.8)
    # same direction of (v, u): the curvature u/v is kept
    assert v2 * u - u2 * v == pytest.approx(0.0, abs=1e-9)
    assert v2 * v >= 0 and u2 * u >= 0


def test_wheel_command_round_trip_below_the_limit():
    r_rev, l_rev = wheel_command(1.0, 0.5, 0.2, 0.8, 10.0)
    v, u = body_velocity(2 * math.pi * r_rev, 2 * math.pi * l_rev, 0.2, 0.8)
    assert (v, u) == pytest.approx((1.0, 0.5))


def test_saturation_only_when_needed():
    # wheels at 325 and -175 rad/s against a 10 rev/s limit: both scaled by one factor
    assert wheel_command(15.0, 125.0, 0.2, 0.8, 10.0) == pytest.approx((10.0,
                                                                        -10.0 * 175 / 325))
    slow = 1.0 / 0.2 / (2 * math.pi)                     # rev/s, well below the limit
    assert wheel_command(1.0, 0.0, 0.2, 0.8, 10.0) == pytest.approx((slow, slow))


@pytest.mark.parametrize("v, u", [(math.nan, 0.0), (0.0, math.nan), (math.inf, 0.0),
                                  (1.0, -math.inf)])
def test_wheel_command_is_not_finite_for_bad_input(v, u):
    """The agent turns such a command into zero velocity; it must not look finite."""
    assert not all(map(math.isfinite, wheel_command(v, u, 0.1, 0.5, 5.0)))
