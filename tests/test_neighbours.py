import math
from types import SimpleNamespace

import pytest

from agent.kinematics import arc_step
from agent.neighbours import in_range


def state(stamp, x, y, theta, v, u, robot_id=0):
    return SimpleNamespace(robot_id=robot_id, stamp=stamp, x=x, y=y, theta=theta, v=v, u=u)


def fresh(got):
    return list(zip(got.fresh_x, got.fresh_y))


def stale(got):
    return list(zip(got.stale_x, got.stale_y))


def test_fresh_neighbours_are_moved_along_their_arcs():
    got = in_range([state(9.9, 0.0, 0.0, 0.0, 2.0, 0.0),          # straight east at 2 m/s
                    state(9.0, 1.0, 0.0, math.pi / 2, math.pi / 2, math.pi / 2)],  # quarter/s
                   x=0.0, y=0.0, now=10.0, staleness=1.5, reach=10.0)
    assert stale(got) == []
    assert fresh(got)[0] == pytest.approx((0.2, 0.0))
    assert fresh(got)[1] == pytest.approx((0.0, 1.0))           # centre (0, 0), radius 1
    assert got.ages == pytest.approx([0.1, 1.0])


def test_the_arc_is_the_simulations_arc():
    got = in_range([state(9.75, 1.0, -2.0, 0.4, 1.5, -0.8)], 0.0, 0.0, 10.0, 1.0, 100.0)
    assert fresh(got) == [arc_step(1.0, -2.0, 0.4, 1.5 * 0.25, -0.8 * 0.25)[:2]]


def test_stale_neighbours_stay_where_they_were_last_seen():
    got = in_range([state(1.0, 3.0, 4.0, 0.0, 5.0, 1.0)], 0.0, 0.0, now=2.0, staleness=0.5,
                   reach=10.0)
    assert fresh(got) == [] and got.ages == []
    assert stale(got) == [(3.0, 4.0)]


def test_future_stamps_are_not_extrapolated_backwards():
    got = in_range([state(5.0, 0.0, 0.0, 0.0, 1.0, 0.0)], 0.0, 0.0, 4.0, 0.5, 10.0)
    assert fresh(got) == [pytest.approx((0.0, 0.0))]


def test_only_neighbours_within_reach_after_extrapolation():
    # 2.95 m away moving away at 1 m/s for 0.1 s: 3.05 m, out of a 3 m reach
    moving_away = state(9.9, 2.95, 0.0, 0.0, 1.0, 0.0)
    # 3.05 m away moving closer: 2.95 m, in range
    closing = state(9.9, -3.05, 0.0, 0.0, 1.0, 0.0)
    stale_far = state(0.0, 0.0, 3.5, 0.0, 0.0, 0.0)
    stale_near = state(0.0, 0.0, 2.5, 0.0, 0.0, 0.0)
    got = in_range([moving_away, closing, stale_far, stale_near], 0.0, 0.0, 10.0, 0.5, 3.0)
    assert fresh(got) == [pytest.approx((-2.95, 0.0))]
    assert stale(got) == [pytest.approx((0.0, 2.5))]
