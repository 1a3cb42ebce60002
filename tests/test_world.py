"""What robots sense (firmware_sim.swarm_step's cell-list search) against brute force."""
import numpy as np
import pytest

from firmware_sim.swarm_step import build_grid, sense_neighbours, sense_obstacles
from firmware_sim.world import Obstacles


def sensed(pos, obs, rng_m=8.0, cap=64):
    """{(i, j)} neighbours and {(i, k)} obstacles that the search finds."""
    pose = np.column_stack([pos, np.zeros(len(pos))])
    grid = build_grid(pose[:, 0], pose[:, 1], rng_m, 4 * len(pos) + 64)
    o = np.column_stack([obs.centers, obs.radii]).reshape(-1, 3)
    max_r = o[:, 2].max() if len(o) else 0.0
    ogrid = build_grid(o[:, 0], o[:, 1], rng_m + max_r, 4 * len(o) + 64)
    bufs = [np.empty(cap), np.empty(cap), np.empty(cap), np.empty(cap, np.int64)]
    nb, ob = set(), set()
    sorted_xy = pos[grid[1]]
    for i in range(len(pos)):
        m = sense_neighbours(i, pos[i, 0], pos[i, 1], sorted_xy, rng_m, grid, cap, *bufs)
        assert m <= cap
        nb |= {(i, int(j)) for j in bufs[3][:m]}
        assert np.allclose(bufs[2][:m], np.hypot(*(pos[bufs[3][:m]] - pos[i]).T))
        k = sense_obstacles(pos[i, 0], pos[i, 1], o, rng_m, max_r, ogrid, cap, *bufs)
        ob |= {(i, int(kk)) for kk in bufs[3][:k]}
    return nb, ob


def brute(pos, obs, rng_m=8.0):
    d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1))
    nb = {(i, j) for i, j in zip(*np.nonzero(d <= rng_m)) if i != j}
    ob = set(zip(*np.nonzero(obs.clearance(pos) <= rng_m)))
    return {(int(i), int(j)) for i, j in nb}, {(int(i), int(k)) for i, k in ob}


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_cell_lists_find_exactly_what_is_in_range(seed):
    rng = np.random.default_rng(seed)
    pos = rng.uniform(0, 60, (300, 2))
    obs = Obstacles(rng.uniform(-5, 65, (40, 2)), rng.uniform(0.5, 3, 40))
    got, want = sensed(pos, obs), brute(pos, obs)
    assert got == want
    assert len(want[0]) > 100 and len(want[1]) > 50


def test_only_what_is_in_range_is_sensed():
    pos = np.array([[0.0, 0.0], [7.9, 0.0], [8.1, 0.0]])
    obs = Obstacles(np.array([[0.0, 11.0], [0.0, -12.5]]), np.array([3.0, 4.0]))
    nb, ob = sensed(pos, obs)
    assert (0, 1) in nb and (0, 2) not in nb and (1, 2) in nb
    assert (0, 0) in ob and (0, 1) not in ob          # surface 8.0 vs 8.5 m away


def test_a_full_buffer_reports_how_many_there_are():
    pos = np.column_stack([np.arange(10.0) * 0.5, np.zeros(10)])
    pose = np.column_stack([pos, np.zeros(10)])
    grid = build_grid(pose[:, 0], pose[:, 1], 8.0, 100)
    bufs = [np.empty(3), np.empty(3), np.empty(3), np.empty(3, np.int64)]
    assert sense_neighbours(0, 0.0, 0.0, pos[grid[1]], 8.0, grid, 3, *bufs) == 9


def test_clearance():
    obs = Obstacles(np.array([[0.0, 0.0]]), np.array([2.0]))
    assert obs.clearance(np.array([[3.0, 4.0]]))[0, 0] == pytest.approx(3.0)
    assert len(Obstacles.empty()) == 0


@pytest.mark.parametrize("x, y", [(0.0, 500.0), (0.0, -500.0), (500.0, 0.0), (-500.0, 0.0),
                                  (30.0, 29.0)])
def test_a_robot_outside_the_obstacle_grid_senses_only_what_is_in_range(x, y):
    """The obstacles' grid spans their centres only: a robot beyond it in any direction
    looks at no cell outside it (and still finds an obstacle just beyond the edge)."""
    obs = Obstacles(np.array([[0.0, 0.0], [10.0, 10.0], [20.0, 20.0]]), np.ones(3))
    pos = np.array([[x, y]])
    assert sensed(pos, obs) == brute(pos, obs)
