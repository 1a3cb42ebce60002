"""Geometry of collision and obstacle avoidance, vectorised over robots.

Arrays are padded per robot: neighbours (N, M, ...) and obstacles (N, K, ...) with a
boolean ``valid`` mask, so one call serves one agent (N = 1) and a whole swarm. Distances in
metres, angles in radians, world frame ENU.

Potential (paper eq. Vij): V = K_ij ln cosh(r - c). Its gradient with respect to the robot's
own position is g = K_ij tanh(r - c) (p_i - p_j)/r, which for r < c points *toward* the other
robot (the paper prints f with the opposite sign); the robot descends it, i.e. moves along -g.
An obstacle acts through a virtual agent at the robot's projection on its boundary.
"""
from __future__ import annotations

import numpy as np

from agent.kinematics import wrap_angle

EPS = 1e-9


def potential_gradient(heading: np.ndarray, toward: np.ndarray, nbr_dist: np.ndarray,
                       nbr_active: np.ndarray, obs_out: np.ndarray, obs_clear: np.ndarray,
                       obs_active: np.ndarray, K_ij: float, c: float) -> np.ndarray:
    """g = grad_{p_i} sum V over active neighbours and obstacle virtual agents, (N, 2).

    ``toward`` (N, M, 2) is the unit vector from the robot to each neighbour (zero where
    they coincide), ``nbr_dist`` their distance; ``obs_out`` (N, K, 2) the unit vector from
    each obstacle centre to the robot and ``obs_clear`` the distance to its surface. A
    neighbour at the robot's own position pushes it backwards along its own heading (a
    deterministic, finite choice).
    """
    w_n = np.where(nbr_active, K_ij * np.tanh(np.where(nbr_active, nbr_dist, c) - c), 0.0)
    w_o = np.where(obs_active,
                   K_ij * np.tanh(np.maximum(np.where(obs_active, obs_clear, c), 0.0) - c), 0.0)
    # grad of r_ij w.r.t. p_i is -toward; tanh(r - c) < 0 for r < c, so g points toward
    g = -(w_n[..., None] * toward).sum(axis=1) + (w_o[..., None] * obs_out).sum(axis=1)
    same = (nbr_active & (nbr_dist < EPS)).any(axis=1)
    if same.any():
        back = -np.column_stack([np.cos(heading[same]), np.sin(heading[same])])
        w_same = np.where(nbr_active & (nbr_dist < EPS), w_n, 0.0)[same].sum(axis=1)
        g[same] += w_same[:, None] * back
    return g


def remove_toward(direction: np.ndarray, toward: np.ndarray, active: np.ndarray
                  ) -> np.ndarray:
    """Remove from ``direction`` (N, 2) every component along an active unit vector of
    ``toward`` (N, K, 2) that it has a positive projection on.

    Used in AVOID for obstacles closer than b (without it two neighbours outweigh one
    obstacle and push a robot into it) and for neighbours closer than b (the bounded
    potential's gradient is nearly flat, so robots behind push a robot into the one ahead).
    """
    d = direction.copy()
    for k in np.flatnonzero(active.any(axis=0)):
        comp = np.einsum("ij,ij->i", d, toward[:, k, :])
        d -= np.where(active[:, k] & (comp > 0.0), comp, 0.0)[:, None] * toward[:, k, :]
    return d


def segment_distance(start: np.ndarray, end: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance from each of (N, K, 2) ``points`` to the segment start[i] -> end[i]."""
    seg = (end - start)[:, None, :]
    rel = points - start[:, None, :]
    len2 = np.einsum("ikj,ikj->ik", seg, seg)
    t = np.clip(np.einsum("ikj,ikj->ik", rel, seg) / np.maximum(len2, EPS), 0.0, 1.0)
    gap = rel - t[..., None] * seg
    return np.hypot(gap[..., 0], gap[..., 1])


def tangent_side(phi: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """Side s in {+1, -1} such that heading phi + s pi/2 has a positive component along beta.

    ``phi``: direction robot -> obstacle centre; ``beta``: direction robot -> reference. With
    s = +1 the obstacle is on the robot's right (it circles counter-clockwise). A reference
    exactly behind the obstacle picks +1.
    """
    return np.where(np.sin(beta - phi) < 0.0, -1, 1).astype(np.int8)


def corner_takeover(followed: np.ndarray, side: np.ndarray, phi: np.ndarray,
                    centers: np.ndarray, radii: np.ndarray, clear: np.ndarray,
                    valid: np.ndarray, b: float, c: float) -> np.ndarray:
    """Index of the obstacle to follow after applying the corner rule, (N,).

    While circling obstacle F on side s (heading phi_F + s pi/2), another obstacle on the
    followed side that is within c, or within 2c and closer than 2b to F, takes over when its
    own same-side tangent turns further away from the obstacles.
    """
    n, k = valid.shape
    rows = np.arange(n)
    s = side.astype(float)[:, None]
    theta_f = phi[rows, followed] + side * (np.pi / 2)
    rel = wrap_angle(phi - theta_f[:, None])
    on_side = (s * rel < 0.0)
    gap = (np.linalg.norm(centers - centers[rows, followed][:, None, :], axis=-1)
           - radii - radii[rows, followed][:, None])
    near = (clear < c) | ((gap < 2.0 * b) & (clear < 2.0 * c))
    cand = valid & on_side & near
    cand[rows, followed] = False
    turn = np.where(cand, s * wrap_angle(phi + s * (np.pi / 2) - theta_f[:, None]), -np.inf)
    best = np.argmax(turn, axis=1) if k else np.zeros(n, dtype=int)
    return np.where(turn[rows, best] > 0.0, best, followed)
