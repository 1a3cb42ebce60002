"""Where a neighbour can be: the safety governor's disc round each neighbour (A10, A17).

Every hazard of the safety governor (:mod:`agent.governor`) is a disc the robot's centre
must stay out of. A neighbour's disc grows from its *reported* position by what it can have
done since its stamp (its speed and acceleration over the data's age, at most the swarm's
top speed, or less where its reported heading and turn rate say it was driving elsewhere:
:func:`approach`; its acceleration is its law's speed-up where that is below its wheels'
ramp, docs/controller.md A17) and by this robot's own motion over that age, the two paired
at each instant the neighbour may last have acted (:func:`neighbour_radii`). It runs the
same governor, so the free distance between the two is shared half and half: its share is
what it claimed when it last acted on data of this robot, and whatever happened since (it
may have died then) is on this robot, whose motion since then the disc counts as far as it
brought it nearer (:func:`_own_share`). A silent neighbour (older than the staleness limit)
is a static disc at its last known position grown by a and by what it could travel from its
last report until it must have stopped (its drivers' watchdog, then each wheel braking to
rest on its own: :func:`agent.braking.stopping`), taken in full.

What a robot counts on of its neighbours is a :class:`agent.params.NeighbourModel` (the
swarm's robots are alike). Plain floats: agents run this interpreted, the batch simulator
compiled, as the law. Where it runs per neighbour, the least and the largest of two floats
are conditional expressions: ``b if b < a else a`` is what ``min(a, b)`` returns (ties and
NaN alike), and the interpreter runs it several times faster than the builtin.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

from agent.braking import stopping
from agent.trail import Splits

if TYPE_CHECKING:
    from agent.params import NeighbourModel

EPS = 1e-9
FLOOR_PAD = 1e-6     # m, neighbour_floor's bounds are this much looser than rounding needs


class Disc(NamedTuple):
    """A neighbour's hazard (:func:`neighbour_radii`): its exclusion radii [m] round a
    centre (east, north) [m] from its reported position, and its claim's half radius."""

    full: float     # m, this robot owns d - full of a distance d to the centre (-inf: no
    #                 such rule)
    half: float     # m, and (d - half) / 2 of it (-inf: no such rule); the less counts
    east: float     # m
    north: float    # m
    claim: float    # m, the half radius the law passes round (A13)


class Arc(NamedTuple):
    """A set this robot sees ``dist`` [m] away (its distance to the set's nearest point),
    between the unit directions (sx, sy) and (ex, ey) (the shorter arc)."""

    sx: float
    sy: float
    ex: float
    ey: float
    dist: float


class Sight(NamedTuple):
    """This robot's line of sight to a neighbour's report: its distance [m] to the
    report's position and the unit vector toward it, then its distance [m] to the report's
    segment and the unit vector toward the segment's far end (:func:`_capsule`)."""

    dist: float
    sx: float
    sy: float
    off: float
    ex: float
    ey: float


class Report(NamedTuple):
    """A neighbour's report as this robot sees it: this robot's position less the
    report's (rel_x, rel_y) [m] and its length, the unit vector (hx, hy) along the
    reported heading, the reported speed [m/s] and turn rate [rad/s], the data's age [s]."""

    rel_x: float
    rel_y: float
    rel: float
    hx: float
    hy: float
    speed: float
    turn_rate: float
    age: float


_BLIND = Sight(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)    # no line of sight (needed only with a trail)


