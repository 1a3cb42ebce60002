"""The simulated world: circular obstacles, what each robot senses, distances for safety.

Each robot senses only the neighbours and obstacles inside its sensing range (neighbour
centre distance, obstacle surface distance), never the whole swarm: the law stays
distributed. Below ``DENSE_MAX`` robots the search is a dense distance matrix; above it a
k-d tree (scipy's cKDTree). Results are padded per robot for the vectorised law.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

DENSE_MAX = 256


@dataclass(frozen=True)
class Obstacles:
    """Circular obstacles: centres (K, 2) [m] and radii (K,) [m]."""

    centers: np.ndarray
    radii: np.ndarray

    @classmethod
    def empty(cls) -> "Obstacles":
        return cls(np.zeros((0, 2)), np.zeros(0))

    def __len__(self) -> int:
        return len(self.radii)

    def clearance(self, pos: np.ndarray) -> np.ndarray:
        """(N, K) distance [m] from robot centres to obstacle surfaces (< 0 inside)."""
        return (np.linalg.norm(pos[:, None, :] - self.centers[None, :, :], axis=-1)
                - self.radii[None, :])


@dataclass(frozen=True)
class Sensed:
    """Padded per-robot view: neighbour indices (N, M) and obstacle indices (N, K')."""

    nbr_idx: np.ndarray     # (N, M) int, index into the swarm, valid where nbr_valid
    nbr_valid: np.ndarray   # (N, M) bool
    obs_idx: np.ndarray     # (N, K') int, index into Obstacles
    obs_valid: np.ndarray   # (N, K') bool
    pairs: np.ndarray       # (P, 2) int, i < j, every pair within sensing range


def _pad(rows: np.ndarray, cols: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Group ``cols`` by ``rows`` into a padded (n, max count) index array and mask."""
    order = np.argsort(rows, kind="stable")
    rows, cols = rows[order], cols[order]
    counts = np.bincount(rows, minlength=n)
    width = int(counts.max()) if len(rows) else 0
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(len(rows)) - starts[rows]
    idx = np.zeros((n, width), dtype=np.intp)
    valid = np.zeros((n, width), dtype=bool)
    idx[rows, slot] = cols
    valid[rows, slot] = True
    return idx, valid


def sense(pos: np.ndarray, obstacles: Obstacles, sensing_range: float,
          dense_max: int = DENSE_MAX) -> Sensed:
    """Neighbours (centre distance <= range) and obstacles (surface <= range) of each robot.

    Up to ``dense_max`` robots a dense distance matrix, above it k-d trees.
    """
    n = len(pos)
    if n <= dense_max:
        d = np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=-1)
        near = d <= sensing_range
        np.fill_diagonal(near, False)
        i, j = np.nonzero(np.triu(near))
        nbr_idx = np.broadcast_to(np.arange(n), (n, n))
        nbr_valid = near
    else:
        pairs = cKDTree(pos).query_pairs(sensing_range, output_type="ndarray")
        i, j = pairs[:, 0], pairs[:, 1]
        nbr_idx, nbr_valid = _pad(np.concatenate([i, j]), np.concatenate([j, i]), n)
    k = len(obstacles)
    if k and n * k > 4 * dense_max * dense_max:
        reach = sensing_range + float(obstacles.radii.max())
        hits = cKDTree(pos).sparse_distance_matrix(cKDTree(obstacles.centers), reach,
                                                    output_type="ndarray")
        keep = hits["v"] - obstacles.radii[hits["j"]] <= sensing_range
        obs_idx, obs_valid = _pad(hits["i"][keep], hits["j"][keep], n)
    else:
        obs_idx = np.broadcast_to(np.arange(k), (n, k))
        obs_valid = obstacles.clearance(pos) <= sensing_range
    return Sensed(nbr_idx, nbr_valid, obs_idx, obs_valid, np.column_stack([i, j]))


def pair_distances(pos: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Distances [m] of the robot pairs (P, 2)."""
    return np.linalg.norm(pos[pairs[:, 0]] - pos[pairs[:, 1]], axis=-1)
