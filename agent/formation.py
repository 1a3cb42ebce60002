"""Formation references: p_di(t) = center0 + velocity t + Rot(omega t) offset_i.

Offsets are in the formation frame [m], centred on the formation's centroid; robots are
numbered in formation order (index 0 is the first robot of the scenario). The paper's line
formation x_di = 2t + 20, y_di = 4i - 20 (i = 1..9) is ``line`` with spacing 4,
center0 (20, 0) and velocity (2, 0).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

if TYPE_CHECKING:
    from agent.avoidance import FloatRows, FloatSeq


class FormationKind(str, enum.Enum):
    LINE = "line"        # robots along the formation's y axis
    WEDGE = "wedge"      # a V opening backwards (-x), apex first
    CIRCLE = "circle"    # robots evenly on a circle, neighbours `spacing` apart
    GRID = "grid"        # rows of ceil(sqrt(N)) robots
    OFFSETS = "offsets"  # explicit offsets, one per robot


WEDGE_HALF_ANGLE = math.radians(35.0)


def formation_offsets(kind: FormationKind, n: int, spacing: float) -> np.ndarray:
    """(n, 2) offsets [m] of a named formation, centred on their mean."""
    if n < 1:
        raise ValueError("formation: need at least one robot")
    i = np.arange(n, dtype=float)
    if kind is FormationKind.LINE:
        off = np.column_stack([np.zeros(n), spacing * i])
    elif kind is FormationKind.WEDGE:
        rank = np.ceil(i / 2.0)                      # 0, 1, 1, 2, 2, ...
        side = np.where(i % 2 == 1, 1.0, -1.0)       # odd indices left, even right
        side[0] = 0.0
        # robots of one arm are `spacing` apart along the arm
        off = np.column_stack([-rank * spacing * math.cos(WEDGE_HALF_ANGLE),
                               side * rank * spacing * math.sin(WEDGE_HALF_ANGLE)])
    elif kind is FormationKind.CIRCLE:
        radius = 0.0 if n == 1 else spacing / (2.0 * math.sin(math.pi / n))
        ang = 2.0 * math.pi * i / n
        off = radius * np.column_stack([np.cos(ang), np.sin(ang)])
    elif kind is FormationKind.GRID:
        cols = math.ceil(math.sqrt(n))
        off = spacing * np.column_stack([-(i // cols), i % cols])
    else:
        raise ValueError(f"formation: kind {kind.value!r} needs explicit offsets")
    return off - off.mean(axis=0)


def reference_point(offset_x: float, offset_y: float, center_x: float, center_y: float,
                    vel_x: float, vel_y: float, omega: float, t: float
                    ) -> tuple[float, float, float, float]:
    """(x, y, x_dot, y_dot): one robot's reference p_d(t) [m] and its velocity [m/s].

    p_d(t) = center0 + velocity t + Rot(omega t) offset. Plain floats: agents run it
    interpreted, the batch simulator compiled (:mod:`firmware_sim.compiled`).
    """
    c, s = math.cos(omega * t), math.sin(omega * t)
    rx, ry = offset_x * c - offset_y * s, offset_x * s + offset_y * c
    # d/dt Rot(wt) off = w J Rot(wt) off, J = [[0,-1],[1,0]]
    return (center_x + vel_x * t + rx, center_y + vel_y * t + ry,
            vel_x - omega * ry, vel_y + omega * rx)


class Places(NamedTuple):
    """The mission's places as one robot's period reads them."""

    offsets: FloatRows  # (S, 2) m, formation frame
    motion: FloatSeq    # centre0 x, y [m], velocity x, y [m/s], omega [rad/s]


def reference(places: Places, slot: int, t: float) -> tuple[float, float, float, float]:
    """:func:`reference_point` of place ``slot`` at time t [s]."""
    m = places.motion
    return reference_point(places.offsets[slot][0], places.offsets[slot][1], m[0], m[1],
                           m[2], m[3], m[4], t)


def place(places: Places, slot: int, t: float) -> tuple[float, float]:
    """Where place ``slot`` is at time t [s]: x, y [m]."""
    x, y, _, _ = reference(places, slot, t)
    return x, y


@dataclass(frozen=True)
class Formation:
    """A rigid formation moving with constant velocity [m/s] and turn rate omega [rad/s]."""

    offsets: np.ndarray           # (N, 2) m, formation frame
    center0: tuple[float, float]  # m, centre at t = 0 (the mission epoch)
    velocity: tuple[float, float] = (0.0, 0.0)
    omega: float = 0.0

    @property
    def pace(self) -> float:
        """The speed [m/s] of its fastest place: the velocity's, plus omega times the
        offset farthest from the centre of rotation."""
        reach = float(np.hypot(self.offsets[:, 0], self.offsets[:, 1]).max(initial=0.0))
        return math.hypot(*self.velocity) + abs(self.omega) * reach

    def point(self, i: int, t: float) -> tuple[float, float, float, float]:
        """:func:`reference_point` of robot ``i`` at time t [s]."""
        ox, oy = self.offsets[i].tolist()
        return reference_point(ox, oy, self.center0[0], self.center0[1], self.velocity[0],
                               self.velocity[1], self.omega, t)

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(p_d, p_d_dot): every robot's reference [m] and velocity [m/s] at t, (N, 2) each."""
        out = np.array([self.point(i, t) for i in range(len(self.offsets))]).reshape(-1, 4)
        return out[:, :2], out[:, 2:]

    def min_ahead(self, cone: float = math.pi / 6.0, chunk: int = 512) -> float:
        """Smallest distance [m] from a place to another one ahead of it, within ``cone``
        [rad] of its velocity at t = 0 (inf: none; a place that does not move has nothing
        ahead), in chunks of ``chunk`` rows as :meth:`min_spacing`."""
        off, best = self.offsets, math.inf
        vel = (np.asarray(self.velocity, float)[None, :]
               + self.omega * np.column_stack([-off[:, 1], off[:, 0]]))
        speed = np.hypot(vel[:, 0], vel[:, 1])
        for lo in range(0, len(off), chunk):
            rows, v, sp = off[lo:lo + chunk], vel[lo:lo + chunk], speed[lo:lo + chunk]
            dx, dy = off[None, :, 0] - rows[:, None, 0], off[None, :, 1] - rows[:, None, 1]
            d = np.hypot(dx, dy)
            along = dx * v[:, None, 0] + dy * v[:, None, 1]       # d |v| cos(bearing)
            ahead = (along > d * sp[:, None] * math.cos(cone)) & (d > 0.0)
            if ahead.any():
                best = min(best, float(d[ahead].min()))
        return best

    def min_spacing(self, chunk: int = 512) -> float:
        """Smallest distance [m] between two reference positions (inf for one robot), in
        chunks of ``chunk`` rows so that 10 000 places need no N x N array."""
        off, best = self.offsets, math.inf
        for lo in range(0, len(off), chunk):
            rows = off[lo:lo + chunk]
            d = np.hypot(rows[:, None, 0] - off[None, :, 0], rows[:, None, 1] - off[None, :, 1])
            d[np.arange(len(rows)), np.arange(lo, lo + len(rows))] = np.inf     # not itself
            best = min(best, float(d.min()))
        return best
