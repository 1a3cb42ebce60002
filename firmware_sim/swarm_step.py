"""One control period of a whole swarm: sensing, the one law for every robot, the plant.

Written for numba (:mod:`firmware_sim.compiled` compiles it together with the law), and
runnable as it is (interpreted, slowly): only numpy arrays, floats, ints and loops.
``prange`` is ``range`` here and ``numba.prange`` when compiled; every robot's iteration is
independent of the others', so a run's results do not depend on the number of threads.

Sensing: each robot sees the neighbours whose centre is within the sensing range and the
obstacles whose surface is, found through uniform grids (cell lists). Geometry for safety
is measured on the plant's poses at every physics substep, for the pairs and obstacles that
could be the closest or closer than a during the period (see :func:`control`).
"""
from __future__ import annotations

import math

import numpy as np

from agent.exchange import NOBODY, Exchange, exchange_step, place
from agent.formation import reference_point
from agent.governor import (
    NO_GAPS,
    SPLITS,
    TRAIL_ROWS,
    binding,
    fold_hazard,
    frame_limits,
    neighbour_floor,
    neighbour_radii,
    silent_radius,
    trail_motion,
)
from agent.kinematics import TWO_PI, arc_step, body_velocity, wheel_command
from agent.law import (
    LawMemory,
    LawParams,
    governor_frame,
    last_velocity,
    law_step,
    may_pass,
    moved_estimate,
    pair_active,
)
from firmware_sim.world_step import FRESH, NONE, STALE, detect

prange = range   # numba.prange when compiled

# the law's memory per robot (control): floats prev_ex, prev_ey, center_x, center_y, radius,
# wheel_r, wheel_l, then the place exchange's since; ints has_prev, avoiding, side, passing,
# then the place exchange's slot, partner, other and giving (agent.exchange.Exchange)
MEM_F, MEM_I = 8, 8
PLACE, PLACE_SINCE = 4, 7


Grid = tuple[np.ndarray, np.ndarray, float, float, float, int, int]


def build_grid(px: np.ndarray, py: np.ndarray, cell: float, max_cells: int) -> Grid:
    """Cell lists of points (px, py): (start, order, x0, y0, cell, nx, ny).

    The points of cell (ix, iy) are ``order[start[c]:start[c + 1]]`` with c = ix * ny + iy,
    ix = floor((x - x0) / cell). The cell size grows beyond ``cell`` [m] when more than
    ``max_cells`` cells would be needed (a sparse, spread-out swarm), never shrinks.
    """
    n = len(px)
    x0, y0 = (px.min(), py.min()) if n else (0.0, 0.0)
    span_x, span_y = (px.max() - x0, py.max() - y0) if n else (0.0, 0.0)
    while (int(span_x / cell) + 1) * (int(span_y / cell) + 1) > max_cells:
        cell *= 2.0
    nx, ny = int(span_x / cell) + 1, int(span_y / cell) + 1
    start = np.zeros(nx * ny + 1, np.int64)
    key = np.empty(n, np.int64)
    for i in range(n):
        key[i] = int((px[i] - x0) / cell) * ny + int((py[i] - y0) / cell)
        start[key[i] + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[key[i]]] = i
        fill[key[i]] += 1
    return start, order, x0, y0, cell, nx, ny


def _cells_around(x: float, y: float, reach: float, x0: float, y0: float, cell: float,
                  nx: int, ny: int) -> tuple[int, int, int, int]:
    """(ix_lo, ix_hi, iy_lo, iy_hi): the cells that overlap the square of half-side
    ``reach`` [m] around (x, y), clipped to the grid; ix_lo > ix_hi when none does."""
    lo_x = max(int(math.floor((x - reach - x0) / cell)), 0)
    hi_x = min(int(math.floor((x + reach - x0) / cell)), nx - 1)
    lo_y = max(int(math.floor((y - reach - y0) / cell)), 0)
    hi_y = min(int(math.floor((y + reach - y0) / cell)), ny - 1)
    if lo_y > hi_y:
        hi_x = lo_x - 1
    return lo_x, hi_x, lo_y, hi_y


