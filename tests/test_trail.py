"""The robot's own motion over the last seconds (agent.trail), which the governor pairs
with a neighbour's data of that age: an agent's Trail, and the ring the period reads."""
import bisect
import math
import random

import pytest

from agent.trail import (
    TIME_TOL,
    OwnPath,
    Splits,
    Trail,
    at_or_before,
    own_motion,
    path_since,
)


def blank(pieces: int) -> tuple[Splits, list[int]]:
    """Empty splits of ``pieces`` and a fresh key."""
    return Splits(*([0.0] * pieces for _ in Splits._fields)), [-1] * (2 * pieces)


def splits(path: OwnPath, start: float, span: float, pieces: int) -> Splits:
    out, key = blank(pieces)
    own_motion(path, start, span, key, out)
    return out


def since(trail: Trail, t: float) -> float:
    """The path [m] from the position at or before t [s] to the newest."""
    return path_since(trail.path(), t)[0]


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
    assert trail.path().n <= 2 * 50 + 2                  # trimmed, not growing
    # a jump of the estimate (a fix) counts as travel
    trail.record(10.0, 9.99, 3.0)
    assert since(trail, 9.99) == pytest.approx(3.0)
    assert not math.isnan(since(trail, 0.0))


def test_the_splits_of_an_age_give_the_motion_since_each_piece_s_start_and_end():
    trail = Trail(span=1.0)
    assert splits(trail.path(), 0.0, 0.3, 4)[:6] == ([0.0] * 4,) * 6   # nothing yet
    for k, (x, y) in enumerate([(0, 0), (3, 4), (3, 4), (6, 8), (6, 0)]):
        trail.record(0.1 * k, x, y)
    rows = splits(trail.path(), 0.05, 0.3, 3)
    assert rows.walked == [since(trail, 0.05), since(trail, 0.15), since(trail, 0.25)]
    assert rows.walked == pytest.approx([18.0, 13.0, 13.0])
    # from the first position at or after each piece's end: 0.2 (3, 4), 0.3 (6, 8), 0.4
    assert rows.walked_end == pytest.approx([13.0, 8.0, 0.0])
    # the newest position (6, 0) less that at each start: (0, 0), (3, 4), (3, 4)
    assert rows.start_x == pytest.approx([6.0, 3.0, 3.0])
    assert rows.start_y == pytest.approx([0.0, -4.0, -4.0])
    # and at each end: (3, 4), (6, 8), (6, 0)
    assert rows.end_x == pytest.approx([3.0, 0.0, 0.0])
    assert rows.end_y == pytest.approx([-4.0, -8.0, 0.0])
    # what the governor derives (agent.trail.trail_motion): the displacements' lengths,
    # the half minor axis of the ellipse of where the robot was within each piece (5 m
    # walked between foci 5 m apart, (0, 0) and (3, 4), then (3, 4) and (6, 8): a segment;
    # 13 m walked from (3, 4) to (6, 0), foci 5 m apart: 6 m), and whether the next piece
    # dominates (none here: each moved otherwise)
    assert rows.start_len == pytest.approx([6.0, 5.0, 5.0])
    assert rows.end_len == pytest.approx([5.0, 8.0, 0.0])
    assert rows.bulge == pytest.approx([0.0, 0.0, 6.0])
    assert rows.dominated == [0.0, 0.0, 0.0]


def test_stamps_between_the_same_records_share_their_splits_and_others_do_not():
    """Neighbours stamped at different times whose pieces start and end between the same
    recorded positions find the splits already made (the key says so, the splits are left
    as they are); a piece that crosses a record makes them afresh."""
    trail = Trail(span=1.0)
    for k in range(6):
        trail.record(0.02 * k, 0.3 * k, 0.01 * k * k)
    path = trail.path()
    out, key = blank(4)
    own_motion(path, 0.0301, 0.0699, key, out)
    first = [list(row) for row in out]
    out.walked[0] = -1.0                                  # marks a computation
    own_motion(path, 0.0312, 0.0688, key, out)           # every piece's ends: the same
    assert out.walked[0] == -1.0
    own_motion(path, 0.0402, 0.0598, key, out)           # its first piece starts after 0.04
    assert out.walked[0] != -1.0
    assert [list(row) for row in out] == [list(row) for row in splits(path, 0.0402,
                                                                       0.0598, 4)]
    assert [list(row) for row in splits(path, 0.0312, 0.0688, 4)] == first
    key[0] = -1                                          # the period starts afresh
    out.walked[0] = -1.0
    own_motion(path, 0.0402, 0.0598, key, out)
    assert out.walked[0] != -1.0


