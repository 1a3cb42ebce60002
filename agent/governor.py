"""The safety governor: the fastest a robot may go and still stop before any hazard.

A closed-form braking-distance barrier (docs/controller.md, "Safety governor"), in the spirit
of Responsibility-Sensitive Safety and PX4's collision prevention: every hazard is a disc the
robot's centre must stay out of, and the robot may move toward it only as fast as lets it
stop in the free distance it owns, after a reaction time and at its braking deceleration.

* **Hazards.** An obstacle: its detected disc grown by a, taken in full. A neighbour: its
  *reported* position, grown by a, by what it can have travelled since its stamp toward this
  robot (its speed and acceleration over the data age, at most the swarm's top speed, or
  less where its reported heading and turn rate say it was driving elsewhere:
  :func:`approach`; its acceleration is its law's speed-up where that is below its
  wheels' ramp, docs/controller.md A17) and by this robot's own motion over that age,
  the two paired at each instant the neighbour may last have acted
  (:func:`neighbour_radii`). It runs the same governor, so the free distance between the
  two is shared half and half: its share is what it claimed when it last acted on data of
  this robot, and whatever happened since (it may have died then) is on this robot, whose
  motion since then the disc counts as far as it brought it nearer (:func:`_own_share`).
  A silent neighbour (older than the staleness limit): a static disc at its last known
  position grown by a and by what it could travel from its last report until it must
  have stopped (its drivers' watchdog, then each wheel braking to rest on its own:
  :func:`stopping`), taken in full.
* **Limit.** For a hazard at distance d the robot owns f = min(d - R, (d - R_half) / 2).
  Moving along its heading (or against it, when reversing) at speed v, with c the cosine
  of the angle between the hazard's bearing and the headings the robot can have while it
  stops (:func:`speed_limits`), it must satisfy c s(v) <= f, s(v) its path when it holds
  its command for its reaction time tau and then brakes each wheel (:func:`stopping`), tau its
  reaction time (the drivers' watchdog, should its own agent die, and the drive latency).
  Hazards away from the direction of travel (c <= 0) do not limit it, so a robot can
  always back away.

Plain floats: agents run it interpreted, the batch simulator compiled, as the law. Where
it runs per neighbour, the least and the largest of two floats are conditional expressions:
``b if b < a else a`` is what ``min(a, b)`` returns (ties and NaN alike), and the
interpreter runs it several times faster than the builtin (docs/performance.md).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import MutableSequence, Sequence
    from typing import TypeAlias

    import numpy as np
    import numpy.typing as npt

    from agent.avoidance import FloatRows, FloatSeq

    TrailRows: TypeAlias = Sequence[MutableSequence[float]] | npt.NDArray[np.float64]
    Frame: TypeAlias = tuple[float, ...]

EPS = 1e-9
SPLITS = 4           # pieces of a neighbour's data age paired with this robot's path
TRAIL_ROWS = 10      # rows of a trail (:func:`trail_motion`)
MOVING_PAD = 0.3     # rad, a moving neighbour's bearing counts as this much nearer the travel
_STILL = ((0.0,),) * TRAIL_ROWS     # the trail of a robot that has not moved
_BLIND = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)       # no line of sight (needed only with a trail)
_NO_MOTION = (0.0,) * 8     # a split over which the robot did not move (_own_share)
NO_GAPS = (math.inf, math.inf, math.inf)       # fold_hazard's gaps before any hazard
FLOOR_PAD = 1e-6     # m, neighbour_floor's bounds are this much looser than rounding needs


def neighbour_hazard(speed: float, turn: float, age: float, trail: float, a: float,
                     accel: float, top_speed: float, staleness: float, stop_time: float,
                     wheel_top: float = math.inf, nearer: float = math.inf,
                     speed_up: float = math.inf, lag: float = 0.0,
                     turn_up: float = math.inf) -> tuple[float, float]:
    """(full, half): the exclusion radii [m] around a neighbour's reported position, last
    reported moving at ``speed`` [m/s] and turning with its wheels ``turn`` [m/s] apart
    (half the difference of their ground speeds: |u| times half the wheel base) ``age`` [s]
    ago, ``trail`` [m] this robot's own path since then. This robot owns
    min(d - full, (d - half) / 2) of a distance d to it (-inf: that rule does not apply).
    ``accel`` [m/s^2] (its wheels' ramp), ``speed_up`` [m/s^2] (the most its law speeds
    it up: its speed and its wheels' half difference) and ``top_speed`` [m/s] bound how its
    speed can have changed since, ``lag`` [s] how late its wheels follow the commands it
    reports (a period and the drive latency), ``turn_up`` [m/s^2] the most its law speeds
    up its wheels' half difference (at most speed_up), ``wheel_top`` [m/s] each wheel's
    ground speed
    (so the wheels are at most wheel_top - speed apart); ``stop_time`` [s] is how long a
    dead agent's drivers keep going before they brake (watchdog and drive latency).
    ``nearer`` [m]: how much nearer to this robot than its reported position it can be by
    now, when known from where it was heading (:func:`approach`); heard from, its disc
    grows by no more than that.

    Heard from (age <= staleness): half of the gap beyond a, its travel since the stamp and
    this robot's trail. When it last acted, at its stamp or as late as it lived after it,
    its governor kept its stop (its drivers' watchdog included, should it die) within half
    the true gap beyond a then; this robot was at most its trail from where it is now, so
    the two stops stay a apart (docs/controller.md, A10). Silent (older): a static disc
    grown by what it could travel from its last report until it must have stopped, having
    died as late as the staleness limit after that report (the disc never shrinks as the
    data ages), taken in full."""
    speed, turn = abs(speed), abs(turn)
    silent = age > staleness
    age = min(max(age, 0.0), staleness)     # silent: it may have died as late as that
    grow = _travel(speed, age, accel, min(speed_up, accel), lag, top_speed)
    if not silent:
        return -math.inf, a + min(grow, nearer) + trail
    now, turn_now = top_speed, turn
    if not math.isinf(accel):
        up = min(speed_up, accel)
        now = min(now, speed + accel * lag + up * age)
        # each wheel's speed changes at most accel and stays within wheel_top; the longest
        # stop is at the fastest speed, the wheels as far apart as that leaves them
        turn_now = min(turn + accel * lag + min(up, turn_up) * age,
                       max(wheel_top - now, 0.0))
    return a + grow + stopping(now, accel, stop_time, turn_now), -math.inf


def _travel(speed: float, age: float, accel: float, up: float, lag: float,
            top_speed: float) -> float:
    """How far [m] a neighbour last reported at ``speed`` [m/s] (>= 0) can have travelled
    ``age`` [s] (>= 0) later, all round (arguments as :func:`neighbour_hazard`, ``up`` its
    speed-up at most ``accel``): :func:`_grow`, and :func:`_all_round` over one split with
    no motion of this robot's."""
    if math.isinf(accel):
        return top_speed * age
    accel_lag = accel * lag
    return _grow(0.0 if 0.0 > age else age, abs(speed), top_speed, 0.5 * accel, 0.5 * up,
                 accel_lag, accel_lag * lag)


def _all_round(trail: FloatRows, age: float, speed: float, a: float, accel: float,
               top_speed: float, up: float, lag: float,
               sight: tuple[float, float, float, float, float, float] = _BLIND) -> float:
    """around [m] of a neighbour heard from on wheels of finite ``accel`` (arguments as
    :func:`neighbour_radii`, ``up`` its speed-up at most ``accel``): over the splits of
    the ``age`` (>= 0) paired with this robot's ``trail``, the largest of a + how far it
    can have travelled all round by the split's end + this robot's share of its own motion
    since the split's start (:func:`_own_share`, seen along ``sight``: this robot's
    distance [m] to the report's position and the unit vector toward it, then its
    distance to the report's segment and the unit vector toward the segment's far end,
    which :func:`_capsule` uses)."""
    around = -math.inf
    splits = len(trail[0])
    dist, sx, sy = sight[0], sight[1], sight[2]
    speed = abs(speed)
    half_accel, half_up, accel_lag = 0.5 * accel, 0.5 * up, accel * lag
    accel_lag2 = accel_lag * lag
    # the last split first: its sum is often the largest, and a share is at most the
    # path since its split's start, so a split whose sum cannot beat the largest so far
    # needs no share
    for k in range(splits - 1, -1, -1):
        if k + 1 < splits and trail[9][k] != 0.0:
            continue    # the next split dominates it (trail_motion)
        t = age * (k + 1) / splits
        t = 0.0 if 0.0 > t else t
        grow = _grow(t, speed, top_speed, half_accel, half_up, accel_lag, accel_lag2)
        around = _with_share(trail, k, a, grow, around, sx, sy, sx, sy, dist)
    return around


def _capsule(trail: FloatRows, age: float, speed: float, turn_rate: float, a: float,
             accel: float, half_base: float, up: float, lag: float, turn_up: float,
             sight: tuple[float, float, float, float, float, float] = _BLIND
             ) -> tuple[float, float]:
    """(reach, rho) [m] of a neighbour heard from on wheels of finite ``accel`` (arguments
    as :func:`_all_round`, ``turn_up`` its wheels' half difference's speed-up at most
    ``up``): over the splits of the ``age`` paired as there, the largest of a + rho
    (:func:`swerve`; inf when ``half_base`` <= 0) by the split's end + this robot's share
    of its own motion since the split's start toward the report's segment; and rho at the
    age itself."""
    reach = -math.inf
    rho_age = math.inf
    splits = len(trail[0])
    sx, sy, off, ex, ey = sight[1], sight[2], sight[3], sight[4], sight[5]
    speed, half_turn = abs(speed), 0.5 * abs(turn_rate)
    half_accel, half_up, accel_lag = 0.5 * accel, 0.5 * up, accel * lag
    accel_lag2 = accel_lag * lag
    for k in range(splits - 1, -1, -1):       # as _all_round
        if k + 1 < splits and trail[9][k] != 0.0:
            continue
        t = age * (k + 1) / splits
        t = 0.0 if 0.0 > t else t
        rho = math.inf
        if half_base > 0.0:
            t2 = t * t
            # the heading's departure from the reported one, integrated over t [rad s]
            swing = (half_turn * t2 + accel_lag2 * t / half_base
                     + turn_up * t2 * t / (6.0 * half_base))
            rho = half_accel * t2 + accel_lag * t + speed * swing
            turned = half_up * t2 + accel_lag2 + (speed + accel_lag + up * t) * swing
            rho = turned if turned < rho else rho
        if k == splits - 1:
            rho_age = rho
        reach = _with_share(trail, k, a, rho, reach, sx, sy, ex, ey, off)
    return reach, rho_age


def _with_share(trail: FloatRows, k: int, a: float, radius: float, best: float, sx: float,
                sy: float, ex: float, ey: float, dist: float) -> float:
    """The larger of ``best`` [m] and a + ``radius`` [m] + this robot's share of its own
    motion over split ``k`` of ``trail`` toward a set of that radius seen at ``dist`` [m]
    between the unit directions (``sx``, ``sy``) and (``ex``, ``ey``) (:func:`_own_share`);
    the share, at most the split's path, is left out where even that cannot beat ``best``
    (each bound summed as the term is, so that it rounds no lower)."""
    path = trail[0][k]
    if a + radius + path <= best:
        return best
    motion = ((path, trail[2][k], trail[3][k], trail[6][k], trail[4][k], trail[5][k],
               trail[7][k], trail[8][k]) if path > 0.0 else _NO_MOTION)
    bound = a + radius + _own_share(motion, sx, sy, ex, ey, dist, radius)
    return bound if bound > best else best


def _grow(t: float, speed: float, top_speed: float, half_accel: float, half_up: float,
          accel_lag: float, accel_lag2: float) -> float:
    """How far [m] a neighbour last reported at ``speed`` [m/s] (>= 0) can have travelled
    all round ``t`` [s] (>= 0) later (:func:`_all_round`; half its ramp and speed-up, its ramp
    times the lag and that times the lag again): its wheels within a ramp of the command it
    reported for the lag, then its speed grown by at most its speed-up since (or, more
    loosely, the ramp all along), and never faster than ``top_speed``."""
    ramped, sped = half_accel * t * t + accel_lag * t, half_up * t * t + accel_lag2
    grown = speed * t + (sped if sped < ramped else ramped)
    top = top_speed * t
    return grown if grown < top else top


def neighbour_floor(rel_x: float, rel_y: float, speed: float, age: float, path: float,
                    a: float, accel: float, top_speed: float, staleness: float,
                    speed_up: float, lag: float) -> tuple[float, float]:
    """(floor, top) [m] for a neighbour (arguments as :func:`neighbour_radii`, ``path``
    [m] this robot's path since the stamp: its trail's first value): at most
    the free distance this robot owns toward the disc :func:`neighbour_radii` gives it,
    whichever form that takes, and at least its claim's half radius; (-inf, inf) where it
    is silent or its wheels change speed at once (no bound: the disc is cheap there).

    Heard from, its claim is at most a + how far it can have travelled all round by now
    + this robot's path since the stamp (:func:`_all_round`, at the age), and the claim's
    disc leaves this robot half the distance to the reported position beyond that
    (:func:`neighbour_radii` takes the claim that much smaller as its centre comes nearer
    along the report's segment); behind it, the stop strip leaves more free distance,
    never less (:func:`_ahead`). A few operations: for leaving out the discs that cannot
    bind (:func:`binding`) before computing them."""
    if age > staleness or math.isinf(accel):
        return -math.inf, math.inf
    up = accel if accel < speed_up else speed_up
    top = a + _travel(speed, age, accel, up, lag, top_speed) + path + FLOOR_PAD
    dist = math.sqrt(rel_x * rel_x + rel_y * rel_y)
    return 0.5 * (dist - top) - FLOOR_PAD, top


def trail_motion(trail: TrailRows) -> None:
    """Fill rows 6 to 9 of ``trail`` (:func:`neighbour_radii`) from its first six, once
    for all the neighbours that share it: for each split k, the lengths [m] of this
    robot's displacement since the split's start and since its end; half the minor axis
    [m] of the ellipse of the positions it can have had within the split (foci where it
    was at the split's start and end, the path walked within it); and 1.0 where the next
    split dominates split k (it stood still within k, or moved over k as over k + 1:
    the same positions at and after their starts and ends, as where both fall between
    two recorded positions, data younger than the robot's period; the next split ends
    later), else 0.0 (the last split: 0.0)."""
    splits = len(trail[0])
    for k in range(splits):
        path, start_x, start_y = trail[0][k], trail[2][k], trail[3][k]
        end_x, end_y = trail[4][k], trail[5][k]
        within = path - trail[1][k]            # m, walked within the split
        chord_x, chord_y = start_x - end_x, start_y - end_y
        trail[6][k] = math.sqrt(start_x * start_x + start_y * start_y)
        trail[7][k] = math.sqrt(end_x * end_x + end_y * end_y)
        trail[8][k] = 0.5 * math.sqrt(max(within * within - chord_x * chord_x
                                          - chord_y * chord_y, 0.0))
        if k + 1 == splits:
            trail[9][k] = 0.0
            continue
        same = 1.0                             # moved over k as over k + 1
        for row in range(6):
            if trail[row][k] != trail[row][k + 1]:
                same = 0.0
        trail[9][k] = 1.0 if path == trail[1][k] else same     # or stood still within k


def _own_share(motion: tuple[float, float, float, float, float, float, float, float],
               sx: float, sy: float, ex: float, ey: float, dist: float, radius: float
               ) -> float:
    """How much [m] of the gap to a neighbour this robot's own motion takes from its half,
    the neighbour having last acted within a split of its data's age over which this
    robot moved by ``motion`` (path [m] since the split's start; displacement east and
    north [m] since its start and its length; the same since its end; the ellipse's half
    minor axis [m]: the rows of :func:`trail_motion`), at a point within ``radius`` [m] of
    a set this robot sees at ``dist`` [m] (its distance to the set's nearest point) and
    between the unit directions (``sx``, ``sy``) and (``ex``, ``ey``) (the shorter arc).

    The neighbour then at q, this robot at p0, kept its stop within half of |q - p0|
    beyond a; this robot, now at p with D = p - p0, must keep its stop within
    |p - q| - |q - p0| / 2 - a / 2 (docs/controller.md A10). With r = |q - p| and x the
    unit vector toward q, |q - p0| <= r + x.D + |D|^2 / (2 r): the share is at most
    x.D + |D|^2 / (2 r), little where this robot moved across the line of sight, and
    never more than |D|, at most its path since the split's start. p0 lies on a path of
    length l between where it was at the split's start and end, so within the ellipse
    of those foci and l: x.D is at most the larger of x.D at the two ends plus the
    ellipse's half minor axis, and x is within the arc widened by asin(radius / dist)."""
    path, start_x, start_y, start, end_x, end_y, end, bulge = motion
    if path <= 0.0:
        return 0.0
    clear = dist - radius                  # m, the least r
    if clear <= EPS:
        return path
    sin_b = radius / dist                  # the set's points lie within asin(sin_b)
    sin_b = 1.0 if 1.0 < sin_b else sin_b
    cos_b = math.sqrt(1.0 - sin_b * sin_b)
    toward = _toward(start_x, start_y, start, sx, sy, ex, ey, cos_b, sin_b)
    toward_end = _toward(end_x, end_y, end, sx, sy, ex, ey, cos_b, sin_b)
    toward = toward_end if toward_end > toward else toward
    share = toward + bulge + 0.5 * path * path / clear
    share = share if share > 0.0 else 0.0
    return share if share < path else path


def _toward(dx: float, dy: float, size: float, sx: float, sy: float, ex: float,
            ey: float, cos_b: float, sin_b: float) -> float:
    """The largest component [m] of (``dx``, ``dy``) [m] (of length ``size``) along a
    direction within an angle b (its cosine ``cos_b`` and sine ``sin_b``) of the shorter
    arc from unit (``sx``, ``sy``) to unit (``ex``, ``ey``)."""
    if size <= 0.0:
        return 0.0
    arc = sx * ey - sy * ex
    if (arc != 0.0 and arc * (sx * dy - sy * dx) >= 0.0 and arc * (dx * ey - dy * ex) >= 0.0
            and dx * (sx + ex) + dy * (sy + ey) > 0.0):
        return size                        # it points into the arc
    # g, the angle to the arc's nearer end; beyond the widening b the component is
    # size cos(g - b)
    cos_g, cos_e = dx * sx + dy * sy, dx * ex + dy * ey
    cos_g = (cos_e if cos_e > cos_g else cos_g) / size
    cos_g = -1.0 if -1.0 > cos_g else (1.0 if 1.0 < cos_g else cos_g)
    if cos_g >= cos_b:
        return size                        # within the widening
    return size * (cos_g * cos_b + math.sqrt(1.0 - cos_g * cos_g) * sin_b)


def neighbour_radii(rel_x: float, rel_y: float, heading: float, speed: float,
                    turn_rate: float, age: float, trail: FloatRows, a: float,
                    accel: float,
                    half_base: float, top_speed: float, staleness: float, stop_time: float,
                    wheel_top: float, speed_up: float, lag: float, turn_up: float
                    ) -> tuple[float, float, float, float, float]:
    """(full, half, east, north, claim) for a neighbour reported at (x, y) = this robot's
    position less (``rel_x``, ``rel_y``) [m], along ``heading`` [rad] at ``speed`` [m/s] and
    ``turn_rate`` [rad/s], ``age`` [s] ago: the exclusion radii of :func:`neighbour_hazard`
    of a disc centred (east, north) [m] from its reported position, and the half radius
    [m] of its claim's disc, which the law passes round (A13): the same as ``half`` unless
    this robot is behind it (below). ``trail``: this
    robot's motion over each of the splits of the age into equal pieces, the stamp's
    first (agent.trail.Trail.splits): its path [m] since each split's start and since
    its end, and its displacement (east, north) [m] since the start and since the end,
    then the rows :func:`trail_motion` derives from those (the other arguments as there
    and :func:`approach`).

    Heard from, on wheels of finite ramp, the neighbour can be now within rho of the
    segment from its reported position to where its report extrapolates to now
    (:func:`approach`). That capsule is convex, so along a straight path this robot's
    distance to it falls at most as fast as toward its point nearest this robot: the disc
    is centred there, and the governor's cosine (:func:`speed_limits`) bounds the approach
    of a neighbour that drives on beside this robot, which a disc round its old, reported
    position does not (docs/controller.md A10). The neighbour last acted at some time
    since its stamp, where its rho grows with that time and this robot's motion since
    shrinks: the two are paired over each split of the age (rho to its end, the motion
    from its start) and the largest sum counts; the motion counts as far as it took this
    robot toward where the neighbour can have been (:func:`_own_share`). Where the
    all-round bound round the reported position leaves more room, the disc keeps that
    room, still centred on the capsule's nearest point; silent, the static disc round the
    reported position. Behind a neighbour driving away, where it can be and stop bounds
    its stop better than its claim does (:func:`_ahead`)."""
    if age > staleness or math.isinf(accel):
        nearer = approach(rel_x, rel_y, heading, speed, turn_rate, age, accel, half_base,
                          speed_up, lag, turn_up)
        full, half = neighbour_hazard(speed, half_base * abs(turn_rate), age,
                                      trail[0][0], a, accel, top_speed, staleness,
                                      stop_time, wheel_top, nearer, speed_up, lag, turn_up)
        return full, half, 0.0, 0.0, half
    hx, hy = math.cos(heading), math.sin(heading)
    east, north, off, seg_x, seg_y = _nearest_on_report(rel_x, rel_y, hx, hy, speed, age)
    dist = math.sqrt(rel_x * rel_x + rel_y * rel_y)
    # unit vectors from this robot toward the report's position and its segment's far end
    far_x, far_y = seg_x - rel_x, seg_y - rel_y
    far = math.sqrt(far_x * far_x + far_y * far_y)
    near = EPS if EPS > dist else dist
    far = EPS if EPS > far else far
    sight = (dist, -rel_x / near, -rel_y / near, off, far_x / far, far_y / far)
    up = accel if accel < speed_up else speed_up
    turn_up = up if up < turn_up else turn_up
    reach, rho = _capsule(trail, age, speed, turn_rate, a, accel, half_base, up, lag,
                          turn_up, sight)
    beyond = off - reach
    # the all-round bound leaves more room than the capsule only where even its least
    # value, its last split's travel without this robot's share, does; else it is not
    # computed (its splits' shares are half the disc's cost)
    splits = len(trail[0])
    least = a + _travel(speed, age * splits / splits, accel, up, lag, top_speed)
    if dist - least > beyond:
        within = dist - _all_round(trail, age, speed, a, accel, top_speed, up, lag, sight)
        beyond = within if within > beyond else beyond
    claim = off - beyond
    own, to, ahead_x, ahead_y = _ahead(rel_x, rel_y, dist, hx, hy, speed, turn_rate, age,
                                       a, accel, half_base, up, lag, turn_up, stop_time,
                                       rho, 0.5 * (off - claim))
    if to > 0.0:
        return -math.inf, to - 2.0 * own, ahead_x, ahead_y, claim
    return -math.inf, claim, east, north, claim


def _ahead(rel_x: float, rel_y: float, rel: float, hx: float, hy: float, speed: float,
           turn_rate: float, age: float, a: float, accel: float, half_base: float,
           up: float, lag: float, turn_up: float, stop_time: float, rho: float, free: float
           ) -> tuple[float, float, float, float]:
    """(free, dist, east, north): the free distance [m] this robot owns toward a neighbour
    it is behind, by where the neighbour can be and stop (:func:`stop_strip`), with the
    centre (east, north) [m] from its reported position it is measured toward, ``dist``
    [m] from this robot; or (``free``, 0, 0, 0) where that gives no more (arguments as
    :func:`neighbour_radii`, ``rel`` [m] the length of (``rel_x``, ``rel_y``), (``hx``,
    ``hy``) the unit vector along its reported heading, ``up`` and ``turn_up`` at most
    ``accel``, ``stop_time`` [s] as :func:`neighbour_hazard`, ``rho`` [m] as
    :func:`swerve`).

    The neighbour's stop lies in the strip whenever it last acted, so this robot keeps its
    own stop a from the strip instead of half the gap from the neighbour's claim
    (docs/controller.md A10, "A neighbour this robot is behind"); and within its own half
    of the gap, which the neighbour counts on when it acts again, measured from the part
    of the report's segment the neighbour can be on by now. The cheap bounds come first:
    an agent runs this for every neighbour every period."""
    v = abs(speed)
    none = (free, 0.0, 0.0, 0.0)
    if v <= 0.0 or half_base <= 0.0:
        return none
    if speed < 0.0:
        hx, hy = -hx, -hy
    ahead = rel_x * hx + rel_y * hy             # m, this robot along the report
    # not behind its braking distance; or its half can be no more than the claim's, half
    # the gap to the segment's far end beyond rho and a
    if (ahead >= v * v / (2.0 * accel)
            or rel + v * age - rho - a <= 2.0 * free):
        return none
    now = _progress(v, turn_rate, age, accel, half_base, up, lag, turn_up)
    along = 0.0 if 0.0 > now else now                 # on the report's segment, by now
    along = along if along > ahead else ahead
    along = v * age if v * age < along else along
    ox, oy = along * hx - rel_x, along * hy - rel_y
    dist = math.sqrt(ox * ox + oy * oy)
    half = 0.5 * (dist - rho - a)
    if now == -math.inf or dist <= EPS or half <= free:
        return none
    lo, across = _strip(now, v, turn_rate, age, accel, half_base, up, lag, turn_up,
                        stop_time)
    if ahead >= lo:
        return none
    bx, by = ox / dist, oy / dist
    # the least of the strip's points toward that centre, less a
    own = (lo * (hx * bx + hy * by) - rel_x * bx - rel_y * by
           - across * abs(hx * by - hy * bx) - a)
    own = own if own < half else half
    if own <= free:
        return none
    return own, dist, along * hx, along * hy


def _progress(speed: float, turn_rate: float, age: float, accel: float, half_base: float,
              up: float, lag: float, turn_up: float) -> float:
    """The least distance [m] along its reported heading from its reported position a
    neighbour can be at by now (arguments as :func:`stop_strip`; -inf: no bound): braking
    at the full ramp from its stamp, after its wheels' lag, along every heading its turn
    allows (the cosine of the largest), then reversing at its speed-up once stopped."""
    go = speed - accel * lag                    # m/s, its speed at its stamp, at least
    go = 0.0 if 0.0 > go else go
    t_s = go / accel                            # s, the soonest it can be at rest
    brake = t_s if t_s < age else age
    dev = (abs(turn_rate) * brake + accel * lag * lag / half_base
           + 0.5 * turn_up / half_base * brake * brake)
    if speed <= 0.0 or dev >= 0.5 * math.pi:
        return -math.inf
    over = age - t_s                            # s, it may have reversed for that long
    over = 0.0 if 0.0 > over else over
    return ((go * brake - 0.5 * accel * brake * brake) * math.cos(dev)
            - 0.5 * up * over * over - accel * lag * over)


def stop_strip(speed: float, turn_rate: float, age: float, accel: float, half_base: float,
               up: float, lag: float, turn_up: float, stop_time: float
               ) -> tuple[float, float, float]:
    """(now, lo, across) [m] for a neighbour reported ``age`` [s] ago driving at ``speed``
    [m/s] (> 0, along its reported heading) and turning at ``turn_rate`` [rad/s], its
    wheels (2 ``half_base`` [m] apart) braking at ``accel`` [m/s^2] (finite) and following
    its commands ``lag`` [s] late, its law speeding it up by at most ``up`` and its
    wheels' half difference by at most ``turn_up`` [m/s^2] (A17), a dead agent's drivers
    going on for ``stop_time`` [s] before they brake. Measured from its reported position
    along and across its reported heading: it is at least ``now`` along by now
    (:func:`_progress`); and from now until it is at rest, should it have last acted at any
    time since its stamp, at least ``lo`` along and at most ``across`` across (lo = -inf:
    no bound).

    Once stopped it can have reversed at its speed-up and go on back until its wheels
    rest; across, it departs by at most its speed times its heading's departure,
    integrated until it is at rest; and where that departure can pass 90 degrees it
    comes back along its report by at most its path since then."""
    now = _progress(speed, turn_rate, age, accel, half_base, up, lag, turn_up)
    if now == -math.inf:
        return now, -math.inf, math.inf
    lo, across = _strip(now, speed, turn_rate, age, accel, half_base, up, lag, turn_up,
                        stop_time)
    return now, lo, across


def _strip(now: float, speed: float, turn_rate: float, age: float, accel: float,
           half_base: float, up: float, lag: float, turn_up: float, stop_time: float
           ) -> tuple[float, float]:
    """(lo, across) of :func:`stop_strip` (same arguments), ``now`` its first value."""
    bend = accel * lag * lag / half_base        # rad, its heading's departure in the lag
    spin = turn_up / half_base                  # rad/s^2, how fast its turn rate can grow
    u0 = abs(turn_rate)
    go = speed - accel * lag
    over = age - (0.0 if 0.0 > go else go) / accel       # s, reversing
    over = 0.0 if 0.0 > over else over
    reverse = accel * lag + up * over           # m/s, at most that fast
    # should it die now: its speed, turn rate, heading's departure and time until at rest
    fast = speed + accel * lag + up * age
    turn = u0 + accel * lag / half_base + spin * age
    dev_age = u0 * age + bend + 0.5 * spin * age * age
    rest = stop_time + (fast + turn * half_base) / accel
    brakes = stopping(fast, accel, 0.0, turn * half_base)
    swing = dev_age + turn * rest
    past = swing - 0.5 * math.pi                # rad, beyond a quarter turn
    past = 0.0 if 0.0 > past else (1.0 if 1.0 < past else past)
    lo = (now - reverse * stop_time - reverse * reverse / (2.0 * accel)
          - (fast * stop_time + brakes) * past)
    a2 = age * age
    across = ((speed + accel * lag) * (0.5 * u0 * a2 + bend * age + spin * a2 * age / 6.0)
              + up * (u0 * a2 * age / 3.0 + 0.5 * bend * a2 + spin * a2 * a2 / 8.0)
              + fast * stop_time * (dev_age + 0.5 * turn * stop_time)
              + brakes * (1.0 if 1.0 < swing else swing))
    return lo, across


def _nearest_on_report(rel_x: float, rel_y: float, hx: float, hy: float, speed: float,
                       age: float) -> tuple[float, float, float, float, float]:
    """(east, north, off, seg_x, seg_y): the point [m] from a neighbour's reported
    position, on the segment (seg_x, seg_y) [m] its report extrapolates along over ``age``
    [s] (``speed`` [m/s] along the unit vector (``hx``, ``hy``) of its heading), nearest
    the point (``rel_x``, ``rel_y``) [m], and its distance [m] from that point."""
    ex, ey = speed * age * hx, speed * age * hy
    length2 = ex * ex + ey * ey
    t = 0.0 if length2 <= 0.0 else (rel_x * ex + rel_y * ey) / length2
    t = 0.0 if 0.0 > t else (1.0 if 1.0 < t else t)
    ox, oy = rel_x - t * ex, rel_y - t * ey      # products, not ** (pow rounds otherwise)
    return t * ex, t * ey, math.sqrt(ox * ox + oy * oy), ex, ey


def approach(rel_x: float, rel_y: float, heading: float, speed: float, turn_rate: float,
             age: float, accel: float, half_base: float, speed_up: float = math.inf,
             lag: float = 0.0, turn_up: float = math.inf) -> float:
    """How much nearer [m] a neighbour can be by now to a point (``rel_x``, ``rel_y``) [m]
    from its reported position than that position is, having reported commanding ``speed``
    [m/s] (signed, along ``heading`` [rad]) and ``turn_rate`` [rad/s] ``age`` [s] ago, each
    wheel's ground speed changing by at most ``accel`` [m/s^2], its law speeding it up (its
    speed and each wheel's share of its turn) by at most ``speed_up`` [m/s^2] (each
    wheel's share of its turn by at most ``turn_up`` [m/s^2] where that is less), its wheels
    following its commands ``lag`` [s] late (a period and the drive latency) and 2
    ``half_base`` [m] apart (accel inf: no bound, on wheels that change speed at once).

    Since its stamp it has been within rho of the segment from its reported position to
    where its report extrapolates to now (docs/controller.md, A10 and A17): its turn rate
    is within accel lag / half_base of the reported one for the lag, then grows by at most
    speed_up / half_base, which bounds how far its heading turns from the reported one.
    Its speed differs from the reported one by at most accel (t + lag), rho including that
    whole difference; or, braking along the segment, its speed grows past the reported one
    (or past zero, reversing) by at most accel lag then speed_up t, rho including only that
    growth and the turn of the faster speed. The smaller counts. The point's distance to
    the segment, less rho, bounds its distance to the neighbour at any time since the
    stamp: a neighbour driving away is not counted as if it could have turned back at
    once."""
    if math.isinf(accel) or half_base <= 0.0:
        return math.inf
    age = max(age, 0.0)
    off = _nearest_on_report(rel_x, rel_y, math.cos(heading), math.sin(heading), speed,
                             age)[2]
    rho = swerve(speed, turn_rate, age, accel, half_base, speed_up, lag, turn_up)
    return math.sqrt(rel_x * rel_x + rel_y * rel_y) - off + rho


def swerve(speed: float, turn_rate: float, age: float, accel: float, half_base: float,
           speed_up: float = math.inf, lag: float = 0.0, turn_up: float = math.inf
           ) -> float:
    """rho [m] of :func:`approach` (same arguments): how far from the segment of its
    report's extrapolation a neighbour can be ``age`` [s] after its stamp (inf: no bound)."""
    if math.isinf(accel) or half_base <= 0.0:
        return math.inf
    up = min(speed_up, accel)
    return _capsule(_STILL, age, speed, turn_rate, 0.0, accel, half_base, up, lag,
                    min(turn_up, up))[0]


def silent_radius(speed: float, turn: float, a: float, accel: float, top_speed: float,
                  staleness: float, stop_time: float, wheel_top: float = math.inf,
                  speed_up: float = math.inf, lag: float = 0.0, turn_up: float = math.inf
                  ) -> float:
    """The radius [m] of the obstacle the law goes round for a silent neighbour (arguments
    as :func:`neighbour_hazard`): its silent disc less a, since the law keeps b > a from an
    obstacle's surface, at least a/2. On a robot that brakes at once (infinite ``accel``)
    a/2 alone: there the disc is what it could drive at top speed until the staleness
    limit, metres for a neighbour silent for a moment, and such discs scatter a formation."""
    if math.isinf(accel):
        return 0.5 * a
    full, _ = neighbour_hazard(speed, turn, math.inf, 0.0, a, accel, top_speed, staleness,
                               stop_time, wheel_top, math.inf, speed_up, lag, turn_up)
    return max(0.5 * a, full - a)


def stopping(speed: float, accel: float, delay: float, turn: float = 0.0) -> float:
    """The longest path [m] of the centre of a robot moving at ``speed`` [m/s] with its
    wheels ``turn`` [m/s] apart (their ground speeds speed +- turn) that holds its command
    for ``delay`` [s], then ramps each wheel to rest on its own at ``accel`` [m/s^2]. The
    centre moves at the mean of the wheels' speeds: while both turn the same way the path
    is the mean of their braking distances, (v^2 + w^2) / (2 accel), more than
    v^2 / (2 accel) as the slower wheel stops first; when they turn opposite ways (a robot
    spinning) the mean holds at v until the slower one stops, then the faster one alone
    drags the centre: v w / accel. At 2 m/s^2, a robot at v = 0.6 m/s spinning with its
    wheels 1.5 m/s apart brakes over 0.45 m, not 0.09 m."""
    speed, turn = abs(speed), abs(turn)
    if math.isinf(accel):
        return speed * delay
    brake = (speed * speed + turn * turn if turn <= speed else 2.0 * speed * turn)
    return speed * delay + brake / (2.0 * accel)


def braking_speed(free: float, accel: float, reaction: float, turn: float = 0.0) -> float:
    """The largest v [m/s] whose path :func:`stopping` (v, accel, reaction, turn) fits in
    free [m] (0 when free <= 0); ``turn`` [m/s] as there, the wheels' half difference."""
    if free <= 0.0:
        return 0.0
    turn = abs(turn)
    if math.isinf(accel):
        return free / reaction if reaction > 0.0 else math.inf
    if reaction + turn / accel > 0.0:              # (a turn of a few ulp is no turn)
        slow = free / (reaction + turn / accel)    # v <= turn: path v reaction + v turn / a
        if slow <= turn:
            return slow
    rest = free - turn * turn / (2.0 * accel)      # v > turn: (v^2 + turn^2) / (2 a)
    return accel * (math.sqrt(reaction * reaction + 2.0 * rest / accel) - reaction)


def speed_limits(x: float, y: float, theta: float, v_now: float, u_now: float,
                 haz_x: FloatSeq, haz_y: FloatSeq, haz_r: FloatSeq, haz_half: FloatSeq,
                 haz_moving: FloatSeq, accel: float, period: float, latency: float,
                 turn_rate: float, wheel_base: float,
                 top_speed: float = math.inf, margin: float = 0.0,
                 turn_up: float = math.inf) -> tuple[float, float, float]:
    """(forward, backward) speed limits [m/s] (inf: none) of a robot at (x, y, theta)
    [m, m, rad] moving at (v_now [m/s], u_now [rad/s]) among hazards (centre; exclusion
    radii [m]: of the whole free distance, and of the half this robot owns (-inf: no such
    rule, :func:`neighbour_hazard`); 1 for a neighbour that moves and 0 for a static disc),
    braking at ``accel`` [m/s^2] each wheel (``wheel_base`` [m] apart) on its own, as its
    drivers do should its agent die (:func:`stopping`). ``period`` [s] is how long a
    command holds (or the drivers' watchdog, when the robot's agent may die); it reaches
    the wheels ``latency`` [s] (at most a period) late: until then the robot goes
    on at v_now (its last command), give or take one period's ramp; a robot already faster
    than it may go brakes at the full ramp.

    While it stops, the robot's heading sweeps on at u_now (braking takes the whole ramp of
    both wheels, so the turn rate holds) and may turn further during the reaction time: at
    up to ``turn_rate`` [rad/s] more, or, with finite ``accel``, as far as its law lets its
    wheels bend the path in that time (u changing at 2 ``turn_up`` / wheel_base, turn_up
    [m/s^2] the most its law speeds up the wheels' half difference, at most accel:
    turn_up tau^2 / wheel_base), whichever is less. A hazard counts
    with the cosine of its bearing's angle to the nearest heading of that sweep (1 inside
    it; none beyond 90 degrees); a moving one as if its bearing were MOVING_PAD nearer, as
    its own motion turns the line of sight. Hazards farther than the robot needs to stop
    from ``top_speed`` [m/s] are skipped.

    The speeds keep ``margin`` [m] more to every hazard, room for the robot's drift along its
    heading while it turns with slipping wheels (:func:`turn_limit`); the third value is that
    room: the least free distance [m] ahead or behind, margin included, over the cosine of
    the hazard's angle, of the hazards the robot is outside of (inf: none near). A disc the
    robot is already inside (a neighbour's that grew round it as its data aged or it died)
    leaves no room to keep; not turning would never take the robot out of it.

    The same in pieces, for a caller that skips the hazards that cannot bind
    (:func:`binding`): :func:`limit_frame`, :func:`fold_hazard` for each hazard, in any
    order, and :func:`frame_limits`."""
    frame = limit_frame(theta, v_now, u_now, accel, period, latency, turn_rate, wheel_base,
                        top_speed, margin, turn_up)
    gaps = NO_GAPS
    for h in range(len(haz_r)):
        gaps = fold_hazard(gaps, frame, haz_x[h] - x, haz_y[h] - y, haz_r[h], haz_half[h],
                           haz_moving[h])
    return frame_limits(gaps, frame)


def limit_frame(theta: float, v_now: float, u_now: float, accel: float, period: float,
                latency: float, turn_rate: float, wheel_base: float,
                top_speed: float = math.inf, margin: float = 0.0,
                turn_up: float = math.inf) -> Frame:
    """What :func:`speed_limits` measures every hazard against (its arguments but the
    hazards and the position), as plain floats: the unit vector along the middle of the
    headings swept while stopping; the cosine, sine and whether-all (1.0 or 0.0) of the
    sweep's half-width for a static hazard and for a moving one; the free distance [m]
    beyond which a hazard is skipped; the margin [m]; then v_now, the speed [m/s] the
    command may differ by in flight, latency, accel, period and the wheels' half
    difference [m/s]."""
    reaction = period + latency
    ramp = 0.0 if math.isinf(accel) else accel * period   # m/s the speed may differ by in flight
    turn = 0.5 * abs(u_now) * wheel_base                 # m/s, the wheels' half difference
    stop_time = reaction + (0.0 if math.isinf(accel) else (abs(v_now) + turn) / accel)
    sweep = u_now * stop_time
    bend = turn_rate * reaction
    if not math.isinf(accel) and wheel_base > 0.0:
        bend = min(bend, min(turn_up, accel) * reaction * reaction / wheel_base)
    spread = 0.5 * abs(sweep) + bend
    middle = theta + 0.5 * sweep
    reach = (top_speed + ramp) * latency + stopping(top_speed, accel, period, turn)
    # the pads as cosine and sine; a pad of half a turn or more takes in every bearing
    moving = spread + MOVING_PAD
    return (math.cos(middle), math.sin(middle),
            math.cos(spread), math.sin(spread), 1.0 if spread >= math.pi else 0.0,
            math.cos(moving), math.sin(moving), 1.0 if moving >= math.pi else 0.0,
            reach + margin, margin, v_now, ramp, latency, accel, period, turn)


def fold_hazard(gaps: tuple[float, float, float], frame: Frame, dx: float, dy: float,
                radius: float, half: float, moving: float) -> tuple[float, float, float]:
    """``gaps`` (the least free distance [m] less the margin, over the cosine, ahead and
    behind, and the room: :func:`speed_limits`; :data:`NO_GAPS` before any hazard) with
    one more hazard, centred (``dx``, ``dy``) [m] from the robot, its exclusion radii
    ``radius`` and ``half`` [m], ``moving`` 1.0 or 0.0 (:func:`speed_limits`), measured
    in ``frame`` (:func:`limit_frame`)."""
    d = math.sqrt(dx * dx + dy * dy)
    free, shared = d - radius, 0.5 * (d - half)
    free = shared if shared < free else free
    if free >= frame[8]:         # cannot hold the robot below its top speed
        return gaps
    gap_fwd, gap_bwd, room = gaps
    margin = frame[9]
    c_fwd = c_bwd = 1.0          # on the robot
    if d >= EPS:
        # cosine and sine of the bearing's angle from the heading
        along = (dx * frame[0] + dy * frame[1]) / d
        across = abs(dx * frame[1] - dy * frame[0]) / d
        pad = 5 if moving != 0.0 else 2
        c_fwd = _cosine(along, across, frame[pad], frame[pad + 1], frame[pad + 2])
        c_bwd = _cosine(-along, across, frame[pad], frame[pad + 1], frame[pad + 2])
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
    return gap_fwd, gap_bwd, room


def binding(gaps: tuple[float, float, float], frame: Frame) -> float:
    """The free distance [m] below which a hazard can change ``gaps`` (:func:`fold_hazard`):
    beyond the margin its gaps are at least its free distance less the margin, a cosine
    being at most 1, and its room at least its free distance; from the distance
    fold_hazard skips, none. A hazard this robot owns no less free distance toward (as
    :func:`neighbour_floor` bounds it) is left out without changing the limits, in any
    order of the hazards."""
    margin = frame[9]
    fwd, bwd, room = margin + gaps[0], margin + gaps[1], gaps[2]
    most = fwd if fwd > margin else margin
    most = bwd if bwd > most else most
    most = room if room > most else most
    return most if most < frame[8] else frame[8]


def frame_limits(gaps: tuple[float, float, float], frame: Frame
                 ) -> tuple[float, float, float]:
    """(forward, backward, room) of :func:`speed_limits` from its ``gaps``, measured in
    ``frame`` (:func:`limit_frame`): braking_speed grows with the free distance, so the
    nearest hazard each way sets the limit."""
    v_now, ramp, latency, accel, period, turn = (frame[10], frame[11], frame[12],
                                                 frame[13], frame[14], frame[15])
    fwd = _limit(gaps[0], max(v_now, 0.0), ramp, latency, accel, period, turn)
    bwd = _limit(gaps[1], max(-v_now, 0.0), ramp, latency, accel, period, turn)
    return fwd, bwd, gaps[2]


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
    cosine), going at ``going`` [m/s] that way now (:func:`speed_limits`)."""
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
    (:func:`speed_limits`): turning with its wheels w [m/s] apart, a robot whose wheels slip
    by up to ``slip`` moves along its heading at up to slip w, and keeps drifting while the
    turn is held for ``reaction`` [s] and ramps down at ``accel`` [m/s^2]. The limit falls
    with the room: a robot that drifted toward a hazard turns ever slower, and backs or
    drives away instead (its speed limits keep the margin of :func:`slip_margin`)."""
    if slip <= 0.0 or math.isinf(room):
        return math.inf
    return 2.0 * braking_speed(room / slip, accel, reaction) / wheel_base
