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
        rel = pos[:, None, :] - self.centers[None, :, :]
        return np.hypot(rel[..., 0], rel[..., 1]) - self.radii[None, :]


@dataclass(frozen=True)
class Sensed:
    """Padded per-robot view: neighbour indices (N, M) and obstacle indices (N, K')."""

    nbr_idx: np.ndarray     # (N, M) int, index into the swarm, valid where nbr_valid
    nbr_valid: np.ndarray   # (N, M) bool
    obs_idx: np.ndarray     # (N, K') int, index into Obstacles
    obs_valid: np.ndarray   # (N, K') bool
    pairs: np.ndarray       # (P, 2) int, i < j, every pair within sensing range
    pair_dist: np.ndarray   # (P,) m, their distances


def _pad(rows: np.ndarray, cols: np.ndarray, n: int, rows_sorted: bool = False
         ) -> tuple[np.ndarray, np.ndarray]:
    """Group ``cols`` by ``rows`` into a padded (n, max count) index array and mask."""
    if not rows_sorted:
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


def _candidates(pos: np.ndarray, obstacles: Obstacles, reach: float, dense_max: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(i, j) robot pairs i < j within ``reach`` and (rows, cols) robot-obstacle entries
    whose surface is within ``reach``."""
    n = len(pos)
    if n <= dense_max:
        rel = pos[:, None, :] - pos[None, :, :]
        near = np.hypot(rel[..., 0], rel[..., 1]) <= reach
        i, j = np.nonzero(np.triu(near, k=1))
    else:
        pairs = cKDTree(pos).query_pairs(reach, output_type="ndarray")
        i, j = pairs[:, 0], pairs[:, 1]
    k = len(obstacles)
    if n * k <= 8 * dense_max:
        rows, cols = np.nonzero(obstacles.clearance(pos) <= reach)
    else:
        hits = cKDTree(pos).sparse_distance_matrix(
            cKDTree(obstacles.centers), reach + float(obstacles.radii.max()),
            output_type="ndarray")
        keep = hits["v"] - obstacles.radii[hits["j"]] <= reach
        rows, cols = hits["i"][keep], hits["j"][keep]
    return i, j, rows, cols


def sense(pos: np.ndarray, obstacles: Obstacles, sensing_range: float,
          dense_max: int = DENSE_MAX) -> Sensed:
    """Neighbours (centre distance <= range) and obstacles (surface <= range) of each robot.

    Up to ``dense_max`` robots (robot-obstacle pairs up to 8 ``dense_max``) a dense
    distance matrix, above it k-d trees. Either way the result is compacted to what each
    robot actually senses, so the law works on a few columns, not on the whole swarm.
    """
    n = len(pos)
    i, j, rows, cols = _candidates(pos, obstacles, sensing_range, dense_max)
    nbr_idx, nbr_valid = _pad(np.concatenate([i, j]), np.concatenate([j, i]), n)
    obs_idx, obs_valid = _pad(rows, cols, n)
    d = pos[i] - pos[j]
    return Sensed(nbr_idx, nbr_valid, obs_idx, obs_valid, np.column_stack([i, j]),
                  np.hypot(d[:, 0], d[:, 1]))


class Sensing:
    """Repeated :func:`sense` for a moving swarm, with Verlet lists.

    Candidates are searched within ``range + skin`` and reused until some robot has moved
    more than ``skin / 2`` since the search; each call then only filters the candidates by
    their current distance. The result equals :func:`sense` exactly.
    """

    def __init__(self, obstacles: Obstacles, sensing_range: float, skin: float = 2.0,
                 dense_max: int = DENSE_MAX):
        self.obstacles, self.range, self.skin, self.dense_max = (obstacles, sensing_range,
                                                                 skin, dense_max)
        self._anchor: np.ndarray | None = None
        self.rebuilds = 0

    def _rebuild(self, pos: np.ndarray) -> None:
        i, j, rows, cols = _candidates(pos, self.obstacles, self.range + self.skin,
                                       self.dense_max)
        self._i, self._j = i, j
        # directed lists (both ends of each pair), sorted by robot: `order` maps them back
        self._order = np.argsort(np.concatenate([i, j]), kind="stable")
        self._nbr_rows = np.concatenate([i, j])[self._order]
        self._nbr_cols = np.concatenate([j, i])[self._order]
        order = np.argsort(rows, kind="stable")
        self._obs_rows, self._obs_cols = rows[order], cols[order]
        self._anchor = pos.copy()
        self.rebuilds += 1

    def __call__(self, pos: np.ndarray) -> Sensed:
        n = len(pos)
        if n <= self.dense_max and len(self.obstacles) * n <= 8 * self.dense_max:
            return sense(pos, self.obstacles, self.range, self.dense_max)
        moved = pos - self._anchor if self._anchor is not None else None
        if moved is None or len(moved) != n or \
                np.max(np.hypot(moved[:, 0], moved[:, 1]), initial=0.0) > self.skin / 2:
            self._rebuild(pos)
        d = pos[self._i] - pos[self._j]
        dist = np.hypot(d[:, 0], d[:, 1])
        keep = dist <= self.range
        both = np.concatenate([keep, keep])[self._order]
        nbr_idx, nbr_valid = _pad(self._nbr_rows[both], self._nbr_cols[both], n,
                                  rows_sorted=True)
        rows, cols = self._obs_rows, self._obs_cols
        rel = pos[rows] - self.obstacles.centers[cols]
        near = np.hypot(rel[:, 0], rel[:, 1]) - self.obstacles.radii[cols] <= self.range
        obs_idx, obs_valid = _pad(rows[near], cols[near], n, rows_sorted=True)
        return Sensed(nbr_idx, nbr_valid, obs_idx, obs_valid,
                      np.column_stack([self._i[keep], self._j[keep]]), dist[keep])
