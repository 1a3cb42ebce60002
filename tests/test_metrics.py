import numpy as np
import pytest

from firmware_sim.metrics import RunMetrics, tolerance


def test_tolerance_is_lag_plus_margin():
    assert tolerance(np.array([[2.0, 0.0]]), 4.0)[0] == pytest.approx(0.75)


def _control(m, t, err):
    n = len(err)
    m.observe_control(t, np.array(err), np.full(n, 1.0), np.zeros(n), np.zeros(n),
                      np.zeros(n, np.int8))


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


def test_mode_switches_are_counted():
    m = RunMetrics(ids=np.array([1, 2]), a=1.0)
    for modes in ([0, 0], [1, 0], [1, 2], [0, 0]):
        m.observe_control(0.0, np.zeros(2), np.ones(2), np.zeros(2), np.zeros(2),
                          np.array(modes, np.int8))
    assert m.summary("x", 1.0)["mode_switches"] == 4