def test_path_since_is_the_first_value_of_the_splits_bit_for_bit():
    """The governor's cheap bound takes path_since for every neighbour and the splits only
    for the discs it computes: both must agree exactly, at and between recorded times."""
    rng = random.Random(3)
    trail = Trail(1.0)
    assert since(trail, 0.0) == splits(trail.path(), 0.0, 0.1, 4).walked[0] == 0.0
    t = 0.0
    for _ in range(300):
        t += rng.choice((0.01, 0.02, 0.013))
        trail.record(t, rng.uniform(-5, 5), rng.uniform(-5, 5))
        for start in (t - 0.5, t - 0.02, t - rng.uniform(0, 0.7), t, t - 0.013):
            path = trail.path()
            walked, lo, hi = path_since(path, start)
            assert walked == splits(path, start, t - start, 4).walked[0]
            # every time between the same records has that path (the governor asks once)
            for other in (lo - TIME_TOL, 0.5 * (lo + hi) - TIME_TOL, hi - 2 * TIME_TOL):
                if math.isfinite(other):
                    assert path_since(path, other)[0] == walked


def test_a_boundary_at_a_recorded_time_takes_that_record_both_ways():
    """A piece starting exactly at a recorded time starts from that position; one ending
    exactly at a recorded time ends at that position, not the next."""
    trail = Trail(span=10.0)
    for k in range(5):
        trail.record(0.25 * k, float(k * k), 0.0)        # path 0, 1, 4, 9, 16
    rows = splits(trail.path(), 0.25, 0.5, 2)             # boundaries 0.25, 0.5, 0.75
    assert rows.walked == [15.0, 12.0]                    # since the records at 0.25, 0.5
    assert rows.walked_end == [12.0, 7.0]                 # since the records at 0.5, 0.75


def test_the_search_finds_what_a_bisection_finds_on_uneven_times():
    """at_or_before starts where evenly spaced records would put the time and walks from
    there, and the splits' boundaries walk on from it: on ticks that jitter, stall and
    burst (records at one time too) they find the records a bisection of the times finds,
    the last at or before each piece's start and the first at or after its end."""
    rng = random.Random(5)
    for _ in range(200):
        t, times = 0.0, []
        for _ in range(rng.randint(1, 60)):
            t += rng.choice((0.02, 0.02 + rng.uniform(-0.01, 0.01), 0.3, 1e-4, 0.0))
            times.append(t)
        n = len(times)
        path = OwnPath(times, [0.0] * n, [0.0] * n, [0.0] * n, 0, n, n)
        for when in [rng.uniform(-0.1, t + 0.1) for _ in range(20)] + times:
            assert at_or_before(path, when) == max(bisect.bisect_right(times, when) - 1, 0)
            span = rng.choice((0.0, 0.013, rng.uniform(0.0, 0.6)))
            out, key = blank(4)
            own_motion(path, when, span, key, out)
            edges = [when + span * k / 4 for k in range(5)]
            assert key[0::2] == [max(bisect.bisect_right(times, e) - 1, 0) for e in edges[:4]]
            assert key[1::2] == [min(bisect.bisect_left(times, e), n - 1) for e in edges[1:]]


def test_a_ring_reads_as_its_records_oldest_first():
    """The batch simulator's ring (first record at ``first``, wrapped): the same answers
    as the same records kept in order."""
    times = [0.02 * k for k in range(7, 17)]
    x = [float(k * k) for k in range(10)]
    walked = [float(k) for k in range(10)]
    ordered = OwnPath(times, x, [0.0] * 10, walked, 0, 10, 10)
    shift = 4                                             # stored from index 4 on, wrapped
    t_r, x_r, y_r, w_r = (col[-shift:] + col[:-shift] for col in (times, x, [0.0] * 10, walked))
    ring = OwnPath(t_r, x_r, y_r, w_r, shift, 10, 10)
    for start, span in ((0.15, 0.1), (0.2, 0.12), (0.0, 0.5), (0.33, 0.0)):
        assert list(splits(ring, start, span, 4)) == list(splits(ordered, start, span, 4))
        assert path_since(ring, start) == path_since(ordered, start)