def sense_neighbours(i: int, x: float, y: float, sorted_xy: np.ndarray, sensing_range: float,
                     grid: Grid, cap: int, out_x: np.ndarray, out_y: np.ndarray,
                     out_d: np.ndarray, out_j: np.ndarray) -> int:
    """The robots whose centre is within ``sensing_range`` [m] of robot i at (x, y):
    their positions, distances and indices in the first entries of the outputs (at most
    ``cap``); returns how many there are. ``grid`` holds the swarm's positions and
    ``sorted_xy`` (N, 2) those positions in the grid's order (contiguous reads per cell)."""
    start, order, x0, y0, cell, nx, ny = grid
    r2 = sensing_range * sensing_range
    m = 0
    lo_x, hi_x, lo_y, hi_y = _cells_around(x, y, sensing_range, x0, y0, cell, nx, ny)
    for cx in range(lo_x, hi_x + 1):
        # the cells (cx, lo_y..hi_y) are consecutive in the grid's order
        for q in range(start[cx * ny + lo_y], start[cx * ny + hi_y + 1]):
            dx, dy = sorted_xy[q, 0] - x, sorted_xy[q, 1] - y
            d2 = dx * dx + dy * dy
            if d2 <= r2 and order[q] != i:
                if m < cap:
                    out_x[m], out_y[m] = sorted_xy[q, 0], sorted_xy[q, 1]
                    out_d[m], out_j[m] = math.sqrt(d2), order[q]
                m += 1
    return m


def sense_obstacles(x: float, y: float, obs: np.ndarray, sensing_range: float,
                    max_radius: float, grid: Grid, cap: int, out_x: np.ndarray,
                    out_y: np.ndarray, out_r: np.ndarray, out_k: np.ndarray) -> int:
    """The obstacles (K, 3) whose surface is within ``sensing_range`` [m] of (x, y) (``grid``
    of their centres, cells at least the range plus the largest radius): centres, radii
    and indices in the first entries of the outputs (at most ``cap``); returns how many."""
    start, order, x0, y0, cell, nx, ny = grid
    k = 0
    lo_x, hi_x, lo_y, hi_y = _cells_around(x, y, sensing_range + max_radius, x0, y0, cell, nx,
                                           ny)
    for cx in range(lo_x, hi_x + 1):
        for q in range(start[cx * ny + lo_y], start[cx * ny + hi_y + 1]):
            kk = order[q]
            dx, dy = obs[kk, 0] - x, obs[kk, 1] - y
            if math.sqrt(dx * dx + dy * dy) - obs[kk, 2] <= sensing_range:
                if k < cap:
                    out_x[k], out_y[k], out_r[k], out_k[k] = (obs[kk, 0], obs[kk, 1],
                                                              obs[kk, 2], kk)
                k += 1
    return k


def _watch(i: int, x: float, y: float, m: int, k: int, nbr_d: np.ndarray,
           nbr_j: np.ndarray, o_x: np.ndarray, o_y: np.ndarray, o_r: np.ndarray,
           o_k: np.ndarray, a: float, reach: float, watch_cap: int, out_near: np.ndarray,
           watch_j: np.ndarray, watch_k: np.ndarray) -> int:
    """Robot i's watch lists from the true neighbours (distances, indices) and obstacles
    around its true position (x, y) (see :func:`control`); returns the capacity needed."""
    nearest = math.inf
    for q in range(m):
        nearest = min(nearest, nbr_d[q])
    out_near[i, 0] = nearest
    limit = max(nearest, a) + 4.0 * reach
    w = 0
    for q in range(m):
        if nbr_j[q] > i and nbr_d[q] <= limit:
            if w < watch_cap:
                watch_j[i, w] = nbr_j[q]
            w += 1
    if w < watch_cap:
        watch_j[i, w] = -1
    lowest = math.inf
    for q in range(k):
        dx, dy = o_x[q] - x, o_y[q] - y
        lowest = min(lowest, math.sqrt(dx * dx + dy * dy) - o_r[q])
    out_near[i, 1] = lowest
    wk = 0
    for q in range(k):
        dx, dy = o_x[q] - x, o_y[q] - y
        if math.sqrt(dx * dx + dy * dy) - o_r[q] <= lowest + 2.0 * reach:
            if wk < watch_cap:
                watch_k[i, wk] = o_k[q]
            wk += 1
    if wk < watch_cap:
        watch_k[i, wk] = -1
    return max(w + 1, wk + 1)


def at_or_before(step: int, since: float, period: float, ring: int) -> int:
    """The row of the ring of the last periods' paths (``ring`` rows, ``step`` the current
    period's) of the period at or before ``since`` [s] ago (the oldest kept, if beyond)."""
    ago = min(max(int(math.ceil(since / period - 1e-9)), 0), ring - 1)
    return (step - ago) % ring


