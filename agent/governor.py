"""The safety governor's limits: the fastest a robot may go and still stop before any hazard.

A closed-form braking-distance barrier (docs/controller.md A10), in the spirit of
Responsibility-Sensitive Safety and PX4's collision prevention: every hazard is a disc the
robot's centre must stay out of (an obstacle grown by a; a neighbour's disc, agent.discs),
and the robot may move toward it only as fast as lets it stop in the free distance it owns,
after a reaction time and at its braking deceleration.

For a hazard at distance d the robot owns f = min(d - R, (d - R_half) / 2). Moving along
its heading (or against it, when reversing) at speed v, with c the cosine of the angle
between the hazard's bearing and the headings the robot can have while it stops, it must
satisfy c s(v) <= f, s(v) its path when it holds its command for its reaction time and then
brakes each wheel (agent.braking.stopping). Hazards away from the direction of travel
(c <= 0) do not limit it, so a robot can always back away.

In pieces: :func:`limit_frame` (what every hazard is measured against, a :class:`Frame`),
:func:`fold_hazard` for each hazard in any order (the :class:`Gaps`), :func:`frame_limits`;
:func:`binding` tells which hazards can still change the gaps. Plain floats: agents run it
interpreted, the batch simulator compiled.
"""
from __future__ import annotations

import math
from typing import NamedTuple

from agent.braking import braking_speed, stopping
from agent.params import TWO_PI, LawParams

EPS = 1e-9
MOVING_PAD = 0.3     # rad, a moving neighbour's bearing counts as this much nearer the travel


class Braking(NamedTuple):
    """How a robot stops, as the governor counts on it."""

    accel: float        # m/s^2, each wheel's braking ramp (inf: at once)
    period: float       # s, how long a command holds (or the drivers' watchdog, should the
    #                     robot's agent die)
    latency: float      # s, from a command to the wheels (at most a period)
    turn_rate: float    # rad/s, the most its heading may turn further in the reaction time
    wheel_base: float   # m
    top_speed: float    # m/s, its wheels' top speed (inf: none)
    margin: float       # m, room kept for the drift of a turn on slipping wheels
    turn_up: float      # m/s^2, the most its law speeds up the wheels' half difference


class Frame(NamedTuple):
    """What every hazard is measured against (:func:`limit_frame`)."""

    hx: float           # the unit vector along the middle of the headings swept while
    hy: float           # stopping
    cos_static: float   # cosine, sine and whether-all (1.0 or 0.0) of the sweep's
    sin_static: float   # half-width, for a static hazard
    all_static: float
    cos_moving: float   # the same for a moving one (MOVING_PAD wider)
    sin_moving: float
    all_moving: float
    skip: float         # m, the free distance beyond which a hazard cannot limit the robot
    margin: float       # m
    v_now: float        # m/s, the last command
    ramp: float         # m/s the command may differ by in flight
    latency: float      # s
    accel: float        # m/s^2
    period: float       # s
    turn: float         # m/s, the wheels' half difference


class Gaps(NamedTuple):
    """The hazards folded so far (:func:`fold_hazard`)."""

    fwd: float      # m, the least free distance ahead less the margin, over the cosine
    bwd: float      # m, behind
    room: float     # m, the least free distance (margin included) over the cosine, of the
    #                 hazards the robot is outside of (inf: none near)


class Limits(NamedTuple):
    """The governor's verdict (:func:`frame_limits`)."""

    fwd: float      # m/s, the fastest forward (inf: no limit)
    bwd: float      # m/s, backward
    room: float     # m, as :class:`Gaps`


NO_GAPS = Gaps(math.inf, math.inf, math.inf)       # before any hazard
NO_LIMITS = Limits(math.inf, math.inf, math.inf)   # the governor off


def braking_of(p: LawParams, dt: float) -> Braking:
    """How the robot of law parameters ``p`` stops, ``dt`` [s] after its last command: the
    command held for a period, or the drivers' watchdog should the agent die, then the drive
    latency; its wheels' top speed; room kept for the drift of a turn on the spot on
    slipping wheels."""
    return Braking(p.accel, max(dt, p.watchdog), p.latency, p.u_max, p.wheel_base,
                   TWO_PI * p.wheel_radius * p.speed_limit, slip_margin(p.slip, p.wheel_base),
                   p.turn_up)


