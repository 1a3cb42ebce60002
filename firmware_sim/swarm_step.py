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
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from agent.exchange import Exchange
from agent.kinematics import TWO_PI, arc_step, body_velocity
from agent.law import LawMemory
from agent.neighbours import Reports
from agent.params import PeriodParams
from agent.period import Detections, Inputs, Memory, Own, Workspace, robot_period
from agent.trail import SPLITS, OwnPath, Splits
from firmware_sim.world_step import detect

if TYPE_CHECKING:
    from agent.formation import Places
    from agent.params import LawParams, NeighbourModel

prange = range   # numba.prange when compiled

# a robot's memory (agent.period.Memory) as a record of the batch's memory arrays: its
# law's, then its place exchange's (load_memory, store_memory)
MEMORY = np.dtype([(name, {float: np.float64, bool: np.bool_, int: np.int64}[type(value)])
                   for record in (LawMemory(), Exchange(0))
                   for name, value in zip(record._fields, record)])


SPLIT_ROWS = len(Splits._fields)


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


class SwarmState(NamedTuple):
    """What every robot knows at a period's start, by robot index (the robots' ids are
    their indices): the inputs of their periods that the batch simulator keeps."""

    own: np.ndarray         # (N, 3) believed pose [m, m, rad]; (N, 4) with a pose source:
    #                         and the position's uncertainty [m]
    jump: np.ndarray        # (N, 2) m, what pose fixes moved each estimate this period
    seen: np.ndarray        # (N, 3) where each report puts its robot now, x, y [m], and
    #                         NONE, FRESH or STALE (firmware_sim.world_step): the grid's
    path: np.ndarray        # (N, 3, K) each robot's believed x, y [m] and the path [m]
    #                         walked through them over its last K periods, a ring
    path_t: np.ndarray      # (K,) s, the ring's times
    path_first: int         # the ring's oldest record
    path_n: int         # records kept
    memory: np.ndarray      # (N,) MEMORY records
    held: np.ndarray        # (N, C) the ids of each robot's pairs active, -1 ending


class Outputs(NamedTuple):
    """What :func:`control` writes, by robot index."""

    cmd: np.ndarray         # (N, 6) v [m/s], u [rad/s], mode, the speed the governor
    #                         allowed when it acted [m/s] (inf: it did not), the wheels'
    #                         set-points right, left [rev/s]
    ref: np.ndarray         # (N, 4) p_d [m], p_d_dot [m/s]
    memory: np.ndarray      # (N,) MEMORY records
    held: np.ndarray        # (N, C) as SwarmState.held
    near: np.ndarray        # (N, 2) m, the true distance to the nearest neighbour and the
    #                         smallest clearance to an obstacle in range (inf: none)
    watch_j: np.ndarray     # (N, W) the robots j > i to watch, -1 ending
    watch_k: np.ndarray     # (N, W) the obstacles to watch, -1 ending


class World(NamedTuple):
    """The period's world for :func:`control`."""

    t: float                # s, mission time
    period: float           # s
    step: int               # the period's number
    truth: bool             # the robots know the truth (own, seen and reports are it)
    seed: int
    det_noise: float        # m, detection noise (firmware_sim.world_step.detect)
    det_dropout: float
    query: float            # m, the reports' positions looked at round each robot
    reach: float            # m, the farthest a robot moves in a period


def load_memory(rec: np.void) -> Memory:
    """A robot's :class:`agent.period.Memory` from its MEMORY record."""
    return Memory(LawMemory(rec["prev_ex"], rec["prev_ey"], rec["has_prev"], rec["avoiding"],
                            rec["side"], rec["center_x"], rec["center_y"], rec["radius"],
                            rec["wheel_r"], rec["wheel_l"], rec["passing"]),
                  Exchange(rec["slot"], rec["partner"], rec["other"], rec["giving"],
                           rec["since"]))


def store_memory(rec: np.void, mem: Memory) -> None:
    """Write ``mem`` into a MEMORY record (:func:`load_memory`)."""
    law, ex = mem.law, mem.exchange
    rec["prev_ex"], rec["prev_ey"] = law.prev_ex, law.prev_ey
    rec["has_prev"], rec["avoiding"], rec["side"] = law.has_prev, law.avoiding, law.side
    rec["center_x"], rec["center_y"], rec["radius"] = law.center_x, law.center_y, law.radius
    rec["wheel_r"], rec["wheel_l"], rec["passing"] = law.wheel_r, law.wheel_l, law.passing
    rec["slot"], rec["partner"], rec["other"] = ex.slot, ex.partner, ex.other
    rec["giving"], rec["since"] = ex.giving, ex.since


