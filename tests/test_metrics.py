import numpy as np
import pytest

from agent.progress import TOLERANCE_MARGIN
from firmware_sim.metrics import RunMetrics
from firmware_sim.swarm_step import period_summary


def test_tolerance_is_lag_plus_margin():
    """A robot 0.75 m behind a reference moving at 2 m/s (K = 4) is within, 0.76 m is not."""
    pose = np.array([[-0.75, 0.0, 0.0], [-0.76, 0.0, 0.0]])
    ref = np.array([[0.0, 0.0, 2.0, 0.0], [0.0, 0.0, 2.0, 0.0]])
    err, within = np.zeros(2), np.zeros(2, bool)
    alive = np.ones(2, bool)
    period_summary(pose, np.zeros((2, 3)), ref, 4.0, TOLERANCE_MARGIN, True, alive,
                   np.zeros(2), err, within)
    assert err == pytest.approx([0.75, 0.76]) and within.tolist() == [True, False]
    alive[1] = False                    # a dead robot is not waited for
    period_summary(pose, np.zeros((2, 3)), ref, 4.0, TOLERANCE_MARGIN, True, alive,
                   np.zeros(2), err, within)
    assert within.tolist() == [True, True]


def _control(m, t, err):
    err = np.array(err, dtype=float)
    within = err <= 1.0
    m.observe_period(t, 0.0, 0.0, 0, err, within, bool(within.all()))


def test_convergence_time_is_after_the_last_excursion():
    m = RunMetrics(ids=np.array([1, 2]), a=1.0)
    for t, err in [(0, [5, 5]), (1, [0.5, 0.5]), (2, [0.5, 2.0]), (3, [0.5, 0.5]),
                   (4, [0.4, 0.4])]:
        _control(m, t, err)
    s = m.summary("x", 4.0)
    assert s["converged"] and s["convergence_time"] == 3
    assert s["final_max_tracking_error"] == pytest.approx(0.4) and s["stuck_robots"] == []


def test_not_converged_lists_the_robots_out_of_tolerance():
    m = RunMetrics(ids=np.array([7, 8]), a=1.0)
    _control(m, 0, [0.1, 3.0])
    s = m.summary("x", 1.0)
    assert not s["converged"] and s["convergence_time"] is None
    assert s["stuck_robots"] == [8]


def test_collisions_count_pairs_and_robots_inside_obstacles():
    m = RunMetrics(ids=np.array([1, 2, 3]), a=1.0)
    pos = np.array([[0.0, 0.0], [0.5, 0.0], [5.0, 0.0]])
    pairs = np.array([[0, 1], [1, 2]])
    clear = np.array([[3.0], [-0.1]])                      # robots 0 and 2 see an obstacle
    m.observe_geometry(0.0, pos, pairs, np.array([0, 2]), clear)
    m.observe_geometry(0.1, pos, pairs, np.array([0, 2]), clear)   # counted once
    s = m.summary("x", 1.0)
    assert s["collisions"] == 2
    assert s["colliding_pairs"] == [(1, 2)] and s["robots_in_obstacles"] == [3]
    assert s["min_pair_distance"] == 0.5 and s["min_obstacle_clearance"] == -0.1
    assert s["worst_pair"] == [1, 2] and s["min_pair_time"] == 0.0
    assert s["worst_clearance_robot"] == 3 and s["worst_clearance_obstacle"] == 0


def test_deadlock_is_no_progress_over_the_window():
    """Robot 8 sheds 0.3 m in 10 s (deadlocked), robot 9 sheds 2 m (still arriving)."""
    m = RunMetrics(ids=np.array([7, 8, 9]), a=1.0)
    for t in range(21):
        _control(m, float(t), [0.1, 5.0 - 0.03 * t, 30.0 - 0.2 * t])
    s = m.summary("x", 20.0)
    assert s["deadlocked"] and s["deadlocked_robots"] == [8]
    m = RunMetrics(ids=np.array([7]), a=1.0)
    for t in range(5):                  # shorter than the window: no verdict
        _control(m, float(t), [5.0])
    assert not m.summary("x", 4.0)["deadlocked"]


def test_a_robot_pushed_out_of_its_place_is_not_deadlocked_within_the_window():
    """Robot 5 held its place (error 0.1, tolerance 1 m) and was pushed 1.5 m out 4 s
    before the end (a brake for a neighbour's late data): out of tolerance, not converged,
    but not deadlocked; held out for a whole window without progress, it is."""
    m = RunMetrics(ids=np.array([5]), a=1.0)
    for t in range(21):
        _control(m, float(t), [0.1 if t < 16 else 1.5])
    s = m.summary("x", 20.0)
    assert not s["converged"] and s["stuck_robots"] == [5] and not s["deadlocked"]
    for t in range(21, 27):
        _control(m, float(t), [1.5])
    assert m.summary("x", 26.0)["deadlocked_robots"] == [5]


def test_mode_switches_are_counted():
    m = RunMetrics(ids=np.array([1, 2]), a=1.0)
    last_mode, err, within = np.zeros(2), np.zeros(2), np.zeros(2, bool)
    for k, modes in enumerate(([0, 0], [1, 0], [1, 2], [0, 0])):
        cmd = np.column_stack([np.zeros(2), np.zeros(2), modes]).astype(float)
        summary = period_summary(np.zeros((2, 3)), cmd, np.zeros((2, 4)), 4.0,
                                 TOLERANCE_MARGIN, k == 0, np.ones(2, bool), last_mode, err,
                                 within)
        m.observe_period(0.0, summary[0], summary[1], summary[2], err, within, summary[3])
    assert m.summary("x", 1.0)["mode_switches"] == 4


def test_two_live_robots_in_one_place_are_not_converged():
    """Every robot within tolerance, but robots 1 and 2 hold place 0: not converged until
    they hold distinct places; a dead robot's place does not count."""
    m = RunMetrics(ids=np.array([1, 2, 3]), a=1.0)
    within, err = np.ones(3, bool), np.zeros(3)
    alive = np.array([True, True, False])
    m.observe_places(np.array([0, 0, 2]), np.array([0, 1, 2]), alive)
    m.observe_period(0.0, 0.0, 0.0, 0, err, within, True)
    assert m.shared_places == [1, 2] and m.convergence_time is None
    m.observe_places(np.array([0, 1, 1]), np.array([0, 0, 2]), alive)
    m.observe_period(0.02, 0.0, 0.0, 0, err, within, True)
    assert m.shared_places == [] and m.convergence_time == pytest.approx(0.02)
    assert m.place_changes == 3


def test_a_shared_place_lasts_until_changed_or_ended_by_a_death():
    """Periods in which no slot changes keep a sharing, and a robot's death ends it."""
    m = RunMetrics(ids=np.array([1, 2, 3]), a=1.0)
    slots = np.array([0, 0, 2])
    m.observe_places(slots, np.array([0, 1, 2]), np.ones(3, bool))
    m.observe_places(slots, slots, np.ones(3, bool))
    assert m.shared_places == [1, 2]
    m.observe_places(slots, slots, np.array([True, False, True]))
    assert m.shared_places == [] and m.place_changes == 1