def neighbour_hazard(speed: float, turn: float, age: float, trail: float, m: NeighbourModel,
                     nearer: float = math.inf) -> tuple[float, float]:
    """(full, half): the exclusion radii [m] around a neighbour's reported position, last
    reported moving at ``speed`` [m/s] and turning with its wheels ``turn`` [m/s] apart
    (half the difference of their ground speeds: |u| times half the wheel base) ``age`` [s]
    ago, ``trail`` [m] this robot's own path since then. This robot owns
    min(d - full, (d - half) / 2) of a distance d to it (-inf: that rule does not apply).
    Its ramp, speed-up (at most the ramp), lag, top speed and wheels' top speed (the wheels
    are at most wheel_top - speed apart) bound how its speed can have changed since; a dead
    agent's drivers keep going for the model's stop time before they brake. ``nearer``
    [m]: how much nearer to this robot than its reported position it can be by now, when
    known from where it was heading (:func:`approach`); heard from, its disc grows by no
    more than that.

    Heard from (age <= staleness): half of the gap beyond a, its travel since the stamp and
    this robot's trail. When it last acted, at its stamp or as late as it lived after it,
    its governor kept its stop (its drivers' watchdog included, should it die) within half
    the true gap beyond a then; this robot was at most its trail from where it is now, so
    the two stops stay a apart (docs/controller.md, A10). Silent (older): a static disc
    grown by what it could travel from its last report until it must have stopped, having
    died as late as the staleness limit after that report (the disc never shrinks as the
    data ages), taken in full."""
    accel, lag, top_speed = m.accel, m.lag, m.top_speed
    speed, turn = abs(speed), abs(turn)
    silent = age > m.staleness
    age = min(max(age, 0.0), m.staleness)     # silent: it may have died as late as that
    grow = _travel(speed, age, accel, min(m.speed_up, accel), lag, top_speed)
    if not silent:
        return -math.inf, m.a + min(grow, nearer) + trail
    now, turn_now = top_speed, turn
    if not math.isinf(accel):
        up = min(m.speed_up, accel)
        now = min(now, speed + accel * lag + up * age)
        # each wheel's speed changes at most accel and stays within wheel_top; the longest
        # stop is at the fastest speed, the wheels as far apart as that leaves them
        turn_now = min(turn + accel * lag + min(up, m.turn_up) * age,
                       max(m.wheel_top - now, 0.0))
    return m.a + grow + stopping(now, accel, m.stop_time, turn_now), -math.inf


def _travel(speed: float, age: float, accel: float, up: float, lag: float,
            top_speed: float) -> float:
    """How far [m] a neighbour last reported at ``speed`` [m/s] (>= 0) can have travelled
    ``age`` [s] (>= 0) later, all round (``accel``, ``lag``, ``top_speed`` as its model's,
    ``up`` its speed-up at most ``accel``): :func:`_grow`, and :func:`_all_round` over one
    split with no motion of this robot's."""
    if math.isinf(accel):
        return top_speed * age
    accel_lag = accel * lag
    return _grow(0.0 if 0.0 > age else age, abs(speed), top_speed, 0.5 * accel, 0.5 * up,
                 accel_lag, accel_lag * lag)


def _all_round(trail: Splits, age: float, speed: float, up: float, m: NeighbourModel,
               sight: Sight = _BLIND) -> float:
    """around [m] of a neighbour heard from on wheels of finite ramp (arguments as
    :func:`neighbour_radii`, ``up`` its speed-up at most its ramp): over the splits of the
    ``age`` (>= 0) paired with this robot's ``trail``, the largest of a + how far it can
    have travelled all round by the split's end + this robot's share of its own motion
    since the split's start (:func:`_own_share`, seen along ``sight``)."""
    around = -math.inf
    splits = len(trail.walked)
    a, accel, _, top_speed, _, _, _, _, lag, _ = m
    dist, sx, sy, _, _, _ = sight
    arc = Arc(sx, sy, sx, sy, dist)
    speed = abs(speed)
    half_accel, half_up, accel_lag = 0.5 * accel, 0.5 * up, accel * lag
    accel_lag2 = accel_lag * lag
    # the last split first: its sum is often the largest, and a share is at most the
    # path since its split's start, so a split whose sum cannot beat the largest so far
    # needs no share
    for k in range(splits - 1, -1, -1):
        if k + 1 < splits and trail.dominated[k] != 0.0:
            continue    # the next split dominates it (agent.trail.trail_motion)
        t = age * (k + 1) / splits
        t = 0.0 if 0.0 > t else t
        grow = _grow(t, speed, top_speed, half_accel, half_up, accel_lag, accel_lag2)
        around = _with_share(trail, k, a, grow, around, arc)
    return around


