"""A generated scenario's geometry, its rotation, and its scenario document (TOML).

A :class:`Scene` holds what :mod:`hil.campaign.families` and :mod:`hil.campaign.micro_cases`
draw: start poses, the formation's offsets and motion, and disc obstacles, in metres and
radians (world frame, formation frame for the offsets). :meth:`Scene.doc` turns it into the
plain dictionary that :func:`hil.files.scenario.parse_scenario` reads (formation as
``kind = "offsets"``), rounded to 0.1 mm and 0.1 mrad (rates to 1e-6);
:func:`hil.files.toml_text.dumps` writes such a dictionary as TOML text.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

DIGITS = 4        # decimals kept of positions and angles: 0.1 mm, 0.1 mrad
RATE_DIGITS = 6   # of velocities and turn rates, whose error grows with time


def rot(angle: float) -> np.ndarray:
    """The 2x2 rotation by ``angle`` [rad]."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def wrap(angle: float | np.ndarray) -> Any:
    """Angle(s) [rad] wrapped to [-pi, pi)."""
    return (np.asarray(angle) + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class Scene:
    """Robots, formation and obstacles of one scenario (robot i has slot ``offsets[i]``)."""

    poses: np.ndarray                 # (N, 3) m, m, rad, world frame
    offsets: np.ndarray               # (N, 2) m, formation frame
    center0: np.ndarray               # (2,) m, formation centre at t = 0
    velocity: np.ndarray              # (2,) m/s
    omega: float = 0.0                # rad/s
    obstacles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (K, 3): x, y, r [m]

    def slots(self, t: float = 0.0) -> np.ndarray:
        """(N, 2) reference positions p_d(t) [m] at time t [s]."""
        turned = self.offsets @ rot(self.omega * t).T
        return self.center0 + self.velocity * t + turned

    def slot_speed(self) -> float:
        """The fastest any slot moves [m/s]: the reference's speed plus the turn rate times
        the farthest offset."""
        reach = float(np.hypot(self.offsets[:, 0], self.offsets[:, 1]).max(initial=0.0))
        return float(np.hypot(*self.velocity)) + abs(self.omega) * reach

    def within(self, speed: float) -> Scene:
        """The scene with the formation's velocity and turn rate scaled down together so that
        no slot moves faster than ``speed`` [m/s] (unchanged when none does)."""
        fastest = self.slot_speed()
        if fastest <= speed:
            return self
        k = speed / fastest
        return replace(self, velocity=self.velocity * k, omega=self.omega * k)

    def rotated(self, angle: float) -> Scene:
        """The whole scene turned by ``angle`` [rad] about the world origin."""
        r = rot(angle)
        poses = np.column_stack([self.poses[:, :2] @ r.T, wrap(self.poses[:, 2] + angle)])
        obstacles = self.obstacles.copy()
        obstacles[:, :2] = obstacles[:, :2] @ r.T
        return replace(self, poses=poses, offsets=self.offsets @ r.T,
                       center0=r @ self.center0, velocity=r @ self.velocity,
                       obstacles=obstacles)

    def doc(self, name: str, duration: float) -> dict[str, Any]:
        """The scenario document (no [control], [robot] or [sim]); robot ids are 1..N."""
        formation: dict[str, Any] = {"kind": "offsets", "center0": _round(self.center0),
                                     "velocity": _round(self.velocity, RATE_DIGITS),
                                     "omega": round(float(self.omega), RATE_DIGITS) + 0.0,
                                     "offsets": [_round(o) for o in self.offsets]}
        doc: dict[str, Any] = {
            "name": name, "duration": round(float(duration), DIGITS), "formation": formation,
            "robots": [{"id": i + 1, "pose": _round(p)} for i, p in enumerate(self.poses)]}
        if len(self.obstacles):
            doc["obstacles"] = [{"center": _round(o[:2]), "radius": round(float(o[2]), DIGITS)}
                                for o in self.obstacles]
        return doc


def _round(values: np.ndarray, digits: int = DIGITS) -> list[float]:
    # + 0.0 turns -0.0 into 0.0
    return [round(float(v), digits) + 0.0 for v in values]
