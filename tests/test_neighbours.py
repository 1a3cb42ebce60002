import math

import numpy as np
import pytest

from agent.neighbours import extrapolate


def test_fresh_neighbours_are_moved_along_their_arcs():
    states = np.array([[0.0, 0.0, 0.0, 2.0, 0.0],          # straight east at 2 m/s
                       [1.0, 0.0, math.pi / 2, math.pi / 2, math.pi / 2]])  # quarter circle/s
    pos, stale = extrapolate(states, np.array([9.9, 9.0]), now=10.0, staleness=1.5)
    assert not stale.any()
    assert pos[0] == pytest.approx([0.2, 0.0])
    assert pos[1] == pytest.approx([0.0, 1.0])              # centre (0, 0), radius 1


def test_stale_neighbours_stay_where_they_were_last_seen():
    states = np.array([[3.0, 4.0, 0.0, 5.0, 1.0]])
    pos, stale = extrapolate(states, np.array([1.0]), now=2.0, staleness=0.5)
    assert stale[0] and pos[0] == pytest.approx([3.0, 4.0])


def test_future_stamps_are_not_extrapolated_backwards():
    pos, _ = extrapolate(np.array([[0.0, 0.0, 0.0, 1.0, 0.0]]), np.array([5.0]), 4.0, 0.5)
    assert pos[0] == pytest.approx([0.0, 0.0])