def _capsule(trail: Splits, age: float, speed: float, turn_rate: float, up: float,
             turn_up: float, m: NeighbourModel, sight: Sight = _BLIND
             ) -> tuple[float, float]:
    """(reach, rho) [m] of a neighbour heard from on wheels of finite ramp (arguments as
    :func:`_all_round`, ``turn_up`` its wheels' half difference's speed-up at most
    ``up``): over the splits of the ``age`` paired as there, the largest of a + rho
    (:func:`swerve`; inf when half its wheel base is 0) by the split's end + this robot's
    share of its own motion since the split's start toward the report's segment; and rho
    at the age itself."""
    reach = -math.inf
    rho_age = math.inf
    splits = len(trail.walked)
    a, accel, half_base, _, _, _, _, _, lag, _ = m
    _, sx, sy, off, ex, ey = sight
    arc = Arc(sx, sy, ex, ey, off)
    speed, half_turn = abs(speed), 0.5 * abs(turn_rate)
    half_accel, half_up, accel_lag = 0.5 * accel, 0.5 * up, accel * lag
    accel_lag2 = accel_lag * lag
    for k in range(splits - 1, -1, -1):       # as _all_round
        if k + 1 < splits and trail.dominated[k] != 0.0:
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
        reach = _with_share(trail, k, a, rho, reach, arc)
    return reach, rho_age


def _with_share(trail: Splits, k: int, a: float, radius: float, best: float, arc: Arc
                ) -> float:
    """The larger of ``best`` [m] and a + ``radius`` [m] + this robot's share of its own
    motion over split ``k`` of ``trail`` toward a set of that radius seen along ``arc``
    (:func:`_own_share`); the share, at most the split's path, is left out where even that
    cannot beat ``best`` (each bound summed as the term is, so that it rounds no lower)."""
    path = trail.walked[k]
    if a + radius + path <= best:
        return best
    bound = a + radius + (_own_share(trail, k, arc, radius) if path > 0.0 else 0.0)
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
                    m: NeighbourModel) -> tuple[float, float]:
    """(floor, top) [m] for a neighbour (arguments as :func:`neighbour_radii`, ``path``
    [m] this robot's path since the stamp: its trail's first value): at most the free
    distance this robot owns toward the disc :func:`neighbour_radii` gives it, whichever
    form that takes, and at least its claim's half radius; (-inf, inf) where it is silent
    or its wheels change speed at once (no bound: the disc is cheap there).

    Heard from, its claim is at most a + how far it can have travelled all round by now
    + this robot's path since the stamp (:func:`_all_round`, at the age), and the claim's
    disc leaves this robot half the distance to the reported position beyond that
    (:func:`neighbour_radii` takes the claim that much smaller as its centre comes nearer
    along the report's segment); behind it, the stop strip leaves more free distance,
    never less (:func:`_ahead`). A few operations: for leaving out the discs that cannot
    bind (agent.governor.binding) before computing them."""
    a, accel, _, top_speed, staleness, _, _, speed_up, lag, _ = m
    if age > staleness or math.isinf(accel):
        return -math.inf, math.inf
    up = accel if accel < speed_up else speed_up
    top = a + _travel(speed, age, accel, up, lag, top_speed) + path + FLOOR_PAD
    dist = math.sqrt(rel_x * rel_x + rel_y * rel_y)
    return 0.5 * (dist - top) - FLOOR_PAD, top