def limit_frame(theta: float, v_now: float, u_now: float, b: Braking) -> Frame:
    """The frame of a robot heading ``theta`` [rad] and moving at (``v_now`` [m/s],
    ``u_now`` [rad/s]), its last command, that stops as ``b`` says.

    The command reaches the wheels a latency late: until then the robot goes on at v_now,
    give or take one period's ramp; a robot already faster than it may go brakes at the
    full ramp. While it stops, its heading sweeps on at u_now (braking takes the whole ramp
    of both wheels, so the turn rate holds) and may turn further during the reaction time:
    at up to the turn rate more, or, with a finite ramp, as far as its law lets its wheels
    bend the path in that time (u changing at 2 turn_up / wheel_base: turn_up tau^2 /
    wheel_base), whichever is less. A hazard counts with the cosine of its bearing's angle to
    the nearest heading of that sweep (1 inside it; none beyond 90 degrees); a moving one as
    if its bearing were MOVING_PAD nearer, as its own motion turns the line of sight.
    Hazards farther than the robot needs to stop from its top speed are skipped."""
    accel, period, latency, wheel_base = b.accel, b.period, b.latency, b.wheel_base
    reaction = period + latency
    ramp = 0.0 if math.isinf(accel) else accel * period   # m/s the speed may differ by in flight
    turn = 0.5 * abs(u_now) * wheel_base                 # m/s, the wheels' half difference
    stop_time = reaction + (0.0 if math.isinf(accel) else (abs(v_now) + turn) / accel)
    sweep = u_now * stop_time
    bend = b.turn_rate * reaction
    if not math.isinf(accel) and wheel_base > 0.0:
        bend = min(bend, min(b.turn_up, accel) * reaction * reaction / wheel_base)
    spread = 0.5 * abs(sweep) + bend
    middle = theta + 0.5 * sweep
    reach = (b.top_speed + ramp) * latency + stopping(b.top_speed, accel, period, turn)
    # the pads as cosine and sine; a pad of half a turn or more takes in every bearing
    moving = spread + MOVING_PAD
    return Frame(math.cos(middle), math.sin(middle),
                 math.cos(spread), math.sin(spread), 1.0 if spread >= math.pi else 0.0,
                 math.cos(moving), math.sin(moving), 1.0 if moving >= math.pi else 0.0,
                 reach + b.margin, b.margin, v_now, ramp, latency, accel, period, turn)


def fold_hazard(gaps: Gaps, frame: Frame, dx: float, dy: float, radius: float, half: float,
                moving: float) -> Gaps:
    """``gaps`` with one more hazard, centred (``dx``, ``dy``) [m] from the robot, its
    exclusion radii ``radius`` and ``half`` [m] (this robot owns min(d - radius, (d -
    half) / 2) of a distance d to it; -inf: no such rule), ``moving`` 1.0 for a neighbour
    that moves and 0.0 for a static disc, measured in ``frame``.

    The speeds keep the frame's margin more to every hazard, room for the robot's drift
    along its heading while it turns with slipping wheels (:func:`turn_limit`); the room is
    the least free distance ahead or behind, margin included, over the cosine, of the
    hazards the robot is outside of. A disc the robot is already inside (a neighbour's that
    grew round it as its data aged or it died) leaves no room to keep; not turning would
    never take the robot out of it."""
    d = math.sqrt(dx * dx + dy * dy)
    free, shared = d - radius, 0.5 * (d - half)
    free = shared if shared < free else free
    if free >= frame.skip:        # cannot hold the robot below its top speed
        return gaps
    gap_fwd, gap_bwd, room = gaps
    margin = frame.margin
    c_fwd = c_bwd = 1.0          # on the robot
    if d >= EPS:
        # cosine and sine of the bearing's angle from the heading
        along = (dx * frame.hx + dy * frame.hy) / d
        across = abs(dx * frame.hy - dy * frame.hx) / d
        if moving != 0.0:
            cos_pad, sin_pad, every = frame.cos_moving, frame.sin_moving, frame.all_moving
        else:
            cos_pad, sin_pad, every = frame.cos_static, frame.sin_static, frame.all_static
        c_fwd = _cosine(along, across, cos_pad, sin_pad, every)
        c_bwd = _cosine(-along, across, cos_pad, sin_pad, every)
    if c_fwd > EPS:
        gap = (free - margin) / c_fwd
        gap_fwd = gap if gap < gap_fwd else gap_fwd
    if c_bwd > EPS:
        gap = (free - margin) / c_bwd
        gap_bwd = gap if gap < gap_bwd else gap_bwd
    c = c_bwd if c_bwd > c_fwd else c_fwd
    if free > 0.0 and c > EPS:
        gap = free / c
        room = gap if gap < room else room
    return Gaps(gap_fwd, gap_bwd, room)


