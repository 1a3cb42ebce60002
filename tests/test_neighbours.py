import math
from types import SimpleNamespace

import numpy as np
import pytest

from agent.kinematics import integrate_arc
from agent.neighbours import in_range


def state(stamp, x, y, theta, v, u):
    return SimpleNamespace(stamp=stamp, x=x, y=y, theta=theta, v=v, u=u)


def test_fresh_neighbours_are_moved_along_their_arcs():
    got = in_range([state(9.9, 0.0, 0.0, 0.0, 2.0, 0.0),          # straight east at 2 m/s
                    state(9.0, 1.0, 0.0, math.pi / 2, math.pi / 2, math.pi / 2)],  # quarter/s
                   x=0.0, y=0.0, now=10.0, staleness=1.5, reach=10.0)
    assert got.stale == []
    assert got.fresh[0] == pytest.approx((0.2, 0.0))
    assert got.fresh[1] == pytest.approx((0.0, 1.0))            # centre (0, 0), radius 1
    assert got.ages == pytest.approx([0.1, 1.0])


def test_the_arc_is_the_simulations_arc():
    rng = np.random.default_rng(3)
    for x, y, th, v, u, age in rng.uniform(-2.0, 2.0, (50, 6)):
        age = abs(age) / 4.0
        got = in_range([state(10.0 - age, x, y, th, v, u)], 0.0, 0.0, 10.0, 1.0, 100.0)
        want = integrate_arc(np.array([x, y, th]), v, u, age)[:2]
        assert got.fresh[0] == pytest.approx(tuple(want), abs=1e-12)


def test_stale_neighbours_stay_where_they_were_last_seen():
    got = in_range([state(1.0, 3.0, 4.0, 0.0, 5.0, 1.0)], 0.0, 0.0, now=2.0, staleness=0.5,
                   reach=10.0)
    assert got.fresh == [] and got.ages == []
    assert got.stale == [pytest.approx((3.0, 4.0))]


def test_future_stamps_are_not_extrapolated_backwards():
    got = in_range([state(5.0, 0.0, 0.0, 0.0, 1.0, 0.0)], 0.0, 0.0, 4.0, 0.5, 10.0)
    assert got.fresh == [pytest.approx((0.0, 0.0))]


def test_only_neighbours_within_reach_after_extrapolation():
    # 2.95 m away moving away at 1 m/s for 0.1 s: 3.05 m, out of a 3 m reach
    moving_away = state(9.9, 2.95, 0.0, 0.0, 1.0, 0.0)
    # 3.05 m away moving closer: 2.95 m, in range
    closing = state(9.9, -3.05, 0.0, 0.0, 1.0, 0.0)
    stale_far = state(0.0, 0.0, 3.5, 0.0, 0.0, 0.0)
    stale_near = state(0.0, 0.0, 2.5, 0.0, 0.0, 0.0)
    got = in_range([moving_away, closing, stale_far, stale_near], 0.0, 0.0, 10.0, 0.5, 3.0)
    assert got.fresh == [pytest.approx((-2.95, 0.0))]
    assert got.stale == [pytest.approx((0.0, 2.5))]