def _own_share(trail: Splits, k: int, arc: Arc, radius: float) -> float:
    """How much [m] of the gap to a neighbour this robot's own motion takes from its half,
    the neighbour having last acted within split ``k`` of its data's age (this robot's
    motion over it: the split's column of ``trail``), at a point within ``radius`` [m] of a
    set this robot sees along ``arc``.

    The neighbour then at q, this robot at p0, kept its stop within half of |q - p0|
    beyond a; this robot, now at p with D = p - p0, must keep its stop within
    |p - q| - |q - p0| / 2 - a / 2 (docs/controller.md A10). With r = |q - p| and x the
    unit vector toward q, |q - p0| <= r + x.D + |D|^2 / (2 r): the share is at most
    x.D + |D|^2 / (2 r), little where this robot moved across the line of sight, and
    never more than |D|, at most its path since the split's start. p0 lies on a path of
    length l between where it was at the split's start and end, so within the ellipse
    of those foci and l: x.D is at most the larger of x.D at the two ends plus the
    ellipse's half minor axis, and x is within the arc widened by asin(radius / dist)."""
    path = trail.walked[k]
    if path <= 0.0:
        return 0.0
    sx, sy, ex, ey, dist = arc
    clear = dist - radius                  # m, the least r
    if clear <= EPS:
        return path
    sin_b = radius / dist                  # the set's points lie within asin(sin_b)
    sin_b = 1.0 if 1.0 < sin_b else sin_b
    cos_b = math.sqrt(1.0 - sin_b * sin_b)
    toward = _toward(trail.start_x[k], trail.start_y[k], trail.start_len[k], sx, sy, ex, ey,
                     cos_b, sin_b)
    toward_end = _toward(trail.end_x[k], trail.end_y[k], trail.end_len[k], sx, sy, ex, ey,
                         cos_b, sin_b)
    toward = toward_end if toward_end > toward else toward
    share = toward + trail.bulge[k] + 0.5 * path * path / clear
    share = share if share > 0.0 else 0.0
    return share if share < path else path


def _toward(dx: float, dy: float, size: float, sx: float, sy: float, ex: float, ey: float,
            cos_b: float, sin_b: float) -> float:
    """The largest component [m] of (``dx``, ``dy``) [m] (of length ``size``) along a
    direction within an angle b (its cosine ``cos_b`` and sine ``sin_b``) of ``arc``."""
    if size <= 0.0:
        return 0.0
    turn = sx * ey - sy * ex
    if (turn != 0.0 and turn * (sx * dy - sy * dx) >= 0.0
            and turn * (dx * ey - dy * ex) >= 0.0 and dx * (sx + ex) + dy * (sy + ey) > 0.0):
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
                    turn_rate: float, age: float, trail: Splits, m: NeighbourModel) -> Disc:
    """The :class:`Disc` of a neighbour reported at (x, y) = this robot's position less
    (``rel_x``, ``rel_y``) [m], along ``heading`` [rad] at ``speed`` [m/s] and
    ``turn_rate`` [rad/s], ``age`` [s] ago: the exclusion radii of
    :func:`neighbour_hazard` of a disc centred (east, north) [m] from its reported
    position, and the half radius [m] of its claim's disc, which the law passes round
    (A13): the same as ``half`` unless this robot is behind it (below). ``trail``: this
    robot's motion over each of the splits of the age (agent.trail.own_motion).

    Heard from, on wheels of finite ramp, the neighbour can be now within rho of the
    segment from its reported position to where its report extrapolates to now
    (:func:`approach`). That capsule is convex, so along a straight path this robot's
    distance to it falls at most as fast as toward its point nearest this robot: the disc
    is centred there, and the governor's cosine (agent.governor.fold_hazard) bounds the
    approach of a neighbour that drives on beside this robot, which a disc round its old,
    reported position does not (docs/controller.md A10). The neighbour last acted at some
    time since its stamp, where its rho grows with that time and this robot's motion since
    shrinks: the two are paired over each split of the age (rho to its end, the motion
    from its start) and the largest sum counts; the motion counts as far as it took this
    robot toward where the neighbour can have been (:func:`_own_share`). Where the
    all-round bound round the reported position leaves more room, the disc keeps that
    room, still centred on the capsule's nearest point; silent, the static disc round the
    reported position. Behind a neighbour driving away, where it can be and stop bounds
    its stop better than its claim does (:func:`_ahead`)."""
    a, accel, half_base, top_speed, staleness, _, _, speed_up, lag, turn_up = m
    if age > staleness or math.isinf(accel):
        nearer = approach(rel_x, rel_y, heading, speed, turn_rate, age, m)
        full, half = neighbour_hazard(speed, half_base * abs(turn_rate), age,
                                      trail.walked[0], m, nearer)
        return Disc(full, half, 0.0, 0.0, half)
    hx, hy = math.cos(heading), math.sin(heading)
    east, north, off, seg_x, seg_y = _nearest_on_report(rel_x, rel_y, hx, hy, speed, age)
    dist = math.sqrt(rel_x * rel_x + rel_y * rel_y)
    # unit vectors from this robot toward the report's position and its segment's far end
    far_x, far_y = seg_x - rel_x, seg_y - rel_y
    far = math.sqrt(far_x * far_x + far_y * far_y)
    near = EPS if EPS > dist else dist
    far = EPS if EPS > far else far
    sight = Sight(dist, -rel_x / near, -rel_y / near, off, far_x / far, far_y / far)
    up = accel if accel < speed_up else speed_up
    turn_up = up if up < turn_up else turn_up
    reach, rho = _capsule(trail, age, speed, turn_rate, up, turn_up, m, sight)
    beyond = off - reach
    # the all-round bound leaves more room than the capsule only where even its least
    # value, its last split's travel without this robot's share, does; else it is not
    # computed (its splits' shares are half the disc's cost)
    splits = len(trail.walked)
    least = a + _travel(speed, age * splits / splits, accel, up, lag, top_speed)
    if dist - least > beyond:
        within = dist - _all_round(trail, age, speed, up, m, sight)
        beyond = within if within > beyond else beyond
    claim = off - beyond
    report = Report(rel_x, rel_y, dist, hx, hy, speed, turn_rate, age)
    own, to, ahead_x, ahead_y = _ahead(report, up, turn_up, m, rho, 0.5 * (off - claim))
    if to > 0.0:
        return Disc(-math.inf, to - 2.0 * own, ahead_x, ahead_y, claim)
    return Disc(-math.inf, claim, east, north, claim)


