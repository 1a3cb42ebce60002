"""One control period of an imperfect world (:class:`firmware_sim.world.WorldParams`).

What an agent would know, produced from the plant's truth: its pose from the odometry of
slipping wheels read through noisy encoders, and its neighbours' states as they arrive over
a link with delay, jitter and bursty loss. Every random draw is a hash of (seed, stream,
robot, index, period) (:mod:`common.draws`), so a run is reproducible from its scenario and
seed whatever the number of threads, and the compiled and interpreted runs draw the same
numbers. Compiled
with the law (:mod:`firmware_sim.compiled`); plain floats, ints and arrays only.

The model (docs/world.md): each robot publishes its odometry pose and command every period;
a state is lost or delivered to every receiver alike, with one age drawn per state; a
receiver keeps the newest state that has arrived (by stamp) and extrapolates it with
:func:`agent.neighbours.extrapolate`, the agents' code.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from agent.neighbours import extrapolate
from agent.odometry import odometry_step
from common.draws import AGE, DETECT, DROPOUT, ENCODER, LOSS, SLIP, loss_step, normal, uniform

if TYPE_CHECKING:
    from agent.neighbours import Reports

prange = range   # numba.prange when compiled

NONE, FRESH, STALE = 0, 1, 2                           # what a robot knows of a neighbour
SLIP_TIME = 1.0      # s, correlation time of wheel slip
SLIP_MAX = 0.9       # slip fractions are clipped to +-SLIP_MAX
TIME_EPS = 1e-9      # s, arrival times equal to a period's start up to rounding count as due


def publish(step: int, period: float, est: np.ndarray, cmd: np.ndarray, places: np.ndarray,
            alive: np.ndarray, seed: int, delay: float, jitter: float, loss: float,
            burst: float, bad: np.ndarray, hist: np.ndarray, arrive: np.ndarray) -> None:
    """Every live robot publishes its state of this period: ``est`` (N, 3) pose [m, m,
    rad], ``cmd`` (N, >= 2) v [m/s], u [rad/s] and ``places`` (N, 3) its place exchange's
    slot, partner and other (:class:`agent.exchange.Exchange`), into ring slot step % H of
    ``hist`` (H, N, 9: x, y, theta, v, u, stamp [s], slot, partner, other) with its arrival
    time [s] in ``arrive`` (H, N)
    (inf: lost or not sent). Loss: independent with probability ``loss`` when ``burst`` is
    1, else a Gilbert-Elliott channel (``bad`` (N,) its state) with mean burst ``burst``.
    Age: delay + jitter * normal, at least 0 and at most H - 2 periods."""
    slot = step % hist.shape[0]
    longest = (hist.shape[0] - 2) * period
    for j in prange(est.shape[0]):
        hist[slot, j, 0], hist[slot, j, 1], hist[slot, j, 2] = est[j, 0], est[j, 1], est[j, 2]
        hist[slot, j, 3], hist[slot, j, 4] = cmd[j, 0], cmd[j, 1]
        hist[slot, j, 5] = step * period
        hist[slot, j, 6], hist[slot, j, 7] = places[j, 0], places[j, 1]
        hist[slot, j, 8] = places[j, 2]
        lost = not alive[j]
        if alive[j] and loss > 0.0:
            bad[j] = loss_step(uniform(seed, LOSS, j, 0, step), bad[j], loss, burst)
            lost = bad[j] != 0
        age = delay
        if jitter > 0.0:
            age += jitter * normal(seed, AGE, j, 0, step)
        arrive[slot, j] = math.inf if lost else step * period + min(max(age, 0.0), longest)


def deliver(t: float, hist: np.ndarray, arrive: np.ndarray, reports: Reports,
            staleness: float, out_seen: np.ndarray) -> None:
    """What the robots know of each other at time t [s]: ``reports`` (agent.neighbours
    .Reports, row j robot j's) hold the newest of each robot's states that has arrived
    (stamp -inf: none yet), updated from the ring of :func:`publish`; ``out_seen`` (N, 3)
    = the position [m] its report puts it at by t and NONE, FRESH or STALE."""
    for j in prange(len(reports.stamp)):
        # in a function of its own: numba loses the writes a parallel loop's body makes
        # into the arrays of a record
        _deliver_to(j, t, hist, arrive, reports, staleness, out_seen)


def _deliver_to(j: int, t: float, hist: np.ndarray, arrive: np.ndarray, reports: Reports,
                staleness: float, out_seen: np.ndarray) -> None:
    """:func:`deliver` for robot ``j``'s report."""
    for h in range(hist.shape[0]):
        if arrive[h, j] <= t + TIME_EPS and hist[h, j, 5] > reports.stamp[j]:
            reports.x[j], reports.y[j], reports.theta[j] = (hist[h, j, 0], hist[h, j, 1],
                                                            hist[h, j, 2])
            reports.v[j], reports.u[j], reports.stamp[j] = (hist[h, j, 3], hist[h, j, 4],
                                                            hist[h, j, 5])
            reports.slot[j], reports.partner[j] = int(hist[h, j, 6]), int(hist[h, j, 7])
            reports.other[j] = int(hist[h, j, 8])
    if reports.stamp[j] == -math.inf:
        out_seen[j, 0], out_seen[j, 1], out_seen[j, 2] = reports.x[j], reports.y[j], NONE
    else:
        x, y, stale = extrapolate(reports.x[j], reports.y[j], reports.theta[j], reports.v[j],
                                  reports.u[j], t - reports.stamp[j], staleness)
        out_seen[j, 0], out_seen[j, 1] = x, y
        out_seen[j, 2] = STALE if stale else FRESH


def slip_update(step: int, period: float, seed: int, sigma: float, slip: np.ndarray) -> None:
    """Advance each wheel's slip fraction ``slip`` (N, 2) one period: a first-order
    Gauss-Markov process of standard deviation ``sigma`` and correlation time SLIP_TIME,
    clipped to [-0.9, 0.9]."""
    for i in prange(slip.shape[0]):
        for w in range(2):
            slip[i, w] = slip_next(slip[i, w], period, seed, sigma, i, w, step)


def slip_next(s: float, period: float, seed: int, sigma: float, i: int, w: int,
              step: int) -> float:
    """Wheel ``w`` (0 right, 1 left) of robot ``i``: its slip fraction ``s`` one period
    [s] later (``step``: the period's index, the key of the draw)."""
    rho = math.exp(-period / SLIP_TIME)
    s = rho * s + sigma * math.sqrt(1.0 - rho * rho) * normal(seed, SLIP, i, w, step)
    return min(max(s, -SLIP_MAX), SLIP_MAX)


def odometry(step: int, seed: int, noise: float, enc: np.ndarray, last_read: np.ndarray,
             wheel_radius: float, wheel_base: float, est: np.ndarray) -> None:
    """Each robot reads its encoders (true wheel turns ``enc`` (N, 2) [rev] plus noise of
    standard deviation ``noise`` [rev]) and integrates the change since ``last_read`` into
    its pose estimate ``est`` (N, 3) with :func:`agent.odometry.odometry_step`."""
    for i in prange(enc.shape[0]):
        right, left = enc[i, 0], enc[i, 1]
        if noise > 0.0:
            right += noise * normal(seed, ENCODER, i, 0, step)
            left += noise * normal(seed, ENCODER, i, 1, step)
        x, y, th = odometry_step(est[i, 0], est[i, 1], est[i, 2], right - last_read[i, 0],
                                 left - last_read[i, 1], wheel_radius, wheel_base)
        est[i, 0], est[i, 1], est[i, 2] = x, y, th
        last_read[i, 0], last_read[i, 1] = right, left


def detect(i: int, step: int, seed: int, noise: float, dropout: float, k: int,
           o_x: np.ndarray, o_y: np.ndarray, o_r: np.ndarray, o_k: np.ndarray) -> int:
    """Robot i's detections of the k obstacles it senses this period (centres, radii [m]
    and indices in the first k entries): each missing with probability ``dropout``, the
    others' centre coordinates and radius off by normal noise of standard deviation
    ``noise`` [m] (radius at least 0). Compacts the arrays; returns how many remain."""
    kept = 0
    for q in range(k):
        kk = o_k[q]
        if dropout > 0.0 and uniform(seed, DROPOUT, i, kk, step) < dropout:
            continue
        x, y, r = o_x[q], o_y[q], o_r[q]
        if noise > 0.0:
            x += noise * normal(seed, DETECT, i, 3 * kk, step)
            y += noise * normal(seed, DETECT, i, 3 * kk + 1, step)
            r = max(r + noise * normal(seed, DETECT, i, 3 * kk + 2, step), 0.0)
        o_x[kept], o_y[kept], o_r[kept], o_k[kept] = x, y, r, kk
        kept += 1
    return kept
