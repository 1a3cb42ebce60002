"""One robot's control period, written once: what it senses, its place exchange, its safety
governor, the law, and what it remembers.

:func:`robot_period` takes everything one robot knows in one period (:class:`Inputs`: its
believed pose, every robot's newest report, its detections, the mission's places, its own
path, the pairs it avoided) with its :class:`Memory` and its :class:`agent.params.PeriodParams`,
and returns the command, the new memory and what it observed (:class:`PeriodOut`). It is
pure but for its :class:`Workspace`, scratch columns the caller hands in and may read after
the call. An agent (agent.node) runs it interpreted on lists, once per tick; the batch
simulator (firmware_sim.swarm_step) compiles this same source with numba and runs it for
every robot. Everything else in either is gathering the inputs and applying the outputs.

In order (docs/controller.md section 5):

1. A pose fix's jump moves the remembered error (agent.law.moved_estimate).
2. Sensing (:func:`sense`): the detected obstacles; each neighbour heard from moved along
   its arc to now (A8); those in the sensing range are the law's neighbours, a silent one
   (older than the staleness limit) in range is a static obstacle (A7); every one that may
   be within the sensing range by now (its report within the range plus what the fastest
   robot travels in its data's age) is a hazard of the governor.
3. The place exchange (A18) and the reference of the place held.
4. The safety governor's limits (:func:`governor_limits`, A10): the detected obstacles and
   the neighbours' discs, the nearest first, those that cannot bind left out.
5. The law (agent.law.law_step), and the pairs that are active for the next period (A3).

Metres, seconds, radians; world frame ENU. Times (stamps, the path's, ``now``) are in one
clock: UNIX time in an agent, mission time in the batch simulator.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

from agent.avoidance import Surroundings
from agent.discs import neighbour_floor, neighbour_radii, silent_radius
from agent.exchange import NOBODY, Exchange, Heard, exchange_step
from agent.formation import place, reference
from agent.governor import (
    NO_GAPS,
    NO_LIMITS,
    Limits,
    binding,
    braking_of,
    fold_hazard,
    frame_limits,
    limit_frame,
)
from agent.kinematics import wheel_command
from agent.law import (
    LawMemory,
    Reference,
    last_velocity,
    law_step,
    may_pass,
    moved_estimate,
    pair_active,
)
from agent.neighbours import Reports, extrapolate
from agent.trail import TIME_TOL, OwnPath, Splits, own_motion, path_since

if TYPE_CHECKING:
    from agent.avoidance import FloatBuf, FloatSeq, IntBuf, IntSeq
    from agent.formation import Places
    from agent.params import PeriodParams

RANGE_PAD = 1e-6      # m, a neighbour this much beyond the range is not moved along its arc


class Own(NamedTuple):
    """What the robot knows of itself."""

    robot: int          # its id
    x: float            # m, its believed pose
    y: float            # m
    theta: float        # rad
    uncertainty: float  # m, how far its position may be off (0 without a pose source)
    jump_x: float       # m, how far a pose fix moved the estimate since the last period
    jump_y: float       # m


class Detections(NamedTuple):
    """The obstacles the robot detects: the first ``n`` entries, centres and radii [m]."""

    x: FloatSeq
    y: FloatSeq
    r: FloatSeq
    n: int


class Inputs(NamedTuple):
    """Everything one robot knows in one period."""

    own: Own
    now: float          # s, the clock of the reports' stamps and the path
    t: float            # s, mission time
    dt: float           # s since the last period
    reports: Reports    # every robot's newest report
    near: IntSeq        # the rows of ``reports`` that may be in range (the first n_near)
    n_near: int
    detections: Detections
    places: Places
    path: OwnPath       # its own believed positions of the last seconds
    held: IntSeq        # the ids of the robots whose pair was active last period (A3),
    n_held: int         # the first n_held


class Memory(NamedTuple):
    """What a robot carries from one period to the next (with :attr:`Inputs.held`)."""

    law: LawMemory
    exchange: Exchange


class Workspace(NamedTuple):
    """Scratch columns of :func:`robot_period`, each at least as long as the rows it looks
    at (the obstacle columns as those and the detections together); after a call, the
    first ``n_nbr`` entries of the neighbour columns are the law's neighbours and the first
    ``n_held`` of ``held`` the pairs active this period."""

    nbr_x: FloatBuf     # m, the law's neighbours, where they are now
    nbr_y: FloatBuf
    nbr_held: FloatBuf  # 1.0 where the pair was active last period
    nbr_grow: FloatBuf  # m, each one's governor disc beyond a (A13)
    nbr_row: IntBuf     # its row of the reports
    obs_x: FloatBuf     # m, the law's obstacles: detections, then silent neighbours
    obs_y: FloatBuf
    obs_r: FloatBuf
    cand_row: IntBuf    # the governor's neighbours: their rows,
    cand_law: IntBuf    # their index among the law's neighbours (-1: none),
    cand_floor: FloatBuf  # m, a bound of the free distance toward their discs,
    order: IntBuf       # and their order by it
    splits: Splits      # this robot's motion over a neighbour's data age
    key: IntBuf         # the records those splits were taken from (agent.trail.own_motion)
    held: IntBuf        # out: the ids of the robots whose pair is active


class PeriodOut(NamedTuple):
    """One robot's period: its command, its memory and what it observed."""

    right: float        # rev/s, the wheels' set-points
    left: float
    v: float            # m/s, the command they make
    u: float            # rad/s
    mode: int           # the law's mode (common.vocabulary.Mode)
    governed: float     # m/s the safety governor allowed where it lowered the command
    #                     (inf: it did not)
    memory: Memory
    reference: Reference
    n_nbr: int          # the law's neighbours (Workspace.nbr_row)
    n_held: int         # the pairs active (Workspace.held)