def at_or_after(step: int, since: float, period: float, ring: int) -> int:
    """The row, as :func:`at_or_before`, of the period at or after ``since`` [s] ago (the
    current one, if since is below a period)."""
    ago = min(max(int(math.floor(since / period + 1e-9)), 0), ring - 1)
    return (step - ago) % ring


def own_motion(path: np.ndarray, step: int, i: int, age: float, period: float,
               trail: np.ndarray) -> None:
    """Fill ``trail`` (agent.governor.neighbour_radii's rows) with robot ``i``'s motion
    over each split of the last ``age`` [s], from its path (``path``: the ring of the
    robots' (x, y, path length) of the last periods, ``step`` the current period's):
    from the period at or before each split's start, and at or after its end."""
    ring = len(path)
    now = path[step % ring, i]
    for piece in range(SPLITS):
        since = age * (SPLITS - piece) / SPLITS
        start = path[at_or_before(step, since, period, ring), i]
        end = path[at_or_after(step, since - age / SPLITS, period, ring), i]
        trail[0, piece] = now[2] - start[2]
        trail[1, piece] = now[2] - end[2]
        trail[2, piece] = now[0] - start[0]
        trail[3, piece] = now[1] - start[1]
        trail[4, piece] = now[0] - end[0]
        trail[5, piece] = now[1] - end[1]
    trail_motion(trail)


