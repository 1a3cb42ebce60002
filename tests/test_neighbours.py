"""A neighbour's report moved along its arc to now (agent.neighbours.extrapolate)."""
import math

import pytest

from agent.kinematics import arc_step
from agent.neighbours import extrapolate


def test_fresh_neighbours_are_moved_along_their_arcs():
    assert extrapolate(0.0, 0.0, 0.0, 2.0, 0.0, 0.1, 1.5)[:2] == pytest.approx((0.2, 0.0))
    # a quarter turn a second for a second, radius 1 round (0, 0)
    x, y, stale = extrapolate(1.0, 0.0, math.pi / 2, math.pi / 2, math.pi / 2, 1.0, 1.5)
    assert (x, y) == pytest.approx((0.0, 1.0)) and not stale


def test_the_arc_is_the_simulations_arc():
    got = extrapolate(1.0, -2.0, 0.4, 1.5, -0.8, 0.25, 1.0)
    assert got[:2] == arc_step(1.0, -2.0, 0.4, 1.5 * 0.25, -0.8 * 0.25)[:2]


def test_stale_neighbours_stay_where_they_were_last_seen():
    assert extrapolate(3.0, 4.0, 0.0, 5.0, 1.0, 1.0, 0.5) == (3.0, 4.0, True)


def test_future_stamps_are_not_extrapolated_backwards():
    assert extrapolate(0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.5)[:2] == pytest.approx((0.0, 0.0))
