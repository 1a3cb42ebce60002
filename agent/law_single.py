"""The law of :mod:`agent.law` for a single robot, in plain floats: an agent's period.

:func:`agent.law.control_step` defines the law (vectorised over robots; the swarm
simulation runs it). An agent runs it for one robot with a handful of neighbours, where
numpy's fixed cost per call dominates: its hundred-odd calls take about 90 us per step, where
this module, the same computation step for step and in the same order on floats, takes 6 us
(``bench/law_step.py``; 170 us against 17 us with cold caches). ``tests/test_law.py`` runs every law test on
both, and ``tests/test_law_single.py`` checks that they agree on random inputs.

Units and frames as in agent.law: metres, radians, world frame ENU.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from agent.avoidance import EPS
from agent.config import ControlParams
from agent.kinematics import wrap_scalar
from common.vocabulary import Mode

HALF_PI = math.pi / 2


@dataclass(frozen=True)
class SingleMemory:
    """One robot's :class:`agent.law.LawMemory`."""

    prev_error: tuple[float, float] | None = None     # m, e(t - T); None before a step
    avoiding: bool = False                            # in neighbour-AVOID (hysteresis)
    side: int = 0                                     # latched circulation side or 0
    followed_center: tuple[float, float] = (0.0, 0.0)  # m, obstacle being circled
    followed_radius: float = 0.0                      # m


def _argmin(values: Sequence[float]) -> int:
    """Index of the first smallest value (as numpy's argmin)."""
    return min(range(len(values)), key=values.__getitem__)


def _remove_toward(dx: float, dy: float, toward: Sequence[tuple[float, float]],
                   active: Sequence[bool]) -> tuple[float, float]:
    for (tx, ty), on in zip(toward, active):
        if on:
            comp = dx * tx + dy * ty
            if comp > 0.0:
                dx, dy = dx - comp * tx, dy - comp * ty
    return dx, dy


def _corner_takeover(followed: int, side: int, phi: list[float],
                     obstacles: Sequence[tuple[float, float, float]], clear: list[float],
                     b: float, c: float) -> int:
    s = float(side)
    theta_f = phi[followed] + side * HALF_PI
    fx, fy, fr = obstacles[followed]
    best, best_turn = 0, -math.inf
    for k, (cx, cy, r) in enumerate(obstacles):
        gap = math.sqrt((cx - fx) ** 2 + (cy - fy) ** 2) - r - fr
        near = clear[k] < c or (gap < 2.0 * b and clear[k] < 2.0 * c)
        if k != followed and s * wrap_scalar(phi[k] - theta_f) < 0.0 and near:
            turn = s * wrap_scalar(phi[k] + s * HALF_PI - theta_f)
            if turn > best_turn:
                best, best_turn = k, turn
    return best if best_turn > 0.0 else followed