def _control_range(lo: int, hi: int, pose: np.ndarray, own: np.ndarray, seen: np.ndarray,
                   view: np.ndarray, path: np.ndarray, mem_f: np.ndarray,
                   mem_i: np.ndarray, held: np.ndarray,
                   offsets: np.ndarray,
                   motion: np.ndarray, t: float, obs: np.ndarray, p: LawParams,
                   period: float, sensing_range: float, a: float, reach: float, cap: int,
                   watch_cap: int, world_i: np.ndarray, world_f: np.ndarray,
                   sorted_seen: np.ndarray, seen_grid: Grid, sorted_xy: np.ndarray,
                   grid: Grid, obs_grid: Grid, outs: tuple[np.ndarray, ...]
                   ) -> tuple[int, int]:
    """:func:`control` for robots lo..hi - 1: returns (capacity, watch capacity) needed."""
    out_cmd, out_ref, out_mem_f, out_mem_i, out_held, out_near, watch_j, watch_k = outs
    truth, seed, step = world_i[0] != 0, world_i[1], world_i[2]
    det_noise, det_dropout = world_f[0], world_f[1]
    staleness, stop_time, top_speed = world_f[2], world_f[3], world_f[4]
    ring = len(path)                    # periods of the robots' own path kept
    wheel_top = TWO_PI * p.wheel_radius * p.speed_limit    # m/s, each wheel's ground speed
    lag = period + p.latency          # s, how late the wheels follow a reported command
    need, need_watch = 0, 0
    max_r = obs[:, 2].max() if len(obs) else 0.0
    nbr_x, nbr_y, nbr_d = np.empty(cap), np.empty(cap), np.empty(cap)
    nbr_j = np.empty(cap, np.int64)
    nbr_h = np.empty(cap)
    nbr_g = np.empty(cap)             # m, each neighbour's governor disc beyond a
    nbr_s, nbr_p, nbr_o = (np.empty(cap, np.int64), np.empty(cap, np.int64),
                           np.empty(cap, np.int64))   # their slot, partner, other
    o_x, o_y, o_r = np.empty(cap), np.empty(cap), np.empty(cap)
    o_k = np.empty(cap, np.int64)
    c_floor, c_q = np.empty(cap), np.empty(cap, np.int64)   # the neighbours with a disc
    trail = np.empty((TRAIL_ROWS, SPLITS))    # agent.governor.neighbour_radii's own motion
    for i in range(lo, hi):
        x, y = own[i, 0], own[i, 1]
        m = sense_neighbours(i, x, y, sorted_seen, sensing_range, seen_grid, cap, nbr_x,
                             nbr_y, nbr_d, nbr_j)
        k = sense_obstacles(x, y, obs, sensing_range, max_r, obs_grid, cap, o_x, o_y, o_r,
                            o_k)
        need = max(need, m, k)
        if m > cap or k > cap:
            continue
        if not truth:
            k = detect(i, step, seed, det_noise, det_dropout, k, o_x, o_y, o_r, o_k)
        mem = LawMemory(mem_f[i, 0], mem_f[i, 1], mem_i[i, 0] != 0, mem_i[i, 1] != 0,
                        mem_i[i, 2], mem_f[i, 2], mem_f[i, 3], mem_f[i, 4], mem_f[i, 5],
                        mem_f[i, 6], mem_i[i, 3])
        # the governor's limits among its hazards: the detected obstacles, and neighbours
        # where they can be by now given their data's age; all grown by the robot's own
        # position uncertainty (own[:, 3], with a pose source). The nearest neighbours
        # first, by a bound of the free distance toward their discs; a disc is computed
        # only where it can bind or the law can pass the neighbour (as
        # agent.node.Agent._limits). None with the governor off
        nbr_g[:m] = 0.0
        limits = NO_GAPS
        if p.governor:
            grow = own[i, 3] if own.shape[1] > 3 else 0.0
            v_now, u_now = last_velocity(mem, p)
            frame = governor_frame(own[i, 2], v_now, u_now, p, period)
            gaps = NO_GAPS
            for q in range(k):
                gaps = fold_hazard(gaps, frame, o_x[q] - x, o_y[q] - y, o_r[q] + a + grow,
                                   -math.inf, 0.0)
            n_c = 0
            walked_age, walked = math.nan, 0.0
            for q in range(m):
                j = nbr_j[q]
                if not truth and seen[j, 2] == NONE:
                    continue
                age = t - view[j, 5]
                if age != walked_age:     # this robot's path since: own_motion's first
                    walked_age = age
                    walked = (path[step % ring, i, 2]
                              - path[at_or_before(step, age, period, ring), i, 2])
                floor, top = neighbour_floor(x - view[j, 0], y - view[j, 1], view[j, 3], age,
                                             walked, a, p.accel, top_speed, staleness,
                                             p.speed_up, lag)
                floor -= 0.5 * grow
                # in order of the floor (insertion: a few neighbours, no allocation)
                c = n_c
                while c > 0 and c_floor[c - 1] > floor:
                    c_floor[c], c_q[c] = c_floor[c - 1], c_q[c - 1]
                    c -= 1
                c_floor[c], c_q[c] = floor, q
                nbr_g[q] = top + grow - a
                n_c += 1
            trails_age = math.nan
            bind = binding(gaps, frame)
            for c in range(n_c):
                q = c_q[c]
                j = nbr_j[q]
                if c_floor[c] >= bind:      # it cannot bind: is it one the law may pass?
                    dx, dy = nbr_x[q] - x, nbr_y[q] - y
                    if not may_pass(math.sqrt(dx * dx + dy * dy), nbr_g[q], p):
                        continue
                age = t - view[j, 5]
                if age != trails_age:       # neighbours heard in the same period share it
                    trails_age = age
                    own_motion(path, step, i, age, period, trail)
                full, half, east, north, claim = neighbour_radii(
                    x - view[j, 0], y - view[j, 1], view[j, 2], view[j, 3], view[j, 4], age,
                    trail, a, p.accel, 0.5 * p.wheel_base, top_speed, staleness, stop_time,
                    wheel_top, p.speed_up, lag, p.turn_up)
                gaps = fold_hazard(gaps, frame, view[j, 0] + east - x, view[j, 1] + north - y,
                                   full + grow, half + grow, 1.0 if age <= staleness else 0.0)
                bind = binding(gaps, frame)
                nbr_g[q] = claim + grow - a
            limits = frame_limits(gaps, frame)
        if not truth:
            # stale neighbours become static obstacles; unheard ones are unknown
            fresh = 0
            for q in range(m):
                status = seen[nbr_j[q], 2]
                if status == STALE:
                    if k < cap:
                        j = nbr_j[q]
                        o_x[k], o_y[k], o_k[k] = nbr_x[q], nbr_y[q], -1
                        o_r[k] = silent_radius(view[j, 3], 0.5 * view[j, 4] * p.wheel_base,
                                               a, p.accel, top_speed, staleness,
                                               stop_time, wheel_top, p.speed_up, lag,
                                               p.turn_up)
                    k += 1
                elif status == FRESH:
                    nbr_x[fresh], nbr_y[fresh], nbr_j[fresh] = nbr_x[q], nbr_y[q], nbr_j[q]
                    nbr_g[fresh] = nbr_g[q]
                    fresh += 1
            m = fresh
            need = max(need, k)
            if k > cap:
                continue
        ex = Exchange(mem_i[i, PLACE], mem_i[i, PLACE + 1], mem_i[i, PLACE + 2],
                      mem_i[i, PLACE + 3] != 0, mem_f[i, PLACE_SINCE])
        if p.exchange > 0.0:
            for q in range(m):
                j = nbr_j[q]
                nbr_s[q], nbr_p[q], nbr_o[q] = int(view[j, 6]), int(view[j, 7]), int(view[j, 8])
            was, pal = ex.slot, ex.partner
            pal_slot, pal_partner, pal_age = NOBODY, NOBODY, math.inf
            if pal != NOBODY and view[pal, 5] > -math.inf:
                pal_slot, pal_partner = int(view[pal, 6]), int(view[pal, 7])
                pal_age = t - view[pal, 5]
            ex = exchange_step(i, x, y, t, ex, nbr_j[:m], nbr_x[:m], nbr_y[:m], nbr_s[:m],
                               nbr_p[:m], nbr_o[:m], pal_slot, pal_partner, pal_age,
                               view[:, 6], offsets, motion, p.exchange, staleness)
            if ex.slot != was:      # the error's finite difference sees no jump
                ox, oy = place(offsets, motion, was, t)
                nx, ny = place(offsets, motion, ex.slot, t)
                mem = moved_estimate(mem, ox - nx, oy - ny)
        slot = ex.slot
        rx, ry, rvx, rvy = reference_point(offsets[slot, 0], offsets[slot, 1], motion[0],
                                           motion[1], motion[2], motion[3], motion[4], t)
        # the pairs active last period (per-pair hysteresis); held lists are short
        for q in range(m):
            nbr_h[q] = 0.0
            for w in range(held.shape[1]):
                if held[i, w] < 0:
                    break
                if held[i, w] == nbr_j[q]:
                    nbr_h[q] = 1.0
        v, u, mode, allowed, new = law_step(x, y, own[i, 2], rx, ry, rvx, rvy, nbr_x[:m],
                                            nbr_y[:m], nbr_h[:m], nbr_g[:m], o_x[:k],
                                            o_y[:k], o_r[:k],
                                            limits, mem, p, period)
        out_cmd[i, 0], out_cmd[i, 1], out_cmd[i, 2], out_cmd[i, 3] = v, u, mode, allowed
        out_ref[i, 0], out_ref[i, 1], out_ref[i, 2], out_ref[i, 3] = rx, ry, rvx, rvy
        out_mem_f[i, 0], out_mem_f[i, 1] = new.prev_ex, new.prev_ey
        out_mem_f[i, 2], out_mem_f[i, 3], out_mem_f[i, 4] = (new.center_x, new.center_y,
                                                             new.radius)
        out_mem_f[i, 5], out_mem_f[i, 6] = new.wheel_r, new.wheel_l
        out_mem_i[i, 0], out_mem_i[i, 1], out_mem_i[i, 2] = (int(new.has_prev),
                                                             int(new.avoiding), new.side)
        out_mem_i[i, 3] = new.passing
        out_mem_i[i, PLACE], out_mem_i[i, PLACE + 1] = ex.slot, ex.partner
        out_mem_i[i, PLACE + 2], out_mem_i[i, PLACE + 3] = ex.other, int(ex.giving)
        out_mem_f[i, PLACE_SINCE] = ex.since
        w = 0
        for q in range(m):
            dx, dy = nbr_x[q] - x, nbr_y[q] - y
            if pair_active(dx * dx + dy * dy, nbr_h[q] > 0.5, p.b, p.hysteresis):
                out_held[i, w] = nbr_j[q]
                w += 1
        out_held[i, w] = -1
        # what to watch during the period: around the truth
        if not truth:
            x, y = pose[i, 0], pose[i, 1]
            m = sense_neighbours(i, x, y, sorted_xy, sensing_range, grid, cap, nbr_x, nbr_y,
                                 nbr_d, nbr_j)
            k = sense_obstacles(x, y, obs, sensing_range, max_r, obs_grid, cap, o_x, o_y,
                                o_r, o_k)
            need = max(need, m, k)
            if m > cap or k > cap:
                continue
        need_watch = max(need_watch, _watch(i, x, y, m, k, nbr_d, nbr_j, o_x, o_y, o_r, o_k,
                                            a, reach, watch_cap, out_near, watch_j, watch_k))
    return need, need_watch