def workspace(cap: int) -> Workspace:
    """Scratch columns for robot_period among ``cap`` reports and ``cap`` detections."""
    splits = np.zeros((SPLIT_ROWS, SPLITS))
    return Workspace(np.empty(cap), np.empty(cap), np.empty(cap), np.empty(cap),
                     np.empty(cap, np.int64), np.empty(2 * cap), np.empty(2 * cap),
                     np.empty(2 * cap), np.empty(cap, np.int64), np.empty(cap, np.int64),
                     np.empty(cap), np.empty(cap, np.int64),
                     Splits(splits[0], splits[1], splits[2], splits[3], splits[4], splits[5],
                            splits[6], splits[7], splits[8], splits[9]),
                     np.full(2 * SPLITS, -1, np.int64), np.empty(cap, np.int64))


def _control_range(lo: int, hi: int, pose: np.ndarray, s: SwarmState, reports: Reports,
                   out: Outputs, places: Places, obs: np.ndarray, law: LawParams,
                   model: NeighbourModel, sensing_range: float, w: World,
                   sorted_seen: np.ndarray, seen_grid: Grid, sorted_xy: np.ndarray, grid: Grid,
                   obs_grid: Grid, cap: int, watch_cap: int) -> tuple[int, int]:
    """:func:`control` for robots lo..hi - 1: returns (capacity, watch capacity) needed."""
    p = PeriodParams(law, model, sensing_range)
    a = model.a
    need, need_watch = 0, 0
    max_r = obs[:, 2].max() if len(obs) else 0.0
    nbr_x, nbr_y, nbr_d = np.empty(cap), np.empty(cap), np.empty(cap)
    nbr_j = np.empty(cap, np.int64)
    o_x, o_y, o_r = np.empty(cap), np.empty(cap), np.empty(cap)
    o_k = np.empty(cap, np.int64)
    ws = workspace(cap)
    size = len(s.path_t)
    for i in range(lo, hi):
        x, y = s.own[i, 0], s.own[i, 1]
        # the reports that may put a robot in range, and the obstacles in range, detected
        m = sense_neighbours(i, x, y, sorted_seen, w.query, seen_grid, cap, nbr_x, nbr_y,
                             nbr_d, nbr_j)
        k = sense_obstacles(x, y, obs, sensing_range, max_r, obs_grid, cap, o_x, o_y, o_r,
                            o_k)
        need = max(need, m, k)
        if m > cap or k > cap:
            continue
        if not w.truth:
            k = detect(i, w.step, w.seed, w.det_noise, w.det_dropout, k, o_x, o_y, o_r, o_k)
        held = s.held[i]
        n_held = 0
        while held[n_held] >= 0:
            n_held += 1
        grow = s.own[i, 3] if s.own.shape[1] > 3 else 0.0
        inputs = Inputs(Own(i, x, y, s.own[i, 2], grow, s.jump[i, 0], s.jump[i, 1]), w.t, w.t,
                        w.period, reports, nbr_j, m, Detections(o_x, o_y, o_r, k), places,
                        OwnPath(s.path_t, s.path[i, 0], s.path[i, 1], s.path[i, 2],
                                s.path_first, s.path_n, size),
                        held, n_held)
        got = robot_period(inputs, load_memory(s.memory[i]), p, ws)
        cmd = out.cmd[i]
        cmd[0], cmd[1], cmd[2], cmd[3] = got.v, got.u, got.mode, got.governed
        cmd[4], cmd[5] = got.right, got.left
        ref = got.reference
        out.ref[i, 0], out.ref[i, 1], out.ref[i, 2], out.ref[i, 3] = ref.x, ref.y, ref.vx, ref.vy
        store_memory(out.memory[i], got.memory)
        for h in range(got.n_held):
            out.held[i, h] = ws.held[h]
        out.held[i, got.n_held] = -1
        # what to watch during the period: around the truth
        if not w.truth:
            x, y = pose[i, 0], pose[i, 1]
            m = sense_neighbours(i, x, y, sorted_xy, sensing_range, grid, cap, nbr_x, nbr_y,
                                 nbr_d, nbr_j)
            k = sense_obstacles(x, y, obs, sensing_range, max_r, obs_grid, cap, o_x, o_y,
                                o_r, o_k)
            need = max(need, m, k)
            if m > cap or k > cap:
                continue
        need_watch = max(need_watch, _watch(i, x, y, m, k, nbr_d, nbr_j, o_x, o_y, o_r, o_k,
                                            a, w.reach, watch_cap, out.near, out.watch_j,
                                            out.watch_k))
    return need, need_watch


def _sorted(pos: np.ndarray, grid: Grid) -> np.ndarray:
    """Positions (N, >= 2) [m] in the order of ``grid`` (contiguous reads per cell)."""
    out = np.empty((len(pos), 2))
    for q in range(len(pos)):
        out[q, 0], out[q, 1] = pos[grid[1][q], 0], pos[grid[1][q], 1]
    return out