def binding(gaps: Gaps, frame: Frame) -> float:
    """The free distance [m] below which a hazard can change ``gaps`` (:func:`fold_hazard`):
    beyond the margin its gaps are at least its free distance less the margin, a cosine
    being at most 1, and its room at least its free distance; from the distance
    fold_hazard skips, none. A hazard this robot owns no less free distance toward (as
    agent.discs.neighbour_floor bounds it) is left out without changing the limits, in any
    order of the hazards."""
    margin = frame.margin
    fwd, bwd, room = margin + gaps.fwd, margin + gaps.bwd, gaps.room
    most = fwd if fwd > margin else margin
    most = bwd if bwd > most else most
    most = room if room > most else most
    return most if most < frame.skip else frame.skip


def frame_limits(gaps: Gaps, frame: Frame) -> Limits:
    """The speed limits and room of ``gaps``, measured in ``frame``: braking_speed grows
    with the free distance, so the nearest hazard each way sets the limit."""
    v_now, ramp, latency = frame.v_now, frame.ramp, frame.latency
    accel, period, turn = frame.accel, frame.period, frame.turn
    fwd = _limit(gaps.fwd, max(v_now, 0.0), ramp, latency, accel, period, turn)
    bwd = _limit(gaps.bwd, max(-v_now, 0.0), ramp, latency, accel, period, turn)
    return Limits(fwd, bwd, gaps.room)


def _cosine(along: float, across: float, cos_pad: float, sin_pad: float,
            everywhere: float) -> float:
    """The weight of a hazard whose bearing makes an angle of cosine ``along`` and sine
    ``across`` (>= 0) with the heading, the robot sweeping the headings within an angle
    ``pad`` of it (its cosine, sine, and 1.0 where it is half a turn or more): 1 within the
    sweep, the cosine of the angle beyond it otherwise (<= 0 beyond 90 degrees)."""
    if everywhere != 0.0 or along >= cos_pad:
        return 1.0
    return along * cos_pad + across * sin_pad


def _limit(gap: float, going: float, ramp: float, latency: float, accel: float,
           period: float, turn: float) -> float:
    """The speed limit [m/s] one way (inf: none) with ``gap`` [m] free that way (over the
    cosine), going at ``going`` [m/s] that way now (:func:`frame_limits`)."""
    if math.isinf(gap):
        return math.inf
    limit = braking_speed(gap - (going + ramp) * latency, accel, period, turn)
    return 0.0 if going > limit else limit   # behind the braking curve: brake at the full ramp


def slip_margin(slip: float, wheel_base: float) -> float:
    """The drift [m] along its heading of a robot turning half a turn on the spot whose
    wheels slip by up to ``slip`` (a fraction of each wheel's turn that does not move the
    ground): its wheels roll pi wheel_base / 2 each way, and unequal slip leaves the centre
    moving by up to slip times that."""
    return slip * 0.5 * math.pi * wheel_base


def turn_limit(room: float, slip: float, accel: float, reaction: float,
               wheel_base: float) -> float:
    """The fastest turn [rad/s] (inf: none) whose drift fits in ``room`` [m]
    (:func:`fold_hazard`): turning with its wheels w [m/s] apart, a robot whose wheels slip
    by up to ``slip`` moves along its heading at up to slip w, and keeps drifting while the
    turn is held for ``reaction`` [s] and ramps down at ``accel`` [m/s^2]. The limit falls
    with the room: a robot that drifted toward a hazard turns ever slower, and backs or
    drives away instead (its speed limits keep the margin of :func:`slip_margin`)."""
    if slip <= 0.0 or math.isinf(room):
        return math.inf
    return 2.0 * braking_speed(room / slip, accel, reaction) / wheel_base