def _sorted(pos: np.ndarray, grid: Grid) -> np.ndarray:
    """Positions (N, >= 2) [m] in the order of ``grid`` (contiguous reads per cell)."""
    out = np.empty((len(pos), 2))
    for q in range(len(pos)):
        out[q, 0], out[q, 1] = pos[grid[1][q], 0], pos[grid[1][q], 1]
    return out


def control(pose: np.ndarray, own: np.ndarray, seen: np.ndarray, view: np.ndarray,
            path: np.ndarray, mem_f: np.ndarray, mem_i: np.ndarray, held: np.ndarray,
            offsets: np.ndarray,
            motion: np.ndarray,
            t: float, obs: np.ndarray, p: LawParams, period: float, sensing_range: float, a: float,
            reach: float, cap: int, watch_cap: int, world_i: np.ndarray,
            world_f: np.ndarray, out_cmd: np.ndarray, out_ref: np.ndarray,
            out_mem_f: np.ndarray, out_mem_i: np.ndarray, out_held: np.ndarray,
            out_near: np.ndarray, watch_j: np.ndarray, watch_k: np.ndarray) -> tuple[int, int]:
    """Sense and run the law for every robot.

    pose (N, 3) [m, m, rad] the truth; own (N, 3) the pose each robot believes it has
    (N, 4 with a pose source: and its position uncertainty [m], which grows every hazard);
    seen (N, 3) where the robots believe the others are: x, y [m] and NONE, FRESH or STALE
    (:mod:`firmware_sim.world_step`); view (N, 9) the states they last received from each
    other (x, y, theta, v, u, stamp [s], slot, partner, other), for the governor's
    hazards and the place exchange; path (K, N, 3) [m] each robot's believed position x,
    y and the cumulative path through them, a ring over its last K periods (period number
    p in row p % K; rows not written yet the start; older data counts K - 1 periods);
    world_i = (1 when own and seen are the truth and detections exact, seed, period
    number), world_f = (detection noise [m], detection dropout, staleness [s], stop time
    of a dead agent [s], top speed [m/s]) (:func:`agent.governor.neighbour_hazard`; a
    stale neighbour is an obstacle of :func:`agent.governor.silent_radius`). Memory of
    :class:`LawMemory` and of :class:`agent.exchange.Exchange` as floats (N, MEM_F) and
    ints (N, MEM_I) (MEM_F); held (N, cap + 1) the indices of the robots each robot's
    pairs with which were active (:func:`agent.law.pair_active`), -1 ending
    the list; offsets (N, 2) [m] the formation's places and motion (5,) = centre0 x, y
    [m], velocity x, y [m/s],
    omega [rad/s] of the formation; obs (K, 3) = obstacle centre x, y and radius [m].
    Out: out_cmd (N, 4) = v [m/s], u [rad/s], mode, the speed the governor allowed when it
    acted [m/s] (inf: it did not); out_ref (N, 4) = p_d, p_d_dot; the new memory and held
    lists;
    out_near (N, 2) [m]: the true distance to the nearest neighbour and the smallest
    clearance to an obstacle in range (inf: none); the watch lists, on the truth:
    watch_j (N, watch_cap) the robots j > i whose distance is within
    max(nearest of i, a) + 4 reach (``reach`` [m]: the farthest a robot moves in a period),
    watch_k (N, watch_cap) the obstacles whose clearance is within the robot's smallest + 2
    reach; -1 ends a list. Returns the capacities needed: (neighbours or obstacles sensed
    by one robot, watch list); one above ``cap`` or ``watch_cap`` means the results are
    incomplete: call again with the capacities returned.
    """
    n, k_obs = len(pose), len(obs)
    grid = build_grid(pose[:, 0], pose[:, 1], sensing_range, 4 * n + 64)
    sorted_xy = _sorted(pose, grid)
    if world_i[0] != 0:
        seen_grid, sorted_seen = grid, sorted_xy
    else:
        seen_grid = build_grid(seen[:, 0], seen[:, 1], sensing_range, 4 * n + 64)
        sorted_seen = _sorted(seen, seen_grid)
    max_r = obs[:, 2].max() if k_obs else 0.0
    obs_grid = build_grid(obs[:, 0], obs[:, 1], sensing_range + max_r, 4 * max(n, k_obs) + 64)
    chunks = min(n, 64)
    need = np.zeros((chunks, 2), np.int64)
    outs = (out_cmd, out_ref, out_mem_f, out_mem_i, out_held, out_near, watch_j, watch_k)
    for chunk in prange(chunks):
        # the robots of a chunk in a plain function: numba optimises it better than the
        # body of a parallel loop
        need[chunk, 0], need[chunk, 1] = _control_range(
            chunk * n // chunks, (chunk + 1) * n // chunks, pose, own, seen, view, path, mem_f,
            mem_i, held, offsets, motion, t, obs, p, period, sensing_range, a, reach, cap,
            watch_cap, world_i, world_f, sorted_seen, seen_grid, sorted_xy, grid, obs_grid,
            outs)
    return (need[:, 0].max(), need[:, 1].max()) if chunks else (0, 0)


