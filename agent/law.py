"""The bounded formation control law of Nguyen & La, made precise (see DESIGN.md).

Theory of operation. Every period each robot picks one of three modes:

* AVOID (Theorem 2) when a neighbour is closer than b (closer than b + hysteresis while it
  is already avoiding one) or an obstacle surface is closer than b. The robot descends the
  potential sum V = K_ij ln cosh(r - c) of those neighbours and obstacle virtual agents, with
  any component into a close obstacle removed: theta_d = atan2(-g), u = -K_theta e_theta,
  v = K cos(e_theta) min(D_max, |g|).
* ROTATE when not avoiding and an obstacle within c blocks the straight path to the
  reference (the segment passes within b of its surface), or while a circulation side is
  latched. Heading is the obstacle's tangent on the side facing the reference; the side is
  latched until the path is clear of every obstacle within 2c, and a corner rule hands over
  to a neighbouring obstacle that turns the robot further out. Speed law as in TRACK.
* TRACK (Theorem 1) otherwise: e = p - p_d, theta_d = atan2(-e), u = -K_theta e_theta +
  theta_d_hat_dot, v = K cos(e_theta) min(D_max, |e|).

Finally |u| is clipped to u_max; |v| <= K D_max holds by construction.

The law is pure: arrays in, arrays out. Its mode memory (previous error, hysteresis flag,
latched side and followed obstacle) is explicit state in :class:`LawMemory`. An agent runs
the same law for its one robot through :mod:`agent.law_single` (plain floats, step for
step the same; the tests run both).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent.avoidance import (EPS, corner_takeover, potential_gradient, remove_toward,
                             segment_distance, tangent_side)
from agent.config import ControlParams
from agent.kinematics import wrap_angle
from common.vocabulary import Mode


@dataclass(frozen=True)
class LawMemory:
    """Per-robot mode memory carried from one period to the next (all arrays length N)."""

    prev_error: np.ndarray       # (N, 2) m, e(t - T)
    has_prev: np.ndarray         # (N,) bool, False before the first step
    avoiding: np.ndarray         # (N,) bool, in neighbour-AVOID (hysteresis)
    side: np.ndarray             # (N,) int8, latched circulation side (+1, -1) or 0
    followed_center: np.ndarray  # (N, 2) m, centre of the obstacle being circled
    followed_radius: np.ndarray  # (N,) m

    @classmethod
    def initial(cls, n: int) -> "LawMemory":
        return cls(prev_error=np.zeros((n, 2)), has_prev=np.zeros(n, bool),
                   avoiding=np.zeros(n, bool), side=np.zeros(n, np.int8),
                   followed_center=np.zeros((n, 2)), followed_radius=np.zeros(n))


@dataclass(frozen=True)
class LawInput:
    """What one period of the law sees, padded per robot.

    pose (N, 3) [m, m, rad]; ref (N, 2) [m]: the robot's reference p_d(t);
    nbr_pos (N, M, 2) [m] with nbr_valid (N, M): neighbours in sensing range (already
    extrapolated to now); obs_center (N, K, 2) [m], obs_radius (N, K) [m] with obs_valid
    (N, K): obstacles in sensing range.
    """

    pose: np.ndarray
    ref: np.ndarray
    nbr_pos: np.ndarray
    nbr_valid: np.ndarray
    obs_center: np.ndarray
    obs_radius: np.ndarray
    obs_valid: np.ndarray


@dataclass(frozen=True)
class LawOutput:
    v: np.ndarray       # (N,) m/s
    u: np.ndarray       # (N,) rad/s
    mode: np.ndarray    # (N,) int8, values of Mode
    memory: LawMemory


def _heading_law(theta: np.ndarray, theta_d: np.ndarray, dist: np.ndarray, p: ControlParams
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(e_theta, v): e_theta = wrap(theta - theta_d) (0 where dist ~ 0) and v = K cos(e) min."""
    e_th = np.where(dist < EPS, 0.0, wrap_angle(theta - theta_d))
    return e_th, p.K * np.cos(e_th) * np.minimum(p.D_max, dist)


