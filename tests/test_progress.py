"""The deadlock detector (agent.progress), alone and in the agent."""
import pytest
from test_agent_node import make_swarm, run

from agent.progress import PROGRESS, ProgressWatch, tolerance
from common.vocabulary import AgentMode, StateFlags


def feed(watch, errors, tol=0.75, period=0.02):
    """Feed ``errors(t)`` for ``len`` seconds; the verdicts, one per period."""
    seconds, error = errors
    return [watch.update(k * period, error(k * period), tol)
            for k in range(int(seconds / period) + 1)]


def test_a_stuck_robot_is_deadlocked_after_the_window_only():
    verdicts = feed(ProgressWatch(10.0), (12.0, lambda t: 5.0))
    assert not any(verdicts[:int(9.9 / 0.02)]) and all(verdicts[int(10.1 / 0.02):])


@pytest.mark.parametrize("error", [
    lambda t: 20.0 - 0.06 * t,          # 0.6 m closer every 10 s: progress
    lambda t: 0.5,                      # within tolerance, however still
])
def test_progress_or_tolerance_is_no_deadlock(error):
    assert not any(feed(ProgressWatch(10.0), (30.0, error)))


def test_progress_just_short_of_the_threshold_is_a_deadlock():
    slow = 0.9 * PROGRESS / 10.0             # m/s
    assert feed(ProgressWatch(10.0), (30.0, lambda t: 20.0 - slow * t))[-1]


def test_a_robot_pushed_out_of_its_place_is_deadlocked_only_after_a_window_out():
    """In tolerance (0.5 m of 0.75) for 12 s, then pushed 1.2 m out and held there: not
    deadlocked until it has been out for a whole window without progress."""
    watch = ProgressWatch(10.0)
    verdicts = feed(watch, (30.0, lambda t: 0.5 if t < 12.0 else 1.2))
    assert not any(verdicts[:int(21.9 / 0.02)]) and all(verdicts[int(23.1 / 0.02):])


def test_reset_starts_the_window_again():
    watch = ProgressWatch(10.0)
    assert feed(watch, (12.0, lambda t: 5.0))[-1]
    watch.reset()
    assert not watch.deadlocked and not watch.update(13.0, 5.0, 0.75)


def test_tolerance_is_the_lag_plus_the_margin():
    assert tolerance(2.0, 4.0) == pytest.approx(0.75)


def test_two_robots_sent_to_one_place_report_their_deadlock():
    """Both robots' places are the same point: they meet there, avoid each other and
    stay about b apart, each out of tolerance: each agent flags DEADLOCKED in its state and
    counts the episode; a robot that reaches its place does not."""
    clock, net, agents = make_swarm([(-6.0, 0.0, 0.0), (6.0, 0.0, 3.14)],
                                    [(0.0, 0.0), (0.0, 0.0)])
    for a in agents:
        a.arm()
        a.set_mode(AgentMode.FORMATION)
    run(clock, agents, 25.0)
    for a in agents:
        assert a.deadlock is not None and "m off" in a.deadlock
        assert a.counters.summary()["deadlocks"] >= 1
        assert a.swarm.published[-1].flags & StateFlags.DEADLOCKED
        assert 0.2 < a.counters.summary()["deadlocked_share"] < 0.8
    clock, net, (alone,) = make_swarm([(0.0, 0.0, 0.0)], [(0.0, 0.0)], center0=(6.0, 3.0))
    alone.arm()
    alone.set_mode(AgentMode.FORMATION)
    run(clock, [alone], 25.0)
    assert alone.counters.summary()["deadlocks"] == 0
    assert not any(m.flags & StateFlags.DEADLOCKED for m in alone.swarm.published)


def test_a_jostled_or_creeping_robot_stays_deadlocked_until_it_moves_on():
    watch = ProgressWatch(10.0)
    assert feed(watch, (12.0, lambda t: 5.0))[-1]
    assert all(watch.update(12.0 + k, 5.0 + (0.4 if k % 2 else -0.4), 0.75) for k in range(20))
    creep = 0.9 * PROGRESS / 10.0                    # m/s, just short of progress
    assert all(watch.update(32.0 + k, 5.0 - creep * k, 0.75) for k in range(40))
    assert not watch.update(80.0, 5.0 - creep * 40 - 1.5, 0.75)   # on its way at last