def advance(pose: np.ndarray, cmd: np.ndarray, wheels: np.ndarray, slip: np.ndarray,
            enc: np.ndarray, ideal: bool, wheel_radius: float, wheel_base: float,
            speed_limit: float, ramp: float, dt: float, substeps: int, watched: np.ndarray,
            out_pos: np.ndarray) -> None:
    """Move every robot through ``substeps`` physics steps of ``dt`` [s]; pose updated.

    ``ideal``: the commands (v, u) of ``cmd[0]`` applied exactly (one exact arc from the
    period's start, evaluated at each substep; only at the period's end for robots not
    ``watched``). Otherwise through the wheel drivers: in substep s the drivers follow the
    commands ``cmd[s - 1]`` (substeps, N, >= 2) (those issued a drive latency earlier),
    set-points of :func:`wheel_command` (speed limit [rev/s]), wheel speeds ``wheels``
    (N, 2) (right, left) [rev/s] ramped at ``ramp`` [rev/s^2] and held over each substep;
    the wheels turn ``enc`` (N, 2) [rev] further and move the ground by (1 - ``slip``) (N,
    2) of that.
    out_pos (substeps + 1, N, 2): positions at the period's start and after each substep
    (of the watched robots at least).
    """
    for i in prange(len(pose)):
        x, y, th = pose[i, 0], pose[i, 1], pose[i, 2]
        out_pos[0, i, 0], out_pos[0, i, 1] = x, y
        if ideal:
            v, u = cmd[0, i, 0], cmd[0, i, 1]
            for s in range(1 if watched[i] else substeps, substeps + 1):
                h = s * dt
                px, py, pth = arc_step(x, y, th, v * h, u * h)
                out_pos[s, i, 0], out_pos[s, i, 1] = px, py
            pose[i, 0], pose[i, 1], pose[i, 2] = px, py, pth
        else:
            step = ramp * dt
            wr, wl = wheels[i, 0], wheels[i, 1]
            grip_r, grip_l = 1.0 - slip[i, 0], 1.0 - slip[i, 1]
            for s in range(1, substeps + 1):
                target_r, target_l = wheel_command(cmd[s - 1, i, 0], cmd[s - 1, i, 1],
                                                   wheel_radius, wheel_base, speed_limit)
                wr += min(max(target_r - wr, -step), step)
                wl += min(max(target_l - wl, -step), step)
                enc[i, 0] += wr * dt
                enc[i, 1] += wl * dt
                bv, bu = body_velocity(TWO_PI * wr * grip_r, TWO_PI * wl * grip_l,
                                       wheel_radius, wheel_base)
                x, y, th = arc_step(x, y, th, bv * dt, bu * dt)
                out_pos[s, i, 0], out_pos[s, i, 1] = x, y
            wheels[i, 0], wheels[i, 1] = wr, wl
            pose[i, 0], pose[i, 1], pose[i, 2] = x, y, th