def single_step(pose: tuple[float, float, float], ref: tuple[float, float],
                nbrs: Sequence[tuple[float, float]],
                obstacles: Sequence[tuple[float, float, float]], mem: SingleMemory,
                p: ControlParams, dt: float) -> tuple[float, float, Mode, SingleMemory]:
    """One period for one robot: (v [m/s], u [rad/s], mode, memory).

    ``pose`` (x, y, theta); ``ref`` its reference p_d(t); ``nbrs`` the neighbours in range
    (extrapolated to now); ``obstacles`` (centre x, centre y, radius) in range.
    """
    x, y, theta = pose
    # TRACK for everyone: error and its finite-difference heading rate
    ex, ey = x - ref[0], y - ref[1]
    D = math.hypot(ex, ey)
    px, py = mem.prev_error if mem.prev_error is not None else (ex, ey)
    edx, edy = (ex - px) / dt, (ey - py) / dt
    ff = (ex * edy - ey * edx) / max(D * D, EPS) if D > EPS else 0.0
    theta_d = math.atan2(-ey, -ex)
    dist = D
    mode = Mode.TRACK

    # neighbours and obstacles around the robot
    to_nbr = [(nx - x, ny - y) for nx, ny in nbrs]
    nbr_d2 = [dx * dx + dy * dy for dx, dy in to_nbr]
    to_obs = [(cx - x, cy - y) for cx, cy, _ in obstacles]
    obs_cdist = [math.hypot(dx, dy) for dx, dy in to_obs]
    obs_clear = [d - r for d, (_, _, r) in zip(obs_cdist, obstacles)]

    # AVOID decision, with hysteresis on the neighbour part
    reach = p.b + p.hysteresis if mem.avoiding else p.b
    nbr_active = [d2 < reach * reach for d2 in nbr_d2]
    obs_active = [cl < p.b for cl in obs_clear]
    avoiding = any(nbr_active)
    avoid = avoiding or any(obs_active)

    # ROTATE decision, when an obstacle is in sight
    side, center, radius = 0, mem.followed_center, mem.followed_radius
    if obstacles:
        phi = [math.atan2(dy, dx) for dx, dy in to_obs]
        sx, sy = ref[0] - x, ref[1] - y                       # segment robot -> reference
        len2 = sx * sx + sy * sy
        on_path = []
        for (dx, dy), (_, _, r) in zip(to_obs, obstacles):
            t = min(max((dx * sx + dy * sy) / max(len2, EPS), 0.0), 1.0)
            on_path.append(math.hypot(dx - t * sx, dy - t * sy) < r + p.b)
        blocking = [on and cl < p.c for on, cl in zip(on_path, obs_clear)]
        clear_2c = not any(on and cl < 2.0 * p.c for on, cl in zip(on_path, obs_clear))
        # keep a latched side while its obstacle is in sight and the path is not clear
        mx, my = mem.followed_center
        match = [math.hypot(cx - mx, cy - my) for cx, cy, _ in obstacles]
        followed = _argmin(match)
        in_sight = match[followed] <= max(mem.followed_radius, EPS)
        side = 0 if clear_2c or not in_sight else mem.side
        # latch a new side on the obstacle that blocks the path
        if side == 0 and not avoid and any(blocking):
            followed = _argmin([cl if bl else math.inf for bl, cl in zip(blocking, obs_clear)])
            side = -1 if math.sin(math.atan2(-ey, -ex) - phi[followed]) < 0.0 else 1
        rotate = not avoid and side != 0
        if rotate:
            followed = _corner_takeover(followed, side, phi, obstacles, obs_clear, p.b, p.c)
        if side != 0:
            cx, cy, radius = obstacles[followed]
            center = (cx, cy)
        if rotate:
            theta_d = phi[followed] + side * HALF_PI
            mode = Mode.ROTATE
            ff = 0.0

    # AVOID: descend the potential, never toward a close obstacle or neighbour
    if avoid:
        nd = [math.sqrt(d2) for d2 in nbr_d2]
        toward = [(dx / d, dy / d) if d >= EPS else (0.0, 0.0)
                  for (dx, dy), d in zip(to_nbr, nd)]
        obs_out = [(-dx / max(d, EPS), -dy / max(d, EPS))
                   for (dx, dy), d in zip(to_obs, obs_cdist)]
        # g = grad of the potential sum: toward active neighbours, away from obstacles
        nx = ny = ox = oy = same = 0.0
        for (tx, ty), d, on in zip(toward, nd, nbr_active):
            if on:
                w = p.K_ij * math.tanh(d - p.c)
                nx, ny = nx + w * tx, ny + w * ty
                if d < EPS:
                    same += w
        for (outx, outy), cl, on in zip(obs_out, obs_clear, obs_active):
            if on:
                w = p.K_ij * math.tanh(max(cl, 0.0) - p.c)
                ox, oy = ox + w * outx, oy + w * outy
        gx, gy = -nx + ox, -ny + oy
        if same:                        # a neighbour on the robot: pushed back along theta
            gx, gy = gx + same * -math.cos(theta), gy + same * -math.sin(theta)
        dx, dy = _remove_toward(-gx, -gy, toward, [d < p.b for d in nd])
        dx, dy = _remove_toward(dx, dy, [(-ox, -oy) for ox, oy in obs_out], obs_active)
        theta_d = math.atan2(dy, dx)
        dist = math.hypot(dx, dy)
        mode = Mode.AVOID
        ff = 0.0

    e_theta = 0.0 if dist < EPS else wrap_scalar(theta - theta_d)
    v = p.K * math.cos(e_theta) * min(p.D_max, dist)
    u = min(max(-p.K_theta * e_theta + ff, -p.u_max), p.u_max)
    return v, u, mode, SingleMemory((ex, ey), avoiding, side, center, radius)