def _ahead(report: Report, up: float, turn_up: float, m: NeighbourModel, rho: float,
           free: float) -> tuple[float, float, float, float]:
    """(free, dist, east, north): the free distance [m] this robot owns toward a neighbour
    it is behind, by where the neighbour can be and stop (:func:`_strip`), with the centre
    (east, north) [m] from its reported position it is measured toward, ``dist`` [m] from
    this robot; or (``free``, 0, 0, 0) where that gives no more (``up`` and ``turn_up``
    at most its ramp, ``rho`` [m] as :func:`swerve`).

    The neighbour's stop lies in the strip whenever it last acted, so this robot keeps its
    own stop a from the strip instead of half the gap from the neighbour's claim
    (docs/controller.md A10, "A neighbour this robot is behind"); and within its own half
    of the gap, which the neighbour counts on when it acts again, measured from the part
    of the report's segment the neighbour can be on by now. The cheap bounds come first:
    an agent runs this for every neighbour every period."""
    rel_x, rel_y, rel, hx, hy, speed, turn_rate, age = report
    a, accel, half_base = m.a, m.accel, m.half_base
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
    now = _progress(v, turn_rate, age, up, turn_up, m)
    along = 0.0 if 0.0 > now else now                 # on the report's segment, by now
    along = along if along > ahead else ahead
    along = v * age if v * age < along else along
    ox, oy = along * hx - rel_x, along * hy - rel_y
    dist = math.sqrt(ox * ox + oy * oy)
    half = 0.5 * (dist - rho - a)
    if now == -math.inf or dist <= EPS or half <= free:
        return none
    lo, across = _strip(now, v, turn_rate, age, up, turn_up, m)
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