def geometry(pos: np.ndarray, watch_j: np.ndarray, watch_k: np.ndarray, obs: np.ndarray,
             a: float, first: int, pair_limit: float, clear_limit: float,
             watched: np.ndarray, out_dmin: np.ndarray, out_cmin: np.ndarray,
             out_who: np.ndarray, hit_j: np.ndarray, hit_k: np.ndarray) -> int:
    """Closest pair and smallest clearance at each substep s >= ``first`` of ``pos`` (S, N,
    2), over the watch lists of :func:`control` of the ``watched`` robots, for the pairs
    no farther than ``pair_limit`` [m] and the obstacles no farther than ``clear_limit`` [m]
    at the period's start: out_dmin, out_cmin (S,) [m] (inf: none), out_who (S, 4) = the
    closest pair's robot indices and the robot and obstacle of the smallest clearance (-1:
    none). hit_j / hit_k (N, cap) are set where a watched pair came closer than a / a robot
    centre entered a watched obstacle; returns how many robots set one.

    Robots move at most ``reach`` per period, so with pair_limit = max(closest pair, a) +
    4 reach and clear_limit = max(smallest clearance, 0) + 2 reach the minima and the hits
    found are exact.
    """
    n_sub, n = pos.shape[0], pos.shape[1]
    d_robot = np.full((n_sub, n), np.inf)
    c_robot = np.full((n_sub, n), np.inf)
    j_robot = np.full((n_sub, n), -1, np.int64)
    k_robot = np.full((n_sub, n), -1, np.int64)
    hit = np.zeros(n, np.int64)
    for i in prange(n):
        if not watched[i]:
            continue
        x0, y0 = pos[0, i, 0], pos[0, i, 1]
        for w in range(watch_j.shape[1]):
            j = watch_j[i, w]
            if j < 0:
                break
            dx, dy = pos[0, j, 0] - x0, pos[0, j, 1] - y0
            if math.sqrt(dx * dx + dy * dy) > pair_limit:
                continue
            for s in range(first, n_sub):
                dx, dy = pos[s, j, 0] - pos[s, i, 0], pos[s, j, 1] - pos[s, i, 1]
                d = math.sqrt(dx * dx + dy * dy)
                if d < d_robot[s, i]:
                    d_robot[s, i], j_robot[s, i] = d, j
                if d < a:
                    hit_j[i, w] = True
                    hit[i] = 1
        for w in range(watch_k.shape[1]):
            k = watch_k[i, w]
            if k < 0:
                break
            dx, dy = obs[k, 0] - x0, obs[k, 1] - y0
            if math.sqrt(dx * dx + dy * dy) - obs[k, 2] > clear_limit:
                continue
            for s in range(first, n_sub):
                dx, dy = obs[k, 0] - pos[s, i, 0], obs[k, 1] - pos[s, i, 1]
                c = math.sqrt(dx * dx + dy * dy) - obs[k, 2]
                if c < c_robot[s, i]:
                    c_robot[s, i], k_robot[s, i] = c, k
                if c < 0.0:
                    hit_k[i, w] = True
                    hit[i] = 1
    for s in range(n_sub):
        out_dmin[s], out_cmin[s] = math.inf, math.inf
        for c in range(4):
            out_who[s, c] = -1
        for i in range(n):
            if d_robot[s, i] < out_dmin[s]:
                out_dmin[s], out_who[s, 0], out_who[s, 1] = d_robot[s, i], i, j_robot[s, i]
            if c_robot[s, i] < out_cmin[s]:
                out_cmin[s], out_who[s, 2], out_who[s, 3] = c_robot[s, i], i, k_robot[s, i]
    return hit.sum()


