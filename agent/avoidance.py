"""Geometry of collision and obstacle avoidance for one robot, in plain floats.

Part of the one law (:mod:`agent.law`): agents run it interpreted, the batch simulator
compiles the same source (:mod:`firmware_sim.compiled`). Hence only floats, ints and
indexable sequences of floats, and ``math.sqrt`` for lengths (bit-identical interpreted and
compiled, unlike ``math.hypot``). Metres, radians, world frame ENU; docs/controller.md.

Potential: V = K_ij ln cosh(r - c). Its gradient with respect to the robot's own position is
g = K_ij tanh(r - c) (p_i - p_j)/r, which for r < c points *toward* the other robot (the
paper prints f with the opposite sign); the robot descends it, i.e. moves along -g. An
obstacle acts through a virtual agent at the robot's projection on its boundary.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

from agent.kinematics import wrap_angle

if TYPE_CHECKING:
    from typing import MutableSequence, Sequence, TypeAlias

    import numpy as np
    import numpy.typing as npt

    # What the float-sequence parameters of the law receive: lists in an agent, 1-D float64
    # arrays when numba compiles this source (firmware_sim.compiled). Declared for the type
    # checker only, so a module numba compiles gains no run-time object.
    FloatSeq: TypeAlias = Sequence[float] | npt.NDArray[np.float64]
    # Rows of floats: a sequence of lists in an agent, a 2-D float64 array compiled.
    FloatRows: TypeAlias = Sequence[FloatSeq] | npt.NDArray[np.float64]
    # Ints: a list in an agent, an array compiled.
    IntSeq: TypeAlias = Sequence[int] | npt.NDArray[np.int64]
    # Columns a function writes into: lists in an agent, arrays compiled.
    FloatBuf: TypeAlias = MutableSequence[float] | npt.NDArray[np.float64]
    IntBuf: TypeAlias = MutableSequence[int] | npt.NDArray[np.int64]

EPS = 1e-9
HALF_PI = math.pi / 2


class Surroundings(NamedTuple):
    """What the law takes into account round the robot: the first ``n_nbr`` entries of the
    neighbour columns and the first ``n_obs`` of the obstacle columns."""

    nbr_x: FloatSeq     # m, the neighbours in range, where they are now
    nbr_y: FloatSeq
    nbr_held: FloatSeq  # 1.0 where the pair with it was active last period, else 0.0
    nbr_grow: FloatSeq  # m, how much wider than a its governor's disc is (A13)
    n_nbr: int
    obs_x: FloatSeq     # m, the obstacles in range (detected, and silent neighbours)
    obs_y: FloatSeq
    obs_r: FloatSeq     # m, their radii
    n_obs: int


def segment_distance(sx: float, sy: float, px: float, py: float) -> float:
    """Distance [m] from point (px, py) to the segment from the origin to (sx, sy)."""
    len2 = sx * sx + sy * sy
    t = min(max((px * sx + py * sy) / max(len2, EPS), 0.0), 1.0)
    gx, gy = px - t * sx, py - t * sy
    return math.sqrt(gx * gx + gy * gy)


def tangent_side(phi: float, beta: float) -> int:
    """Side s in {+1, -1} such that heading phi + s pi/2 has a positive component along beta.

    ``phi``: direction robot -> obstacle centre; ``beta``: direction robot -> reference. With
    s = +1 the obstacle is on the robot's right (it goes round it clockwise). A reference
    exactly behind the obstacle picks +1.
    """
    return -1 if math.sin(beta - phi) < 0.0 else 1


def clearance(x: float, y: float, cx: float, cy: float, r: float) -> float:
    """Distance [m] from (x, y) to the surface of the disc centred at (cx, cy) of radius r
    (negative inside)."""
    dx, dy = cx - x, cy - y
    return math.sqrt(dx * dx + dy * dy) - r


def corner_takeover(followed: int, side: int, x: float, y: float, around: Surroundings,
                    b: float, c: float) -> int:
    """Index of the obstacle to follow after the corner rule, for a robot at (x, y).

    While circling obstacle F on side s (heading phi_F + s pi/2, phi the direction robot ->
    obstacle centre), another obstacle on the followed side that is within c, or within 2c
    and closer than 2b to F, takes over when its own same-side tangent turns further away
    from the obstacles.
    """
    s = float(side)
    obs_x, obs_y, obs_r = around.obs_x, around.obs_y, around.obs_r
    fx, fy, fr = obs_x[followed], obs_y[followed], obs_r[followed]
    theta_f = math.atan2(fy - y, fx - x) + side * HALF_PI
    best, best_turn = 0, -math.inf
    for k in range(around.n_obs):
        phi = math.atan2(obs_y[k] - y, obs_x[k] - x)
        clear = clearance(x, y, obs_x[k], obs_y[k], obs_r[k])
        gap = clearance(fx, fy, obs_x[k], obs_y[k], obs_r[k]) - fr     # between surfaces
        near = clear < c or (gap < 2.0 * b and clear < 2.0 * c)
        if k != followed and s * wrap_angle(phi - theta_f) < 0.0 and near:
            turn = s * wrap_angle(phi + s * HALF_PI - theta_f)
            if turn > best_turn:
                best, best_turn = k, turn
    return best if best_turn > 0.0 else followed


def way_closed(followed: int, side: int, x: float, y: float, around: Surroundings,
               b: float, c: float) -> bool:
    """Whether the way round obstacle F on side s is closed ahead of a robot at (x, y): an
    obstacle on the other side of its heading (phi_F + s pi/2), ahead of it and within c,
    leaves less than 2b between itself and F, too narrow to pass outside AVOID."""
    s = float(side)
    obs_x, obs_y, obs_r = around.obs_x, around.obs_y, around.obs_r
    fx, fy, fr = obs_x[followed], obs_y[followed], obs_r[followed]
    theta_f = math.atan2(fy - y, fx - x) + side * HALF_PI
    for k in range(around.n_obs):
        if k == followed or clearance(x, y, obs_x[k], obs_y[k], obs_r[k]) >= c:
            continue
        off = wrap_angle(math.atan2(obs_y[k] - y, obs_x[k] - x) - theta_f)
        gap = clearance(fx, fy, obs_x[k], obs_y[k], obs_r[k]) - fr     # between surfaces
        if s * off > 0.0 and abs(off) < HALF_PI and gap < 2.0 * b:
            return True
    return False


def remove_toward(dx: float, dy: float, tx: float, ty: float) -> tuple[float, float]:
    """(dx, dy) without its component along the unit vector (tx, ty), if that is positive.

    Used in AVOID for obstacles closer than b (without it two neighbours outweigh one
    obstacle and push a robot into it) and for neighbours closer than b (the bounded
    potential's gradient is nearly flat, so robots behind push a robot into the one ahead).
    """
    comp = dx * tx + dy * ty
    if comp > 0.0:
        return dx - comp * tx, dy - comp * ty
    return dx, dy