def _progress(speed: float, turn_rate: float, age: float, up: float, turn_up: float,
              m: NeighbourModel) -> float:
    """The least distance [m] along its reported heading from its reported position a
    neighbour reported ``age`` [s] ago driving at ``speed`` [m/s] (> 0) and turning at
    ``turn_rate`` [rad/s] can be at by now (its law speeding it up by at most ``up`` and
    its wheels' half difference by at most ``turn_up`` [m/s^2]; -inf: no bound): braking
    at the full ramp from its stamp, after its wheels' lag, along every heading its turn
    allows (the cosine of the largest), then reversing at its speed-up once stopped."""
    accel, lag, half_base = m.accel, m.lag, m.half_base
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


def _strip(now: float, speed: float, turn_rate: float, age: float, up: float,
           turn_up: float, m: NeighbourModel) -> tuple[float, float]:
    """(lo, across) [m] for a neighbour (arguments as :func:`_progress`, ``now`` its
    value): measured from its reported position along and across its reported heading,
    from now until it is at rest, should it have last acted at any time since its stamp,
    it is at least ``lo`` along and at most ``across`` across (its drivers going on for
    the model's stop time should its agent die).

    Once stopped it can have reversed at its speed-up and go on back until its wheels
    rest; across, it departs by at most its speed times its heading's departure,
    integrated until it is at rest; and where that departure can pass 90 degrees it
    comes back along its report by at most its path since then."""
    accel, lag, half_base, stop_time = m.accel, m.lag, m.half_base, m.stop_time
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
             age: float, m: NeighbourModel) -> float:
    """How much nearer [m] a neighbour can be by now to a point (``rel_x``, ``rel_y``) [m]
    from its reported position than that position is, having reported commanding ``speed``
    [m/s] (signed, along ``heading`` [rad]) and ``turn_rate`` [rad/s] ``age`` [s] ago (inf:
    no bound, on wheels that change speed at once). Each wheel's ground speed changes by at
    most the model's ramp, its law speeds it up (its speed and each wheel's share of its
    turn) by at most its speed-up (each wheel's share of its turn by at most its turn
    speed-up where that is less), its wheels follow its commands its lag late.

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
    if math.isinf(m.accel) or m.half_base <= 0.0:
        return math.inf
    age = max(age, 0.0)
    off = _nearest_on_report(rel_x, rel_y, math.cos(heading), math.sin(heading), speed,
                             age)[2]
    rho = swerve(speed, turn_rate, age, m)
    return math.sqrt(rel_x * rel_x + rel_y * rel_y) - off + rho


def _still() -> Splits:
    """The splits of a robot that has not moved, one split."""
    z = (0.0,)          # read only: a tuple (compiled, no allocation)
    return Splits(z, z, z, z, z, z, z, z, z, z)     # type: ignore[arg-type]


def swerve(speed: float, turn_rate: float, age: float, m: NeighbourModel) -> float:
    """rho [m] of :func:`approach` (same arguments): how far from the segment of its
    report's extrapolation a neighbour can be ``age`` [s] after its stamp (inf: no bound)."""
    if math.isinf(m.accel) or m.half_base <= 0.0:
        return math.inf
    up = min(m.speed_up, m.accel)
    # rho at the age: the capsule's reach with a = 0 over a trail that did not move
    return _capsule(_still(), age, speed, turn_rate, up, min(m.turn_up, up), m, _BLIND)[1]


def silent_radius(speed: float, turn: float, m: NeighbourModel) -> float:
    """The radius [m] of the obstacle the law goes round for a silent neighbour reported at
    ``speed`` [m/s], its wheels ``turn`` [m/s] apart (:func:`neighbour_hazard`): its silent
    disc less a, since the law keeps b > a from an obstacle's surface, at least a/2. On a
    robot that brakes at once (infinite ramp) a/2 alone: there the disc is what it could
    drive at top speed until the staleness limit, metres for a neighbour silent for a
    moment, and such discs scatter a formation."""
    if math.isinf(m.accel):
        return 0.5 * m.a
    full, _ = neighbour_hazard(speed, turn, math.inf, 0.0, m)
    return max(0.5 * m.a, full - m.a)