def _rotation(e: np.ndarray, to_obs: np.ndarray, obs_clear: np.ndarray, inp_ref: np.ndarray,
              pos: np.ndarray, centers: np.ndarray, radii: np.ndarray, valid: np.ndarray,
              avoid: np.ndarray, mem_side: np.ndarray, mem_center: np.ndarray,
              mem_radius: np.ndarray, p: ControlParams):
    """ROTATE decision for robots that see at least one obstacle (arrays of those rows).

    Returns (rotate, side, followed centre, followed radius, tangent heading theta_d).
    """
    rows = np.arange(len(pos))
    phi = np.arctan2(to_obs[..., 1], to_obs[..., 0])          # robot -> obstacle centre
    seg = segment_distance(pos, inp_ref, centers)
    on_path = valid & (seg < radii + p.b)
    blocking = on_path & (obs_clear < p.c)
    clear_2c = ~(on_path & (obs_clear < 2.0 * p.c)).any(axis=1)

    # keep a latched side while its obstacle is in sight and the path is not clear
    off = centers - mem_center[:, None, :]
    match = np.where(valid, np.hypot(off[..., 0], off[..., 1]), np.inf)
    followed = np.argmin(match, axis=1)
    in_sight = match[rows, followed] <= np.maximum(mem_radius, EPS)
    side = np.where(clear_2c | ~in_sight, 0, mem_side).astype(np.int8)

    # latch a new side on the obstacle that blocks the path
    nearest_blocking = np.argmin(np.where(blocking, obs_clear, np.inf), axis=1)
    start = (side == 0) & ~avoid & blocking.any(axis=1)
    new_side = tangent_side(phi[rows, nearest_blocking], np.arctan2(-e[:, 1], -e[:, 0]))
    followed = np.where(start, nearest_blocking, followed)
    side = np.where(start, new_side, side).astype(np.int8)
    rotate = ~avoid & (side != 0)
    r = np.flatnonzero(rotate)
    if r.size:
        followed[r] = corner_takeover(followed[r], side[r], phi[r], centers[r], radii[r],
                                      obs_clear[r], valid[r], p.b, p.c)
    latched = side != 0
    center = np.where(latched[:, None], centers[rows, followed], mem_center)
    radius = np.where(latched, radii[rows, followed], mem_radius)
    return rotate, side, center, radius, phi[rows, followed] + side * (np.pi / 2)


def control_step(inp: LawInput, mem: LawMemory, params: ControlParams,
                 dt: float | None = None) -> LawOutput:
    """One period of the law for N robots. ``dt`` [s] defaults to ``params.period``."""
    p = params
    dt = p.period if dt is None else dt
    pos, theta = inp.pose[:, :2], inp.pose[:, 2]
    n = len(pos)

    # --- TRACK for everyone: error and its finite-difference heading rate (Assumption 2)
    e = pos - inp.ref
    D = np.hypot(e[:, 0], e[:, 1])
    e_prev = np.where(mem.has_prev[:, None], mem.prev_error, e)
    e_dot = (e - e_prev) / dt
    feed_forward = np.where(D > EPS, (e[:, 0] * e_dot[:, 1] - e[:, 1] * e_dot[:, 0])
                            / np.maximum(D * D, EPS), 0.0)
    theta_d = np.arctan2(-e[:, 1], -e[:, 0])
    dist = D.copy()
    mode = np.full(n, Mode.TRACK, np.int8)

    # --- neighbours and obstacles around each robot
    to_nbr = inp.nbr_pos - pos[:, None, :]
    nbr_d2 = np.where(inp.nbr_valid, to_nbr[..., 0] ** 2 + to_nbr[..., 1] ** 2, np.inf)
    to_obs = inp.obs_center - pos[:, None, :]
    obs_cdist = np.hypot(to_obs[..., 0], to_obs[..., 1])
    obs_clear = np.where(inp.obs_valid, obs_cdist - inp.obs_radius, np.inf)

    # --- AVOID decision, with hysteresis on the neighbour part
    reach = np.where(mem.avoiding, p.b + p.hysteresis, p.b)
    nbr_active = nbr_d2 < (reach * reach)[:, None]
    obs_active = obs_clear < p.b
    avoiding = nbr_active.any(axis=1)
    avoid = avoiding | obs_active.any(axis=1)

    # --- ROTATE decision, for robots that see an obstacle
    side = np.zeros(n, np.int8)
    center, radius = mem.followed_center.copy(), mem.followed_radius.copy()
    rot = np.flatnonzero(inp.obs_valid.any(axis=1))
    if rot.size:
        rotate, side[rot], center[rot], radius[rot], theta_rot = _rotation(
            e[rot], to_obs[rot], obs_clear[rot], inp.ref[rot], pos[rot], inp.obs_center[rot],
            inp.obs_radius[rot], inp.obs_valid[rot], avoid[rot], mem.side[rot],
            mem.followed_center[rot], mem.followed_radius[rot], p)
        rot = rot[rotate]
        theta_d[rot] = theta_rot[rotate]
        mode[rot] = Mode.ROTATE
        feed_forward[rot] = 0.0

    # --- AVOID: descend the potential, never toward a close obstacle or neighbour
    av = np.flatnonzero(avoid)
    if av.size:
        obs_out = -to_obs[av] / np.maximum(obs_cdist[av], EPS)[..., None]
        nd = np.sqrt(nbr_d2[av])
        toward = to_nbr[av] / np.where(nd < EPS, np.inf, nd)[..., None]
        g = potential_gradient(theta[av], toward, nd, nbr_active[av], obs_out, obs_clear[av],
                               obs_active[av], p.K_ij, p.c)
        descent = remove_toward(-g, toward, nd < p.b)
        descent = remove_toward(descent, -obs_out, obs_active[av])
        theta_d[av] = np.arctan2(descent[:, 1], descent[:, 0])
        dist[av] = np.hypot(descent[:, 0], descent[:, 1])
        mode[av] = Mode.AVOID
        feed_forward[av] = 0.0

    e_theta, v = _heading_law(theta, theta_d, dist, p)
    u = np.clip(-p.K_theta * e_theta + feed_forward, -p.u_max, p.u_max)
    memory = LawMemory(prev_error=e, has_prev=np.ones(n, bool), avoiding=avoiding,
                       side=side, followed_center=center, followed_radius=radius)
    return LawOutput(v=v, u=u, mode=mode, memory=memory)