def robot_period(inputs: Inputs, memory: Memory, p: PeriodParams, ws: Workspace) -> PeriodOut:
    """One period of one robot (module docstring)."""
    own, lp = inputs.own, p.law
    law_mem = memory.law
    if own.jump_x != 0.0 or own.jump_y != 0.0:
        law_mem = moved_estimate(law_mem, own.jump_x, own.jump_y)
    n_nbr, n_obs, n_cand = sense(inputs, p, ws)
    ex = memory.exchange
    if lp.exchange > 0.0:
        was = ex.slot
        ex = exchange_step(own.robot, own.x, own.y, inputs.t, ex,
                           heard(inputs, ex.partner, ws, n_nbr), inputs.places, lp.exchange,
                           p.model.staleness)
        if ex.slot != was:      # the error's finite difference sees no jump
            ox, oy = place(inputs.places, was, inputs.t)
            nx, ny = place(inputs.places, ex.slot, inputs.t)
            law_mem = moved_estimate(law_mem, ox - nx, oy - ny)
    rx, ry, rvx, rvy = reference(inputs.places, ex.slot, inputs.t)
    ref = Reference(rx, ry, rvx, rvy)
    limits = (governor_limits(inputs, law_mem, n_cand, p, ws) if lp.governor
              else NO_LIMITS)
    around = Surroundings(ws.nbr_x, ws.nbr_y, ws.nbr_held, ws.nbr_grow, n_nbr, ws.obs_x,
                          ws.obs_y, ws.obs_r, n_obs)
    out = law_step(own.x, own.y, own.theta, ref, around, limits, law_mem, lp, inputs.dt)
    # the pairs active this period, as the law applied them (A3)
    n_held = 0
    for q in range(n_nbr):
        dx, dy = ws.nbr_x[q] - own.x, ws.nbr_y[q] - own.y
        if pair_active(dx * dx + dy * dy, ws.nbr_held[q] > 0.5, lp.b, lp.hysteresis):
            ws.held[n_held] = inputs.reports.robot[ws.nbr_row[q]]
            n_held += 1
    right, left = out.right, out.left
    if math.isinf(lp.speed_limit) and math.isinf(lp.ramp):     # an ideal robot's wheels
        right, left = wheel_command(out.v, out.u, lp.wheel_radius, lp.wheel_base,
                                    lp.speed_limit)
    return PeriodOut(right, left, out.v, out.u, out.mode, out.governed,
                     Memory(out.memory, ex), ref, n_nbr, n_held)


