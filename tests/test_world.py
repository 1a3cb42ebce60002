import numpy as np
import pytest

from firmware_sim.world import Obstacles, Sensing, sense


def _sets(seen):
    nb = {(i, int(j)) for i in range(seen.nbr_idx.shape[0])
          for j, ok in zip(seen.nbr_idx[i], seen.nbr_valid[i]) if ok}
    ob = {(i, int(k)) for i in range(seen.obs_idx.shape[0])
          for k, ok in zip(seen.obs_idx[i], seen.obs_valid[i]) if ok}
    return nb, ob, {tuple(p) for p in seen.pairs.tolist()}


def test_dense_and_tree_search_agree():
    rng = np.random.default_rng(1)
    pos = rng.uniform(0, 60, (300, 2))
    obs = Obstacles(rng.uniform(0, 60, (40, 2)), rng.uniform(0.5, 3, 40))
    dense = _sets(sense(pos, obs, 8.0, dense_max=2000))
    tree = _sets(sense(pos, obs, 8.0, dense_max=10))
    assert dense == tree
    assert len(dense[0]) > 100 and len(dense[1]) > 50


def test_only_what_is_in_range_is_sensed():
    pos = np.array([[0.0, 0.0], [7.9, 0.0], [8.1, 0.0]])
    obs = Obstacles(np.array([[0.0, 11.0], [0.0, -12.5]]), np.array([3.0, 4.0]))
    nb, ob, pairs = _sets(sense(pos, obs, 8.0))
    assert (0, 1) in nb and (0, 2) not in nb and (1, 2) in nb
    assert (0, 0) in ob and (0, 1) not in ob          # surface 8.0 vs 8.5 m away
    assert pairs == {(0, 1), (1, 2)}


def test_clearance_and_pair_distances():
    obs = Obstacles(np.array([[0.0, 0.0]]), np.array([2.0]))
    assert obs.clearance(np.array([[3.0, 4.0]]))[0, 0] == pytest.approx(3.0)
    seen = sense(np.array([[0.0, 0], [3, 4]]), obs, 8.0)
    assert seen.pairs.tolist() == [[0, 1]] and seen.pair_dist[0] == 5.0
    assert len(Obstacles.empty()) == 0


def test_verlet_sensing_equals_a_fresh_search_while_robots_move():
    rng = np.random.default_rng(2)
    pos = rng.uniform(0, 80, (400, 2))
    obs = Obstacles(rng.uniform(0, 80, (300, 2)), rng.uniform(0.5, 3, 300))
    sensing = Sensing(obs, 8.0, skin=2.0, dense_max=50)
    for _ in range(12):
        assert _sets(sensing(pos)) == _sets(sense(pos, obs, 8.0))
        pos = pos + rng.uniform(-0.3, 0.3, pos.shape)
    assert 1 < sensing.rebuilds < 12                     # lists were reused, and renewed
