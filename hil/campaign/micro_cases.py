"""Micro cases: small seeded situations (1-9 robots) that break naive controllers.

Each builder draws one variation from ``rng`` and returns the scene before its rotation (the
robots' side is -x, their references +x unless said otherwise) and the default duration [s].
Distances scale with the controller's a, b, c and hysteresis [m]; ``sep`` below is
b + hysteresis, the distance at which two robots stop avoiding each other.
"""
from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np

from agent.config import ControlParams
from agent.formation import FormationKind, formation_offsets
from hil.campaign.scene import Scene

Builder = Callable[[np.random.Generator, ControlParams], tuple[Scene, float]]


def _scene(starts: Sequence | np.ndarray, slots: Sequence | np.ndarray,
           obstacles: Sequence[tuple[float, float, float]] = (),
           velocity: tuple[float, float] = (0.0, 0.0)) -> Scene:
    """Scene with references ``slots`` (N, 2) [m] at t = 0, centred on their mean."""
    slots = np.asarray(slots, dtype=float).reshape(-1, 2)
    centre = slots.mean(axis=0)
    return Scene(poses=np.asarray(starts, dtype=float).reshape(-1, 3), offsets=slots - centre,
                 center0=centre, velocity=np.array(velocity, dtype=float),
                 obstacles=np.array(obstacles, dtype=float).reshape(-1, 3))


def _swap(rng: np.random.Generator, ctl: ControlParams, lateral: float) -> Scene:
    """Two robots 2L apart facing each other, each one's reference on the other's start;
    their lines ``lateral`` [m] apart."""
    half, dy = rng.uniform(2 * ctl.c, 3 * ctl.c), lateral / 2
    jitter = rng.uniform(-0.1, 0.1, 2)
    starts = [(-half, dy, jitter[0]), (half, -dy, math.pi + jitter[1])]
    return _scene(starts, [(half, dy), (-half, -dy)])


def head_on_swap(rng: np.random.Generator, ctl: ControlParams) -> tuple[Scene, float]:
    """Two robots swap places along one line."""
    return _swap(rng, ctl, 0.0), 25.0


def offset_head_on(rng: np.random.Generator, ctl: ControlParams) -> tuple[Scene, float]:
    """The swap with the two lines 0.2b..0.8b apart: each robot passes the other's side."""
    return _swap(rng, ctl, rng.uniform(0.2, 0.8) * ctl.b), 25.0


def obstacle_ahead(rng: np.random.Generator, ctl: ControlParams) -> tuple[Scene, float]:
    """One robot; a disc across the straight path to its stationary reference (centre within
    0.3 radius of the path)."""
    r = rng.uniform(1.5, 3.0)
    half = r + rng.uniform(2 * ctl.c, 3 * ctl.c)
    y0 = rng.uniform(-0.3, 0.3) * r
    return _scene([(-half, 0.0, rng.uniform(-0.2, 0.2))], [(half, 0.0)], [(0.0, y0, r)]), 20.0


def crowd_onto_obstacle(rng: np.random.Generator, ctl: ControlParams) -> tuple[Scene, float]:
    """4-6 robots whose references lie on an arc round one disc, centred behind it
    (clearance b + 0.5..1 m, neighbouring references 2 sep apart)."""
    sep = ctl.b + ctl.hysteresis
    r = rng.uniform(2.0, 3.0)
    ring = r + ctl.b + rng.uniform(0.5, 1.0)
    step = 2 * math.asin(min(1.0, sep / ring))            # chord 2 sep
    n = min(int(rng.integers(4, 7)), 1 + int(1.5 * math.pi // step))
    ang = (np.arange(n) - (n - 1) / 2) * step
    slots = ring * np.column_stack([np.cos(ang), np.sin(ang)])
    y = (np.arange(n) - (n - 1) / 2) * 2 * sep + rng.uniform(-0.5, 0.5, n)
    x = -ring - rng.uniform(2 * ctl.c, 3 * ctl.c, n)
    starts = np.column_stack([x, y, rng.uniform(-0.3, 0.3, n)])
    order = np.argsort(slots[:, 1], kind="stable")           # lateral order kept
    return _scene(starts, slots[order], [(0.0, 0.0, r)]), 30.0


def narrow_gap(rng: np.random.Generator, ctl: ControlParams) -> tuple[Scene, float]:
    """1-3 robots and their stationary line beyond two discs whose surfaces are a + 25..75 %
    of (2b - a) apart; the straight path of robot n // 2 runs through the gap."""
    gap = ctl.a + rng.uniform(0.25, 0.75) * (2 * ctl.b - ctl.a)
    r = rng.uniform(2.0, 4.0)
    n = int(rng.integers(1, 4))
    y = (np.arange(n) - n // 2) * 2 * (ctl.b + ctl.hysteresis)
    x0 = -r - rng.uniform(2 * ctl.c, 3 * ctl.c)
    starts = np.column_stack([np.full(n, x0), y + rng.uniform(-0.2, 0.2, n) * gap / 2,
                              rng.uniform(-0.3, 0.3, n)])
    slots = np.column_stack([np.full(n, r + rng.uniform(2 * ctl.c, 3 * ctl.c)), y])
    obstacles = [(0.0, gap / 2 + r, r), (0.0, -gap / 2 - r, r)]
    return _scene(starts, slots, obstacles), 30.0


def through_own_reference(rng: np.random.Generator, ctl: ControlParams
                          ) -> tuple[Scene, float]:
    """1-3 robots side by side; their line starts 2.5c..4c ahead and drives at them at
    1-2 m/s, through them and on: each robot must turn round behind its reference."""
    n = int(rng.integers(1, 4))
    y = (np.arange(n) - (n - 1) / 2) * 2 * (ctl.b + ctl.hysteresis)
    starts = np.column_stack([rng.uniform(-0.3, 0.3, n), y, rng.uniform(-0.3, 0.3, n)])
    ahead = rng.uniform(2.5 * ctl.c, 4 * ctl.c)
    speed = rng.uniform(1.0, 2.0)
    slots = np.column_stack([np.full(n, ahead), y])
    return _scene(starts, slots, velocity=(-speed, 0.0)), 30.0


def late_arrival(rng: np.random.Generator, ctl: ControlParams) -> tuple[Scene, float]:
    """A grid of 6 or 9 (spacing 2 sep + 0.5..1.5 m, moving +x at 0.5-1.5 m/s) formed on its
    slots, except one front-row robot that starts 3-5 spacings behind the last row and must
    pass through its column."""
    sep = ctl.b + ctl.hysteresis
    n = int(rng.choice([6, 9]))
    spacing = 2 * sep + rng.uniform(0.5, 1.5)
    offsets = formation_offsets(FormationKind.GRID, n, spacing)
    late = int(rng.integers(0, math.ceil(math.sqrt(n))))     # a front-row slot
    starts = np.column_stack([offsets, np.zeros(n)])
    starts[late] = (offsets[:, 0].min() - rng.uniform(3, 5) * spacing,
                    offsets[late, 1] + rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3))
    scene = _scene(starts, offsets, velocity=(rng.uniform(0.5, 1.5), 0.0))
    return scene, 30.0


CASES: dict[str, Builder] = {f.__name__: f for f in (
    head_on_swap, offset_head_on, obstacle_ahead, crowd_onto_obstacle, narrow_gap,
    through_own_reference, late_arrival)}