def control(pose: np.ndarray, s: SwarmState, reports: Reports, out: Outputs, places: Places,
            obs: np.ndarray, p: PeriodParams, w: World, cap: int, watch_cap: int
            ) -> tuple[int, int]:
    """Every robot's period (agent.period.robot_period) on what it knows (``s`` and every
    robot's newest ``reports``, as delivered to all alike), into ``out``; ``pose`` (N, 3)
    [m, m, rad] the truth, ``places`` the formation's, ``obs`` (K, 3) the obstacles'
    centres x, y and radii [m].

    Each robot looks at the reports of the robots ``w.query`` [m] round it by where they
    put them now (``s.seen``), found through uniform grids (cell lists), and at the
    obstacles whose surface is within the sensing range; in an imperfect world it detects
    them with noise and dropout. The watch lists are on the truth: the robots j > i whose
    distance is within max(nearest of i, a) + 4 reach, the obstacles whose clearance is
    within the robot's smallest + 2 reach.

    Returns the capacities needed: (reports or obstacles looked at by one robot, watch
    list); one above ``cap`` or ``watch_cap`` means the results are incomplete: call again
    with the capacities returned (``s.held`` and ``out.held`` at least cap + 1 wide)."""
    n, k_obs = len(pose), len(obs)
    sensing_range = p.sensing_range
    grid = build_grid(pose[:, 0], pose[:, 1], sensing_range, 4 * n + 64)
    sorted_xy = _sorted(pose, grid)
    if w.truth:
        seen_grid, sorted_seen = grid, sorted_xy
    else:
        seen_grid = build_grid(s.seen[:, 0], s.seen[:, 1], sensing_range, 4 * n + 64)
        sorted_seen = _sorted(s.seen, seen_grid)
    max_r = obs[:, 2].max() if k_obs else 0.0
    obs_grid = build_grid(obs[:, 0], obs[:, 1], sensing_range + max_r, 4 * max(n, k_obs) + 64)
    return _control_chunks(pose, s, reports, out, places, obs, p.law, p.model, sensing_range,
                           w, sorted_seen, seen_grid, sorted_xy, grid, obs_grid, cap,
                           watch_cap)


def _control_chunks(pose: np.ndarray, s: SwarmState, reports: Reports, out: Outputs,
                    places: Places, obs: np.ndarray, law: LawParams, model: NeighbourModel,
                    sensing_range: float, w: World, sorted_seen: np.ndarray, seen_grid: Grid,
                    sorted_xy: np.ndarray, grid: Grid, obs_grid: Grid, cap: int,
                    watch_cap: int) -> tuple[int, int]:
    """:func:`control`'s robots in chunks, in parallel when compiled. Its arguments are
    flat records, each an argument: numba passes no record of records, nor one it cannot
    trace to an argument, into a parallel loop's body."""
    n = len(pose)
    chunks = min(n, 64)
    need = np.zeros((chunks, 2), np.int64)
    for chunk in prange(chunks):
        # the robots of a chunk in a plain function: numba optimises it better than the
        # body of a parallel loop
        need[chunk, 0], need[chunk, 1] = _control_range(
            chunk * n // chunks, (chunk + 1) * n // chunks, pose, s, reports, out, places, obs,
            law, model, sensing_range, w, sorted_seen, seen_grid, sorted_xy, grid, obs_grid,
            cap, watch_cap)
    return (need[:, 0].max(), need[:, 1].max()) if chunks else (0, 0)


def advance(pose: np.ndarray, cmd: np.ndarray, wheels: np.ndarray, slip: np.ndarray,
            enc: np.ndarray, ideal: bool, wheel_radius: float, wheel_base: float,
            speed_limit: float, ramp: float, dt: float, substeps: int, watched: np.ndarray,
            out_pos: np.ndarray) -> None:
    """Move every robot through ``substeps`` physics steps of ``dt`` [s]; pose updated.

    ``ideal``: the commands (v, u) of ``cmd[0]`` applied exactly (one exact arc from the
    period's start, evaluated at each substep; only at the period's end for robots not
    ``watched``). Otherwise through the wheel drivers: in substep s the drivers follow the
    wheel set-points ``cmd[s - 1]`` (substeps, N, 2) [rev/s] (those issued a drive latency
    earlier), each clamped to the speed limit [rev/s] as a driver clamps its axis, wheel
    speeds ``wheels`` (N, 2) (right, left) [rev/s] ramped at ``ramp`` [rev/s^2] and held
    over each substep;
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
                target_r = min(max(cmd[s - 1, i, 0], -speed_limit), speed_limit)
                target_l = min(max(cmd[s - 1, i, 1], -speed_limit), speed_limit)
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
