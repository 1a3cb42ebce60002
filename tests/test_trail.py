"""The robot's own motion over the last seconds (agent.trail), which the governor pairs
with a neighbour's data of that age."""
import math

import pytest

from agent.trail import Trail


def since(trail, t):
    """The path [m] from the position at or before t [s] to the newest."""
    return trail.splits(t, 0.0, 1)[0][0]


def test_the_path_since_a_time_is_walked_from_the_position_at_or_before_it():
    trail = Trail(span=1.0)
    assert since(trail, 0.0) == 0.0                       # nothing recorded yet
    for k, (x, y) in enumerate([(0, 0), (3, 4), (3, 4), (6, 8), (6, 0)]):
        trail.record(0.1 * k, x, y)
    assert since(trail, 0.4) == 0.0                       # the newest position
    assert since(trail, 0.35) == pytest.approx(8.0)       # from (6, 8): at or before
    assert since(trail, 0.1) == pytest.approx(5.0 + 8.0)
    assert since(trail, -5.0) == pytest.approx(18.0)      # before the first: all of it


def test_it_keeps_its_span_and_no_more():
    trail = Trail(span=0.5)
    for k in range(1000):                                # 1 m/s along x, 100 Hz
        trail.record(0.01 * k, 0.01 * k, 0.0)
    assert since(trail, 9.99 - 0.5) == pytest.approx(0.5)
    assert since(trail, 9.99 - 0.25) == pytest.approx(0.25)
    assert len(trail._t) <= 2 * 50 + 2                   # trimmed, not growing
    # a jump of the estimate (a fix) counts as travel
    trail.record(10.0, 9.99, 3.0)
    assert since(trail, 9.99) == pytest.approx(3.0)
    assert not math.isnan(since(trail, 0.0))


def test_the_splits_of_an_age_give_the_motion_since_each_piece_s_start_and_end():
    trail = Trail(span=1.0)
    assert trail.splits(0.0, 0.3, 4)[:6] == ([0.0] * 4,) * 6     # nothing recorded yet
    for k, (x, y) in enumerate([(0, 0), (3, 4), (3, 4), (6, 8), (6, 0)]):
        trail.record(0.1 * k, x, y)
    rows = trail.splits(0.05, 0.3, 3)
    paths, inner, east, north, end_east, end_north = rows[:6]
    assert paths == [since(trail, 0.05), since(trail, 0.15), since(trail, 0.25)]
    assert paths == pytest.approx([18.0, 13.0, 13.0])
    # from the first position at or after each piece's end: 0.2 (3, 4), 0.3 (6, 8), 0.4
    assert inner == pytest.approx([13.0, 8.0, 0.0])
    # the newest position (6, 0) less that at each start: (0, 0), (3, 4), (3, 4)
    assert east == pytest.approx([6.0, 3.0, 3.0])
    assert north == pytest.approx([0.0, -4.0, -4.0])
    # and at each end: (3, 4), (6, 8), (6, 0)
    assert end_east == pytest.approx([3.0, 0.0, 0.0])
    assert end_north == pytest.approx([-4.0, -8.0, 0.0])
    # what the governor derives (agent.governor.trail_motion): the displacements' lengths,
    # the half minor axis of the ellipse of where the robot was within each piece (5 m
    # walked between foci 5 m apart, (0, 0) and (3, 4), then (3, 4) and (6, 8): a segment;
    # 13 m walked from (3, 4) to (6, 0), foci 5 m apart: 6 m), and whether the next piece
    # dominates (none here: each moved otherwise)
    assert rows[6] == pytest.approx([6.0, 5.0, 5.0])
    assert rows[7] == pytest.approx([5.0, 8.0, 0.0])
    assert rows[8] == pytest.approx([0.0, 0.0, 6.0])
    assert rows[9] == [0.0, 0.0, 0.0]


def test_the_splits_asked_again_are_the_same_until_the_next_record():
    trail = Trail(span=1.0)
    trail.record(0.0, 0.0, 0.0)
    trail.record(0.1, 1.0, 0.0)
    first = trail.splits(0.0, 0.1, 2)
    assert trail.splits(0.0, 0.1, 2) is first            # neighbours of one stamp share it
    assert first[:2] == ([1.0, 1.0], [0.0, 0.0])
    trail.record(0.2, 3.0, 0.0)
    assert trail.splits(0.0, 0.1, 2)[:2] == ([3.0, 3.0], [2.0, 2.0])


def test_stamps_between_the_same_records_share_their_splits_and_others_do_not():
    """Neighbours stamped at different times whose pieces start and end between the same
    recorded positions get the same splits (as a trail asked only once gives them); a
    piece that crosses a record makes other splits."""
    def walked():
        trail = Trail(span=1.0)
        for k in range(6):
            trail.record(0.02 * k, 0.3 * k, 0.01 * k * k)
        return trail
    trail = walked()
    first = trail.splits(0.0301, 0.0699, 4)
    shared = trail.splits(0.0312, 0.0688, 4)          # every piece's ends: the same records
    assert shared is first
    assert walked().splits(0.0312, 0.0688, 4) == first
    other = trail.splits(0.0402, 0.0598, 4)            # its first piece starts after 0.04
    assert other is not first
    assert other == walked().splits(0.0402, 0.0598, 4) != first


def test_path_since_is_the_first_value_of_the_splits_bit_for_bit():
    """The governor's cheap bound takes path_since for every neighbour and the splits only
    for the discs it computes: both must agree exactly, at and between recorded times."""
    import random
    rng = random.Random(3)
    trail = Trail(1.0)
    assert trail.path_since(0.0) == trail.splits(0.0, 0.1, 4)[0][0] == 0.0
    t = 0.0
    for _ in range(300):
        t += rng.choice((0.01, 0.02, 0.013))
        trail.record(t, rng.uniform(-5, 5), rng.uniform(-5, 5))
        for start in (t - 0.5, t - 0.02, t - rng.uniform(0, 0.7), t, t - 0.013):
            assert trail.path_since(start) == trail.splits(start, t - start, 4)[0][0]


def test_a_boundary_at_a_recorded_time_takes_that_record_both_ways():
    """A piece starting exactly at a recorded time starts from that position; one ending
    exactly at a recorded time ends at that position, not the next."""
    trail = Trail(span=10.0)
    for k in range(5):
        trail.record(0.25 * k, float(k * k), 0.0)        # path 0, 1, 4, 9, 16
    rows = trail.splits(0.25, 0.5, 2)                     # boundaries 0.25, 0.5, 0.75
    assert rows[0] == [15.0, 12.0]                        # since the records at 0.25, 0.5
    assert rows[1] == [12.0, 7.0]                         # since the records at 0.5, 0.75