def period_summary(pose: np.ndarray, cmd: np.ndarray, ref: np.ndarray, K: float,
                   margin: float, first: bool, alive: np.ndarray, last_mode: np.ndarray,
                   out_err: np.ndarray, out_within: np.ndarray) -> tuple[float, float, int, bool]:
    """The period's convergence and command metrics: each robot's tracking error [m]
    (out_err) and whether it is within |p_d_dot| / K + ``margin`` (out_within; a robot not
    ``alive`` counts as within); returns (max |v| [m/s], max |u| [rad/s], mode switches
    since ``last_mode`` (none when ``first``), all within). ``last_mode`` is updated to this
    period's modes."""
    max_v, max_u, switches, all_within = 0.0, 0.0, 0, True
    for i in range(len(pose)):
        ex, ey = pose[i, 0] - ref[i, 0], pose[i, 1] - ref[i, 1]
        out_err[i] = math.sqrt(ex * ex + ey * ey)
        tol = math.sqrt(ref[i, 2] * ref[i, 2] + ref[i, 3] * ref[i, 3]) / K + margin
        out_within[i] = out_err[i] <= tol or not alive[i]
        all_within = all_within and out_within[i]
        max_v, max_u = max(max_v, abs(cmd[i, 0])), max(max_u, abs(cmd[i, 1]))
        if not first and cmd[i, 2] != last_mode[i]:
            switches += 1
        last_mode[i] = cmd[i, 2]
    return max_v, max_u, switches, all_within