def sense(inputs: Inputs, p: PeriodParams, ws: Workspace) -> tuple[int, int, int]:
    """(law's neighbours, law's obstacles, governor's neighbours) counted into ``ws``:
    the detections; each neighbour heard from, moved along its arc to now (A8), in the
    sensing range a neighbour of the law, silent and in range a static obstacle of
    agent.discs.silent_radius (A7); and every one that may be within the sensing range
    by now, its report within the range plus the top speed times its data's age (the
    staleness limit at most), a hazard of the governor. Its own row and rows never heard
    from are passed over."""
    # the columns as locals: the same numbers, fewer lookups (an agent runs this
    # interpreted every period)
    own, rep = inputs.own, inputs.reports
    robots, stamps, xs, ys, vs = rep.robot, rep.stamp, rep.x, rep.y, rep.v
    me, x, y, now = own.robot, own.x, own.y, inputs.now
    staleness, half_base, top_speed = p.model.staleness, p.model.half_base, p.model.top_speed
    obs_x, obs_y, obs_r = ws.obs_x, ws.obs_y, ws.obs_r
    nbr_x, nbr_y, nbr_row, nbr_grow, nbr_held = (ws.nbr_x, ws.nbr_y, ws.nbr_row, ws.nbr_grow,
                                                 ws.nbr_held)
    near, held_ids, n_held = inputs.near, inputs.held, inputs.n_held
    r = p.sensing_range
    r2 = r * r
    det = inputs.detections
    for k in range(det.n):
        obs_x[k], obs_y[k], obs_r[k] = det.x[k], det.y[k], det.r[k]
    n_nbr, n_obs, n_cand = 0, det.n, 0
    for q in range(inputs.n_near):
        row = near[q]
        stamp = stamps[row]
        robot = robots[row]
        if robot == me or stamp == -math.inf:
            continue
        age = now - stamp
        rx, ry = xs[row], ys[row]
        dx, dy = rx - x, ry - y
        d2 = dx * dx + dy * dy
        law_q = -1
        if age > staleness:            # silent: a static obstacle where it was last
            if d2 <= r2:
                obs_x[n_obs], obs_y[n_obs] = rx, ry
                obs_r[n_obs] = silent_radius(vs[row], half_base * rep.u[row], p.model)
                n_obs += 1
        elif math.sqrt(d2) - abs(vs[row]) * (0.0 if 0.0 > age else age) <= r + RANGE_PAD:
            # in range wherever its arc took it (an arc is at least as long as its chord)
            px, py, _ = extrapolate(rx, ry, rep.theta[row], vs[row], rep.u[row], age,
                                    staleness)
            ex, ey = px - x, py - y
            if ex * ex + ey * ey <= r2:
                law_q = n_nbr
                nbr_x[n_nbr], nbr_y[n_nbr], nbr_row[n_nbr] = px, py, row
                nbr_grow[n_nbr] = 0.0
                held = 0.0
                for h in range(n_held):
                    if held_ids[h] == robot:
                        held = 1.0
                nbr_held[n_nbr] = held
                n_nbr += 1
        since = 0.0 if 0.0 > age else (staleness if age > staleness else age)
        reach = r + top_speed * since
        if d2 <= reach * reach:
            ws.cand_row[n_cand], ws.cand_law[n_cand] = row, law_q
            n_cand += 1
    return n_nbr, n_obs, n_cand


def heard(inputs: Inputs, partner: int, ws: Workspace, n_nbr: int) -> Heard:
    """What the place exchange hears (agent.exchange.Heard): the law's neighbours, and its
    partner's newest report wherever it is."""
    rep = inputs.reports
    row = -1
    if partner != NOBODY:
        if 0 <= partner < len(rep.robot) and rep.robot[partner] == partner:
            row = partner                       # rows in the order of the ids
        else:
            for r in range(len(rep.robot)):
                if rep.robot[r] == partner:
                    row = r
        if row >= 0 and rep.stamp[row] == -math.inf:
            row = -1
    age = inputs.now - rep.stamp[row] if row >= 0 else math.inf
    return Heard(rep, ws.nbr_row, ws.nbr_x, ws.nbr_y, n_nbr, row, age)


