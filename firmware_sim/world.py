"""The simulated world's circular obstacles (what robots sense of them:
:mod:`firmware_sim.swarm_step`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
