"""The simulated world: circular obstacles, and how imperfect the world is.

:class:`WorldParams` is the optional ``[world]`` table of a scenario (docs/formats.md): link
delay, jitter and (bursty) loss on the neighbour states, wheel slip, encoder noise, noisy
and missing obstacle detections, and agents that die. Absent, the world is ideal: every
robot knows its true pose and its neighbours' current ones. How each imperfection is
modelled is specified in docs/world.md; the batch simulator applies them in
:mod:`firmware_sim.swarm_step`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent.impairment import LinkParams
from common.schema import ConfigError, setting, tables, validate


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
class Kill:
    """An agent that dies: it stops commanding and publishing; its drivers' watchdog
    stops its wheels."""

    robot: int = setting(doc="id of the robot whose agent dies", lo=0)
    at: float = setting(doc="when, in mission time", unit="s", lo=0.0)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class WorldParams(LinkParams):
    """How imperfect the world is (every default: ideal): the link of
    :class:`agent.impairment.LinkParams` (seed, link_delay, link_jitter, link_loss,
    loss_burst), then the robots' own imperfections."""

    wheel_slip: float = setting(0.0, lo=0.0, hi=0.5,
                                doc="standard deviation of each wheel's slip fraction")
    encoder_noise: float = setting(0.0, unit="rev", lo=0.0,
                                   doc="standard deviation of encoder position noise")
    detection_noise: float = setting(0.0, unit="m", lo=0.0,
                                     doc="standard deviation of a detected obstacle's centre "
                                         "coordinates and radius")
    detection_dropout: float = setting(0.0, lo=0.0, hi=1.0,
                                       doc="fraction of periods in which a detection is missing")
    kill: tuple[Kill, ...] = tables(doc="agents that die ([[world.kill]] robot, at)")

    def __post_init__(self) -> None:
        super().__post_init__()
        robots = [k.robot for k in self.kill]
        if len(set(robots)) != len(robots):
            raise ConfigError(f"WorldParams.kill: a robot dies twice: {sorted(robots)}")

    @property
    def ideal(self) -> bool:
        """Nothing imperfect: every robot sees the truth."""
        return self == WorldParams(seed=self.seed)

    @property
    def odometry(self) -> bool:
        """Robots know their own pose only from their (slipping, noisy) wheel encoders."""
        return self.wheel_slip > 0 or self.encoder_noise > 0

    @property
    def detections(self) -> bool:
        """Obstacle detections are noisy or missing."""
        return self.detection_noise > 0 or self.detection_dropout > 0

    @property
    def link(self) -> bool:
        """Neighbour states arrive late or not at all."""
        return self.link_delay > 0 or self.link_jitter > 0 or self.link_loss > 0