def governor_limits(inputs: Inputs, law_mem: LawMemory, n_cand: int, p: PeriodParams,
                    ws: Workspace) -> Limits:
    """The safety governor's limits (A10) among its hazards: the detected obstacles grown
    by a, and every neighbour of :func:`sense`'s where it can be by now given its data's
    age (agent.discs.neighbour_radii); all grown by the robot's own position uncertainty.

    The neighbours nearest first, by a bound of the free distance toward their discs
    (agent.discs.neighbour_floor); a disc is computed only where that is below the distance
    within which a disc can bind (agent.governor.binding) or where the law can pass the
    neighbour (agent.law.may_pass): the limits are those of every disc. Each law
    neighbour's growth (``ws.nbr_grow``) is its claim's half radius less a, which the law
    passes round (A13), or, where its disc was not computed, a bound of it."""
    own, rep, path, m, lp = inputs.own, inputs.reports, inputs.path, p.model, p.law
    stamps, xs, ys, vs = rep.stamp, rep.x, rep.y, rep.v
    cand_row, cand_law, cand_floor, order = ws.cand_row, ws.cand_law, ws.cand_floor, ws.order
    nbr_grow = ws.nbr_grow
    x, y, now, a, staleness = own.x, own.y, inputs.now, m.a, m.staleness
    grow = own.uncertainty
    v_now, u_now = last_velocity(law_mem, lp)
    frame = limit_frame(own.theta, v_now, u_now, braking_of(lp, inputs.dt))
    gaps = NO_GAPS
    det = inputs.detections
    for k in range(det.n):
        gaps = fold_hazard(gaps, frame, det.x[k] - x, det.y[k] - y, det.r[k] + a + grow,
                           -math.inf, 0.0)
    # the floors, and the neighbours in their order (insertion: a few, no allocation)
    walked, lo, hi = 0.0, math.inf, -math.inf
    for c in range(n_cand):
        row = cand_row[c]
        stamp = stamps[row]
        if not lo <= stamp + TIME_TOL < hi:     # this robot's path since the stamp (the
            walked, lo, hi = path_since(path, stamp)   # same for stamps between two records)
        floor, top = neighbour_floor(x - xs[row], y - ys[row], vs[row], now - stamp, walked,
                                     m)
        floor -= 0.5 * grow
        cand_floor[c] = floor
        q = cand_law[c]
        if q >= 0:
            nbr_grow[q] = top + grow - a
        i = c
        while i > 0 and cand_floor[order[i - 1]] > floor:
            order[i] = order[i - 1]
            i -= 1
        order[i] = c
    bind = binding(gaps, frame)
    ws.key[0] = -1
    for i in range(n_cand):
        c = order[i]
        q = cand_law[c]
        if cand_floor[c] >= bind:           # it cannot bind: is it one the law may pass?
            if q < 0:
                continue
            dx, dy = ws.nbr_x[q] - x, ws.nbr_y[q] - y
            if not may_pass(math.sqrt(dx * dx + dy * dy), nbr_grow[q], lp):
                continue
        row = cand_row[c]
        stamp = stamps[row]
        age = now - stamp
        # this robot's motion since the stamp, split as the discs take it (neighbours
        # whose splits fall between the same records share it)
        own_motion(path, stamp, age, ws.key, ws.splits)
        rx, ry = xs[row], ys[row]
        full, half, east, north, claim = neighbour_radii(x - rx, y - ry, rep.theta[row],
                                                         vs[row], rep.u[row], age, ws.splits,
                                                         m)
        gaps = fold_hazard(gaps, frame, rx + east - x, ry + north - y, full + grow,
                           half + grow, 1.0 if age <= staleness else 0.0)
        bind = binding(gaps, frame)
        if q >= 0:
            nbr_grow[q] = claim + grow - a
    return frame_limits(gaps, frame)
