import numpy as np
import pytest

from firmware_sim.world import Obstacles, pair_distances, sense


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
    dense = _sets(sense(pos, obs, 8.0, dense_max=1000))
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
    assert pair_distances(np.array([[0.0, 0], [3, 4]]), np.array([[0, 1]]))[0] == 5.0
    assert len(Obstacles.empty()) == 0
