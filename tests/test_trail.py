"""The robot's own path over the last seconds (agent.trail), which the governor counts in
full for a neighbour's data of that age."""
import math

import pytest

from agent.trail import Trail


def test_the_path_since_a_time_is_walked_from_the_position_at_or_before_it():
    trail = Trail(span=1.0)
    assert trail.since(0.0) == 0.0                       # nothing recorded yet
    for k, (x, y) in enumerate([(0, 0), (3, 4), (3, 4), (6, 8), (6, 0)]):
        trail.record(0.1 * k, x, y)
    assert trail.since(0.4) == 0.0                       # the newest position
    assert trail.since(0.35) == pytest.approx(8.0)       # from (6, 8): at or before
    assert trail.since(0.1) == pytest.approx(5.0 + 8.0)
    assert trail.since(-5.0) == pytest.approx(18.0)      # before the first: all of it


def test_it_keeps_its_span_and_no_more():
    trail = Trail(span=0.5)
    for k in range(1000):                                # 1 m/s along x, 100 Hz
        trail.record(0.01 * k, 0.01 * k, 0.0)
    assert trail.since(9.99 - 0.5) == pytest.approx(0.5)
    assert trail.since(9.99 - 0.25) == pytest.approx(0.25)
    assert len(trail._t) <= 2 * 50 + 2                   # trimmed, not growing
    # a jump of the estimate (a fix) counts as travel
    trail.record(10.0, 9.99, 3.0)
    assert trail.since(9.99) == pytest.approx(3.0)
    assert not math.isnan(trail.since(0.0))


def test_the_paths_since_the_splits_of_an_age_are_those_since_each_instant():
    trail = Trail(span=1.0)
    assert trail.since_each(0.0, 0.3, 4) == [0.0] * 4    # nothing recorded yet
    for k, (x, y) in enumerate([(0, 0), (3, 4), (3, 4), (6, 8), (6, 0)]):
        trail.record(0.1 * k, x, y)
    assert trail.since_each(0.05, 0.3, 3) == [trail.since(0.05), trail.since(0.15),
                                              trail.since(0.25)]
    assert trail.since_each(0.05, 0.3, 3) == pytest.approx([18.0, 13.0, 13.0])
