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


def test_the_reach_test_is_on_the_extrapolated_position_whatever_the_shortcut():
    """Robots far out of reach are passed over without moving them along their arcs; the
    outcome is that of moving every one and testing its distance, also for robots whose arc
    ends right at the reach (a chord is never longer than its arc)."""
    import random

    from agent.neighbours import extrapolate
    rng = random.Random(7)
    for _ in range(300):
        x, y, now, staleness, reach = rng.uniform(-5, 5), rng.uniform(-5, 5), 100.0, 0.5, 6.0
        states = []
        for i in range(20):
            age = rng.choice([rng.uniform(-0.05, 0.6), 0.5, 0.0])
            states.append(state(now - age, x + rng.uniform(-12, 12), y + rng.uniform(-12, 12),
                                rng.uniform(-4, 4), rng.uniform(-6, 6), rng.uniform(-3, 3), i))
        # and one whose arc ends exactly at the reach, from beyond it
        m = states[0]
        px, py, _ = extrapolate(m.x, m.y, m.theta, m.v, m.u, now - m.stamp, staleness)
        d = math.hypot(px - x, py - y)
        if d > 0:
            states[0] = state(m.stamp, m.x + (x - px) * (1 - reach / d),
                              m.y + (y - py) * (1 - reach / d), m.theta, m.v, m.u, 0)
        got = in_range(states, x, y, now, staleness, reach)
        want_fresh: list[tuple[float, float]] = []
        want_stale: list[tuple[float, float]] = []
        for m in states:
            px, py, is_stale = extrapolate(m.x, m.y, m.theta, m.v, m.u, now - m.stamp,
                                           staleness)
            if math.hypot(px - x, py - y) <= reach:
                (want_stale if is_stale else want_fresh).append((px, py))
        assert fresh(got) == want_fresh and stale(got) == want_stale
