"""Where a neighbour can be (agent.discs): the safety governor's disc round each neighbour,
heard from or silent, paired with this robot's own motion, and the promise that a robot
keeping its stop out of it stops a from where the neighbour stops."""
import math

import pytest
from governor_cases import ACCEL, STALE, STOP, TOP, A, neighbour, speed_limits, walk
from helpers import model
from hypothesis import example, given, settings
from hypothesis import strategies as st

from agent.braking import stopping
from agent.discs import (
    Arc,
    Sight,
    _all_round,
    _capsule,
    _grow,
    _nearest_on_report,
    _own_share,
    _progress,
    _strip,
    approach,
    neighbour_floor,
    neighbour_hazard,
    neighbour_radii,
    silent_radius,
)
from agent.kinematics import arc_step
from agent.params import NeighbourModel
from agent.trail import SPLITS, Splits, splits_of, straight

BLIND = Sight(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def _paired(trail: Splits, age: float, speed: float, turn_rate: float, up: float,
            turn_up: float, m: NeighbourModel, sight: Sight = BLIND
            ) -> tuple[float, float, float]:
    """(around, reach, rho) of a neighbour's splits: both bounds, each over all splits."""
    return (_all_round(trail, age, speed, up, m, sight),
            *_capsule(trail, age, speed, turn_rate, up, turn_up, m, sight))


def stop_strip(speed: float, turn_rate: float, age: float, up: float, turn_up: float,
               m: NeighbourModel) -> tuple[float, float, float]:
    """(now, lo, across) [m] for a neighbour reported ``age`` [s] ago driving at ``speed``
    [m/s] (> 0, along its reported heading) and turning at ``turn_rate`` [rad/s], its law
    speeding it up by at most ``up`` and its wheels' half difference by at most
    ``turn_up`` [m/s^2] (A17), its ramp (finite), half wheel base, lag and stop time as
    ``m`` says. Measured from its reported position along and across its reported
    heading: it is at least ``now`` along by now (:func:`agent.discs._progress`); and from
    now until it is at rest, should it have last acted at any time since its stamp, at
    least ``lo`` along and at most ``across`` across (:func:`agent.discs._strip`; lo =
    -inf: no bound)."""
    now = _progress(speed, turn_rate, age, up, turn_up, m)
    if now == -math.inf:
        return now, -math.inf, math.inf
    return (now, *_strip(now, speed, turn_rate, age, up, turn_up, m))


def test_a_neighbour_heard_from_shares_beyond_its_travel_and_this_robot_s_trail():
    """However old its data (within the staleness limit): half the gap beyond a, what it
    can have travelled since its stamp and this robot's own path since then."""
    m = model(a=A, accel=ACCEL, top_speed=TOP, staleness=STALE, stop_time=STOP)
    for age in (0.05, 0.3, STALE):
        full, half = neighbour_hazard(2.0, 0.0, age, 0.4, m)
        assert full == -math.inf
        travel = min(TOP * age, 2.0 * age + 0.5 * ACCEL * age ** 2)
        assert half == pytest.approx(A + travel + 0.4)


@settings(max_examples=500, deadline=None)
@given(pts=st.lists(st.floats(-10.0, 10.0), min_size=8, max_size=8),
       fr=st.lists(st.floats(0.0, 1.0), min_size=2, max_size=2))
def test_sharing_with_old_data_keeps_two_stops_apart_should_the_neighbour_die(pts, fr):
    """The argument of A10 on points: neighbour j last reported from s; it lived on until
    some time when it was at q (within its travel bound g of s) and this robot was at p0,
    and there its governor kept its stop within half the true gap beyond a. Since then this
    robot went to p (its trail: at least |p - p0|) and keeps its stop within half of
    |p - s| beyond its disc of j. Wherever each stop ends in its bound, the two are at least
    a apart; without the trail they are not always."""
    s, q, p0, p = (pts[0:2], pts[2:4], pts[4:6], pts[6:8])
    dist = math.dist
    g, trail = dist(s, q) * (1.0 + fr[0]), dist(p0, p) * (1.0 + fr[1])
    own = 0.5 * (dist(s, p) - A - g - trail)         # this robot's share of the gap
    theirs = 0.5 * (dist(q, p0) - A)                 # the neighbour's, when it last acted
    if own < 0.0 or theirs < 0.0:
        return
    # each stop ends anywhere in its bound: the worst, both on the line between them
    assert dist(p, q) - own - theirs >= A - 1e-9


@settings(max_examples=3000, deadline=None)
@given(pts=st.lists(st.floats(-6.0, 6.0), min_size=4, max_size=4),
       moves=st.lists(st.floats(-3.0, 3.0), min_size=8, max_size=8),
       g=st.floats(0.0, 2.0), turn=st.floats(-math.pi, math.pi),
       fr=st.lists(st.floats(0.0, 1.0), min_size=4, max_size=4))
def test_this_robot_s_share_of_its_own_motion_keeps_two_stops_apart(pts, moves, g, turn, fr):
    """The same on points with this robot's motion counted by its direction
    (:func:`agent.discs._own_share`): the neighbour last acted at q, within g of a
    segment from s to e, while this robot was at p0, on its way (two legs, by a bend)
    from where it was at the split's start to where it was at its end, w; since then it
    went to p. It keeps its stop within half of its distance to the segment beyond a, g
    and its share; the two stops are a apart."""
    s, p = pts[0:2], pts[2:4]
    dist = math.dist
    e = (s[0] + moves[0], s[1] + moves[1])
    on = (s[0] + fr[0] * moves[0], s[1] + fr[0] * moves[1])
    q = (on[0] + g * fr[1] * math.cos(turn), on[1] + g * fr[1] * math.sin(turn))
    start = (p[0] + moves[2], p[1] + moves[3])
    w = (start[0] - moves[4] / 3.0 * moves[2], start[1] - moves[5] / 3.0 * moves[3])
    bend = (0.5 * (start[0] + w[0]) + moves[6] / 3.0, 0.5 * (start[1] + w[1]) + moves[7] / 3.0)
    leg = (start, bend) if fr[2] < 0.5 else (bend, w)
    p0 = (leg[0][0] + fr[3] * (leg[1][0] - leg[0][0]), leg[0][1] + fr[3] * (leg[1][1] - leg[0][1]))
    within = dist(start, bend) + dist(bend, w)        # path from start to w
    path = within + dist(w, p)                        # and on to p
    off = _segment_distance(p, s, e)
    units = [((pt[0] - p[0]) / max(dist(pt, p), 1e-12), (pt[1] - p[1]) / max(dist(pt, p), 1e-12))
             for pt in (s, e)]
    trail = splits_of(([path], [path - within], [p[0] - start[0]], [p[1] - start[1]],
                       [p[0] - w[0]], [p[1] - w[1]]))
    share = _own_share(trail, 0, Arc(*units[0], *units[1], off), g)
    assert 0.0 <= share <= path
    own = 0.5 * (off - A - g - share)
    theirs = 0.5 * (dist(q, p0) - A)
    if own < 0.0 or theirs < 0.0:
        return
    assert dist(p, q) - own - theirs >= A - 1e-9


def _segment_distance(p: tuple, s: tuple, e: tuple) -> float:
    """The distance [m] from point p to the segment from s to e."""
    ex, ey = e[0] - s[0], e[1] - s[1]
    length2 = ex * ex + ey * ey
    t = 0.0 if length2 <= 0.0 else min(max(((p[0] - s[0]) * ex + (p[1] - s[1]) * ey)
                                           / length2, 0.0), 1.0)
    return math.dist(p, (s[0] + t * ex, s[1] + t * ey))


def _drive(v: float, u: float, accel: float, half: float, age: float, plan: list, steps: int
           ) -> list[tuple[float, float, float, float, float]]:
    """States (x [m], y [m], heading [rad], right and left wheel ground speeds [m/s]) every
    age/steps of a robot reported at the origin along x at v and u, each wheel's ground
    speed changing at up to accel (piecewise, per ``plan``)."""
    x = y = theta = 0.0
    right, left = v + u * half, v - u * half
    out = [(x, y, theta, right, left)]
    dt = age / steps
    for k in range(steps):
        ar, al = plan[k * len(plan) // steps]
        # the step's mean wheel speeds (an Euler step at its end speed drives too far)
        mid_r, mid_l = right + 0.5 * ar * accel * dt, left + 0.5 * al * accel * dt
        right += ar * accel * dt
        left += al * accel * dt
        x, y, theta = arc_step(x, y, theta, 0.5 * (mid_r + mid_l) * dt,
                               (mid_r - mid_l) / (2.0 * half) * dt)
        out.append((x, y, theta, right, left))
    return out


def _stop(state: tuple[float, float, float, float, float], half: float, accel: float,
          hold: float) -> tuple[float, float]:
    """Where [m] a robot in ``state`` (as :func:`_drive`) comes to rest should its agent
    die (:func:`dead_path`)."""
    return dead_path(state, 2.0 * half, accel, hold, dt=1e-3)[-1]


@settings(max_examples=300, deadline=None)
@given(v=st.floats(-2.0, 2.0), u=st.floats(-2.0, 2.0), age=st.floats(0.02, 0.5),
       start=st.tuples(st.floats(-6.0, 6.0), st.floats(-6.0, 6.0)),
       legs=st.lists(st.tuples(st.floats(-math.pi, math.pi), st.floats(0.0, 3.0)),
                     min_size=4, max_size=4),
       plan=st.lists(st.tuples(st.sampled_from([-1.0, 0.0, 1.0]),
                               st.sampled_from([-1.0, 0.0, 1.0])), min_size=4, max_size=4))
def test_pairing_the_neighbour_s_travel_with_this_robot_s_path_keeps_stops_apart(
        v, u, age, start, legs, plan):
    """A10's argument over time: neighbour j, reported at the origin, drives on (wheels at
    up to ACCEL) and last acts at any instant t of the age, at q(t), this robot then at
    p(t), keeping its stop within half of |q(t) - p(t)| beyond a. This robot drove from
    ``start`` in four straight legs to p and keeps its stop within half of |p - s| beyond
    the half radius of :func:`agent.discs.neighbour_radii`, which pairs the two over the
    age's splits, or, behind j, a from where j stops (:func:`stop_strip`). The two stops
    end at least a apart, whenever j last acted and wherever it stopped within its half."""
    steps = 64
    half_base = 0.3
    states = _drive(v, u, ACCEL, half_base, age, plan, steps)
    q = [state[:2] for state in states]
    p = [start]
    for k in range(steps):
        heading, speed = legs[k * len(legs) // steps]
        dt = age / steps
        p.append((p[-1][0] + speed * dt * math.cos(heading),
                  p[-1][1] + speed * dt * math.sin(heading)))
    walked = [0.0]
    for k in range(steps, 0, -1):                 # path from each instant to the end
        walked.insert(0, walked[0] + math.dist(p[k], p[k - 1]))
    ends = [round(steps * k / SPLITS) for k in range(SPLITS + 1)]
    now = p[-1]
    trail = splits_of(([walked[i] for i in ends[:-1]], [walked[i] for i in ends[1:]],
                       [now[0] - p[i][0] for i in ends[:-1]],
                       [now[1] - p[i][1] for i in ends[:-1]],
                       [now[0] - p[i][0] for i in ends[1:]],
                       [now[1] - p[i][1] for i in ends[1:]]))
    m = model(a=A, accel=ACCEL, half_base=half_base, top_speed=TOP, staleness=STALE,
              stop_time=STOP, wheel_top=8.0)
    full, half, east, north, _ = neighbour_radii(now[0], now[1], 0.0, v, u, age, trail, m)
    own = 0.5 * (math.dist(now, (east, north)) - half)
    assert full == -math.inf
    for k in range(steps + 1):
        theirs = 0.5 * (math.dist(q[k], p[k]) - A)
        stop = _stop(states[k], half_base, ACCEL, STOP)
        if own >= 0.0 and math.dist(stop, q[k]) <= theirs:
            assert math.dist(now, stop) - own >= A - 1e-6


def test_a_neighbour_driving_on_beside_this_robot_is_met_where_it_is_now():
    """Two fast robots driving on side by side, paths 13 degrees apart and closing, data
    0.44 s old (from the realistic campaign with places assigned, where two such robots
    collided): the neighbour's report lies behind this robot, so a disc round it is one
    this robot drives away from, and its governor let it drive on. The disc is centred
    where the neighbour's report extrapolates to (the capsule's point nearest this
    robot, within it), and the governor brakes."""
    age, speed, heading = 0.44, 5.9, 2.23                     # this robot, at the origin
    v_n, heading_n, now_n = 5.1, 2.45, (2.79, 2.29)           # the neighbour, now
    reported = (now_n[0] - v_n * age * math.cos(heading_n),
                now_n[1] - v_n * age * math.sin(heading_n))
    trail = _straight(speed, heading, age)
    m = model(a=1.0, accel=6.0, half_base=0.25, top_speed=6.0, staleness=0.8, stop_time=0.13,
              wheel_top=6.0, speed_up=6.0, lag=0.03, turn_up=6.0)
    full, half, east, north, _ = neighbour_radii(-reported[0], -reported[1], heading_n, v_n,
                                                 0.0, age, trail, m)
    centre = (reported[0] + east, reported[1] + north)
    assert centre == pytest.approx(now_n, abs=1e-9)

    def allowed(x, y):
        return speed_limits(0.0, 0.0, heading, speed, 0.0, [x], [y], [full], [half], [1.0],
                            6.0, 0.1, 0.03, 9.4, 0.5, 6.0, 0.0, 6.0)[0]

    assert allowed(*centre) == 0.0                   # behind its braking curve: brake
    assert allowed(*reported) > speed                # the report's own disc: drive on


def test_a_neighbour_met_head_on_with_old_data_is_paired_with_this_robot_s_path():
    """Both at 1.5 m/s toward each other, data 0.5 s old: the neighbour's travel and this
    robot's path are not both counted in full (0.75 m each), only as far as they can add up
    at one instant the neighbour last acted; with one split, in full."""
    age, speed = 0.5, 1.5
    trail = _straight(speed, 0.0, age)
    m = model(a=A, accel=ACCEL, half_base=0.3, top_speed=TOP, staleness=STALE, stop_time=STOP,
              wheel_top=8.0)

    def room(trail):         # m, from this robot to the edge of the neighbour's disc
        _, half, east, north, _ = neighbour_radii(-6.0, 0.0, math.pi, speed, 0.0, age, trail,
                                                  m)
        return math.hypot(-6.0 - east, north) - half

    travel = min(approach(-6.0, 0.0, math.pi, speed, 0.0, age,
                          model(accel=ACCEL, half_base=0.3)),
                 speed * age + 0.5 * ACCEL * age * age)
    assert room(_straight(speed, 0.0, age, 1)) == pytest.approx(
        6.0 - (A + travel + speed * age))                                         # 2.75 m
    assert room(trail) > room(_straight(speed, 0.0, age, 1)) + 0.5


def _straight(speed: float, heading: float, age: float, splits: int = SPLITS) -> Splits:
    """The splits (agent.discs.neighbour_radii's trail) of a robot driving straight along
    ``heading`` [rad] at ``speed`` [m/s] over ``age`` [s] split ``splits`` ways."""
    return straight(speed, math.cos(heading), math.sin(heading), age, splits)


def test_a_robot_driving_beside_a_neighbour_counts_little_of_its_own_motion():
    """Side by side 5 m apart at 1.5 m/s with data 0.5 s old: this robot moved along the
    line the neighbour drives, not toward it, and its disc of the neighbour is smaller than
    one that counts its path in full; driving straight at it, the same."""
    age, speed = 0.5, 1.5
    m = model(a=A, accel=ACCEL, half_base=0.3, top_speed=TOP, staleness=STALE, stop_time=STOP,
              wheel_top=8.0)

    def half(heading):       # the neighbour 5 m north, both driving east
        trail = _straight(speed, heading, age)
        return neighbour_radii(speed * age, -5.0, 0.0, speed, 0.0, age, trail, m).half

    print(half(0.0), half(0.5 * math.pi))
    assert half(0.0) < half(0.5 * math.pi) - 0.2


@settings(max_examples=300, deadline=None)
@given(v=st.floats(-3.0, 3.0), u=st.floats(-4.0, 4.0), accel=st.floats(0.5, 25.0),
       base=st.floats(0.2, 0.8), age=st.floats(0.0, 0.6),
       point=st.tuples(st.floats(-2.0, 6.0), st.floats(-2.0, 2.0)),
       wheel_acc=st.lists(st.tuples(st.sampled_from([-1.0, 0.0, 1.0]),
                                    st.sampled_from([-1.0, 0.0, 1.0])),
                          min_size=6, max_size=6))
def test_a_neighbour_is_never_nearer_than_its_heading_allows(v, u, accel, base, age, point,
                                                             wheel_acc):
    """A neighbour reported at the origin, heading along x at v and turning at u, drives on
    for ``age`` with each wheel's ground speed changing at up to ``accel`` (piecewise
    constant, any sign, in six stretches): at every instant its distance to ``point`` is at
    least the distance from the origin less :func:`agent.discs.approach`, and
    :func:`agent.discs.approach` never grants more than a disc centred on the origin
    would."""
    half = 0.5 * base
    nearer = approach(point[0], point[1], 0.0, v, u, age, model(accel=accel, half_base=half))
    d0 = math.hypot(*point)
    assert nearer >= 0.0
    x = y = theta = 0.0
    right, left = v + u * half, v - u * half          # wheels' ground speeds [m/s]
    steps = 600
    dt = age / steps
    for k in range(steps):
        ar, al = wheel_acc[k * len(wheel_acc) // steps]
        # the step's mean wheel speeds (an Euler step at its end speed drove too far)
        mid_r, mid_l = right + 0.5 * ar * accel * dt, left + 0.5 * al * accel * dt
        right += ar * accel * dt
        left += al * accel * dt
        speed, turn = 0.5 * (mid_r + mid_l), (mid_r - mid_l) / base
        x, y, theta = arc_step(x, y, theta, speed * dt, turn * dt)
        assert math.hypot(point[0] - x, point[1] - y) >= d0 - nearer - 1e-6


def _toward(value: float, target: float, step: float) -> float:
    return value + min(max(target - value, -step), step)


def _committed(now: float, choice: float, up: float, brake: float) -> float:
    """A set-point part one step on: grown by ``up`` (choice 1), held (0), or braked by
    ``brake`` toward zero and past it by at most ``up`` (-1)."""
    if choice > 0.0:
        return now + math.copysign(up, now) if now != 0.0 else up
    if choice < 0.0:
        return now - brake if now > brake else (now + brake if now < -brake else
                                                -math.copysign(up, now))
    return now


@settings(max_examples=300, deadline=None)
@example(v=3.0, u=0.0, accel=25.0, up=2.0, turn=1.0, base=0.3, age=0.6, lag=(0.02, 0.01),
         before=(0.0, 0.0), point=(1.5, 2.0), plan=[(0.0, 1.0)] * 6)      # turning ever faster
@example(v=3.0, u=0.0, accel=25.0, up=2.0, turn=0.2, base=0.3, age=0.6, lag=(0.02, 0.01),
         before=(0.0, 0.0), point=(2.0, 1.0), plan=[(0.0, 1.0)] * 6)
@given(v=st.floats(-3.0, 3.0), u=st.floats(-4.0, 4.0), accel=st.floats(2.0, 25.0),
       up=st.floats(0.5, 2.0), turn=st.floats(0.05, 1.0), base=st.floats(0.3, 0.8),
       age=st.floats(0.01, 0.6), lag=st.tuples(st.floats(0.01, 0.02), st.floats(0.0, 0.03)),
       before=st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)),
       point=st.tuples(st.floats(-2.0, 6.0), st.floats(-2.0, 2.0)),
       plan=st.lists(st.tuples(st.sampled_from([-1.0, 0.0, 1.0]),
                               st.sampled_from([-1.0, 0.0, 1.0])), min_size=6, max_size=6))
def test_a_neighbour_that_speeds_up_slowly_is_never_nearer_than_its_report_allows(
        v, u, accel, up, turn, base, age, lag, before, point, plan):
    """A17: a neighbour whose law speeds it up (its speed at ``up``, each wheel's share of
    its turn at ``turn`` x up) and brakes at up to ``accel``, reported at the origin commanding v
    along x and u; its wheels follow its commands a drive latency late at their ramp, and
    at the stamp still run the command of a period before (within a period's ramp of the
    reported one). At every instant its distance to ``point`` is at least the distance
    from the origin less :func:`agent.discs.approach` with that speed-up and lag."""
    period, latency = lag
    half = 0.5 * base
    nearer = approach(point[0], point[1], 0.0, v, u, age,
                      model(accel=accel, half_base=half, speed_up=up, lag=period + latency,
                            turn_up=turn * up))
    d0 = math.hypot(*point)
    sv, sw = v, u * half                               # set-point: speed, half difference
    wv = v + before[0] * accel * period                # the wheels: the command before
    ww = sw + before[1] * accel * period
    x = y = theta = 0.0
    steps = 600
    dt = age / steps
    history = [(sv, sw)]
    for k in range(steps):
        cv, cw = plan[k * len(plan) // steps]
        sv = _committed(sv, cv, up * dt, accel * dt)
        sw = _committed(sw, cw, turn * up * dt, accel * dt)
        history.append((sv, sw))
        if (k + 1) * dt >= latency:                    # the command latency ago
            tv, tw = history[max(len(history) - 1 - round(latency / dt), 0)]
            right, left = wv + ww, wv - ww             # each wheel ramps on its own
            right = _toward(right, tv + tw, accel * dt)
            left = _toward(left, tv - tw, accel * dt)
            wv, ww = 0.5 * (right + left), 0.5 * (right - left)
        x, y, theta = arc_step(x, y, theta, wv * dt, ww / half * dt)
        assert math.hypot(point[0] - x, point[1] - y) >= d0 - nearer - 1e-6


@settings(max_examples=300, deadline=None)
@example(v=2.5, u=0.0, accel=6.0, up=2.0, turn=1.0, base=0.6, age=0.55, lag=(0.02, 0.01),
         before=(0.0, 0.0), plan=[(1.0, 1.0)] * 6, died=1.0, hold=0.1)  # the fast robot
@example(v=0.2, u=0.0, accel=2.0, up=2.0, turn=1.0, base=0.8, age=0.6, lag=(0.02, 0.02),
         before=(-1.0, 0.0), plan=[(-1.0, 0.0)] * 6, died=1.0, hold=0.2)  # reverses
@given(v=st.floats(0.05, 3.0), u=st.floats(-2.0, 2.0), accel=st.floats(2.0, 25.0),
       up=st.floats(0.5, 2.0), turn=st.floats(0.05, 1.0), base=st.floats(0.3, 0.8),
       age=st.floats(0.01, 0.6), lag=st.tuples(st.floats(0.01, 0.02), st.floats(0.0, 0.03)),
       before=st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)),
       plan=st.lists(st.tuples(st.sampled_from([-1.0, 0.0, 1.0]),
                               st.sampled_from([-1.0, 0.0, 1.0])), min_size=6, max_size=6),
       died=st.floats(0.0, 1.0), hold=st.floats(0.05, 0.2))
def test_a_neighbour_stops_in_the_strip_ahead_of_its_report(
        v, u, accel, up, turn, base, age, lag, before, plan, died, hold):
    """A10, a neighbour this robot is behind: reported at the origin driving along x at v
    and turning at u, it keeps the commitment of A17 (as the test above) and dies at any
    instant of the age; its drivers go on with the commands already sent for ``hold`` s,
    then ramp each wheel to rest. By the age it is at least :func:`stop_strip`'s ``now``
    along x, and from then until at rest at least ``lo`` along and at most ``across``
    across."""
    period, latency = lag
    half = 0.5 * base
    now, lo, across = stop_strip(v, u, age, up, turn * up,
                                 model(accel=accel, half_base=half, lag=period + latency,
                                       stop_time=hold + latency))
    sv, sw = v, u * half
    wv = v + before[0] * accel * period
    ww = sw + before[1] * accel * period
    x = y = theta = 0.0
    dt = age / 600
    death = died * age
    history = [(sv, sw)]
    k = 0
    while k * dt < age or wv != 0.0 or ww != 0.0:
        t = k * dt
        if t < death:                                  # alive: its law's next set-point
            cv, cw = plan[min(int(t / age * len(plan)), len(plan) - 1)]
            sv = _committed(sv, cv, up * dt, accel * dt)
            sw = _committed(sw, cw, turn * up * dt, accel * dt)
        history.append((sv, sw))
        right, left = wv + ww, wv - ww
        if t < death + hold + latency:                 # the drivers follow the commands
            if t + dt >= latency:
                tv, tw = history[max(len(history) - 1 - round(latency / dt), 0)]
                right = _toward(right, tv + tw, accel * dt)
                left = _toward(left, tv - tw, accel * dt)
        else:                                          # the watchdog: each wheel to rest
            right, left = _toward(right, 0.0, accel * dt), _toward(left, 0.0, accel * dt)
        mid_v, mid_w = 0.5 * (0.5 * (right + left) + wv), 0.5 * (0.5 * (right - left) + ww)
        wv, ww = 0.5 * (right + left), 0.5 * (right - left)
        x, y, theta = arc_step(x, y, theta, mid_v * dt, mid_w / half * dt)
        k += 1
        if abs(k * dt - age) < 0.5 * dt:
            assert x >= now - 1e-6
        if k * dt >= age:
            assert x >= lo - 1e-6
            assert abs(y) <= across + 1e-6
        assert k < 10 ** 6


def test_a_neighbour_that_speeds_up_slowly_is_grown_less_head_on():
    """A sporty neighbour (25 m/s^2 wheels) heading at this robot with 0.5 s old data: its
    law's 2 m/s^2 speed-up grows its disc by a fraction of what its wheels alone allow."""
    age, speed, half = 0.5, 2.0, 0.25
    wheels = approach(5.0, 0.0, 0.0, speed, 1.0, age, model(accel=25.0, half_base=half))
    committed = approach(5.0, 0.0, 0.0, speed, 1.0, age,
                         model(accel=25.0, half_base=half, speed_up=2.0, lag=0.03))
    assert wheels - speed * age > 3.0                    # beyond 1/2 x 25 m/s^2 x age^2
    assert committed - speed * age < 0.4 * (wheels - speed * age)


def test_a_neighbour_driving_away_is_not_grown_by_its_speed():
    """Ahead of this robot and driving away at 1.5 m/s with 0.27 s old data (a 0.2 s link):
    its disc grows by what braking or turning could leave it short of the extrapolation,
    not by its whole travel; head on, by its whole travel."""
    age, speed, base = 0.27, 1.5, 0.5
    travel = speed * age + 0.5 * ACCEL * age ** 2
    wheels = model(accel=ACCEL, half_base=0.5 * base)
    away = approach(-2.0, -2.0, math.atan2(2.0, 2.0), speed, 0.0, age, wheels)
    head_on = approach(3.0, 0.0, 0.0, speed, 0.0, age, wheels)
    assert away < 0.3 * travel
    assert head_on == pytest.approx(speed * age + 0.5 * ACCEL * age ** 2
                                    + speed * ACCEL * age ** 3 / (3.0 * base))
    m = model(a=A, accel=ACCEL, top_speed=TOP, staleness=STALE, stop_time=STOP)
    _, half = neighbour_hazard(speed, 0.0, age, 0.4, m, nearer=away)
    assert half == pytest.approx(A + away + 0.4)
    assert approach(3.0, 0.0, 0.0, speed, 0.0, age,
                    model(accel=math.inf, half_base=0.25)) == math.inf   # ideal


def test_without_the_trail_a_dead_neighbour_s_half_is_taken_twice():
    """Head on: j stopped reporting 5 m away, having claimed half the 4 m beyond a, and
    died. This robot drove 1 m toward it since. Sharing the gap it sees now without its
    trail, its stop and j's overlap; with the trail they end a apart."""
    s = q = (5.0, 0.0)
    p0, p = (0.0, 0.0), (1.0, 0.0)
    theirs = 0.5 * (math.dist(q, p0) - A)
    m = model(a=A, accel=ACCEL, top_speed=0.0, staleness=STALE, stop_time=STOP)
    _, half = neighbour_hazard(0.0, 0.0, 0.3, 0.0, m)
    own_without = 0.5 * (math.dist(p, s) - half)
    _, half = neighbour_hazard(0.0, 0.0, 0.3, 1.0, m)
    own = 0.5 * (math.dist(p, s) - half)
    assert math.dist(p, q) - own_without - theirs < A - 0.4
    assert math.dist(p, q) - own - theirs == pytest.approx(A)


def test_a_silent_neighbour_is_a_static_disc_grown_until_it_must_have_stopped():
    """Reported at 2 m/s straight: it may have driven on until the staleness limit, its
    speed reaching 3 m/s and its wheels drifting up to ACCEL x STALE apart, then held its
    command for the stop time and braked each wheel."""
    m = model(a=A, accel=ACCEL, top_speed=TOP, staleness=STALE, stop_time=STOP)
    full, half = neighbour_hazard(2.0, 0.0, 5.0, 0.0, m)
    assert half == -math.inf
    now, apart = 2.0 + ACCEL * STALE, ACCEL * STALE
    assert full == pytest.approx(A + 2.0 * STALE + 0.5 * ACCEL * STALE ** 2 + now * STOP
                                 + (now ** 2 + apart ** 2) / (2 * ACCEL))
    assert neighbour_hazard(2.0, 0.0, 50.0, 0.0, m)[0] == full


def test_the_law_goes_round_a_silent_neighbour_as_its_disc_less_a():
    """The law keeps b > a from an obstacle's surface: a silent neighbour's obstacle is its
    disc less a, so the law's path stays outside the governor's disc and the robot does not
    wait at its edge; at least a/2, and a/2 on a robot that brakes at once (there the disc
    is metres for a neighbour silent a moment)."""
    disc = dict(a=1.0, top_speed=3.0, staleness=0.5, stop_time=0.12)
    full, _ = neighbour_hazard(1.5, 0.2, 0.8, 0.0, model(accel=2.0, **disc))
    assert silent_radius(1.5, 0.2, model(accel=2.0, **disc)) == pytest.approx(full - 1.0)
    assert full - 1.0 > 2.0
    assert silent_radius(1.5, 0.2, model(accel=math.inf, **disc)) == 0.5
    assert silent_radius(0.0, 0.0, model(a=4.0, accel=50.0, top_speed=0.1, staleness=0.5,
                                         stop_time=0.0)) == 2.0   # a/2 floor


def dead_path(state: tuple[float, float, float, float, float], base: float, accel: float,
              hold: float, dt: float = 1e-4) -> list[tuple[float, float]]:
    """The batch plant's dead robot (firmware_sim.swarm_step.advance) from ``state`` (x, y
    [m], heading [rad], right and left wheel ground speeds [m/s]): its drivers hold the
    wheels for ``hold`` s, then ramp each to rest at ``accel``. Its centre's positions [m],
    the last at rest."""
    x0, y0, th0, right, left = state
    v, u = 0.5 * (right + left), (right - left) / base
    out = [arc_step(x0, y0, th0, v * hold * k / 63, u * hold * k / 63)   # held: an arc
           for k in range(64)]
    x, y, th = out[-1]
    while right != 0.0 or left != 0.0:                      # each wheel ramps to rest
        r0, l0 = right, left
        right = _toward(right, 0.0, accel * dt)
        left = _toward(left, 0.0, accel * dt)
        vr, vl = 0.5 * (r0 + right), 0.5 * (l0 + left)   # exact unless a wheel stops mid-step
        x, y, th = arc_step(x, y, th, 0.5 * (vr + vl) * dt, (vr - vl) / base * dt)
        out.append((x, y, th))
    return [(px, py) for px, py, _ in out]


def dead_robot_path(v, u, base, accel, hold, dt=1e-4):
    """The farthest [m] the centre of a dead robot last commanding (v, u) gets from where it
    started (:func:`dead_path`)."""
    state = (0.0, 0.0, 0.0, v + 0.5 * u * base, v - 0.5 * u * base)
    return max(math.hypot(x, y) for x, y in dead_path(state, base, accel, hold, dt))


def test_a_dead_spinning_robot_travels_farther_than_its_reported_speed_says():
    """Robot 3 of the grid scenario with the cart, killed at 24 s: reported at -0.63 m/s
    spinning at 3.83 rad/s, its wheels ramp to rest unevenly (the right one stops first,
    the left one then drags it on) and its centre ends 0.46 m away; its speed alone allowed
    0.18 m, and a robot kept out of that disc came within 0.85 m of it."""
    v, u, base, accel = -0.63, 3.826, 0.8, 2.0
    far = dead_robot_path(v, u, base, accel, STOP)
    assert far > stopping(abs(v), accel, STOP) + 0.2
    full, half = neighbour_hazard(v, 0.5 * u * base, 5.0, 0.0,
                                  model(a=A, accel=accel, top_speed=TOP, staleness=STALE,
                                        stop_time=STOP))
    assert half == -math.inf and full - A >= far


@settings(max_examples=200, deadline=None)
@given(v=st.floats(-3.0, 3.0), u=st.floats(-6.0, 6.0), base=st.floats(0.2, 1.0),
       accel=st.floats(0.5, 10.0), hold=st.floats(0.0, 0.2))
def test_a_silent_neighbour_s_disc_holds_however_its_wheels_brake(v, u, base, accel, hold):
    """Whatever it was doing when its agent died, a silent neighbour's centre stays in the
    disc the governor keeps out of (less a), its wheels braking each on its own."""
    full, _ = neighbour_hazard(v, 0.5 * u * base, 5.0, 0.0,
                               model(a=A, accel=accel, top_speed=TOP, staleness=STALE,
                                     stop_time=hold))
    assert dead_robot_path(v, u, base, accel, hold, dt=1e-3) <= full - A + 1e-3


@settings(max_examples=300, deadline=None)
@given(v=st.floats(0.0, 3.0), w=st.floats(0.0, 3.0), now=st.floats(0.0, 3.0),
       apart=st.floats(0.0, 6.0), accel=st.floats(0.5, 30.0), hold=st.floats(0.0, 0.2))
def test_the_longest_stop_within_the_wheels_limit_is_at_the_fastest_speed(v, w, now, apart,
                                                                           accel, hold):
    """Any speed v <= now with wheels w <= apart apart, each wheel within 3 m/s
    (v + w <= 3), stops within the path neighbour_hazard counts: at ``now``, the wheels as
    far apart as the limit leaves them."""
    wheel_top = 3.0
    v, w = min(v, now), min(w, apart)
    if v + w > wheel_top:
        w = wheel_top - v
    assert stopping(v, accel, hold, w) <= stopping(
        now, accel, hold, min(apart, wheel_top - now)) + 1e-9


def test_the_wheels_limit_shrinks_a_silent_neighbour_s_disc():
    """A sporty robot (8 m/s, 25 m/s^2) silent after reporting 6.4 m/s: within 0.5 s its
    wheels could be 12.5 m/s further apart, but not beyond their 8 m/s limit, so it stops
    as from 8 m/s straight, not spinning."""
    accel, top, stop = 25.0, 8.0, 0.13
    args = (6.4, 0.3, 5.0, 0.0)
    sporty = dict(a=A, accel=accel, top_speed=top, staleness=STALE, stop_time=stop)
    free, _ = neighbour_hazard(*args, model(**sporty))
    held, _ = neighbour_hazard(*args, model(**sporty, wheel_top=top))
    travel = min(top * STALE, 6.4 * STALE + 0.5 * accel * STALE ** 2)
    assert held == pytest.approx(A + travel + stopping(top, accel, stop))
    assert free - held > 2.0


@settings(max_examples=200, deadline=None)
@given(speed=st.floats(0.0, 3.0), turn_rate=st.floats(-2.0, 2.0), age=st.floats(0.0, 0.6),
       path=st.lists(st.sampled_from([0.0, 0.1, 0.25]), min_size=SPLITS, max_size=SPLITS),
       up=st.floats(0.2, 2.0))
def test_the_pairing_takes_the_largest_of_all_splits(speed, turn_rate, age, path, up):
    """The discs are the largest over the splits of the age, each split's reach to its end
    paired with this robot's path from its start: the same, bit for bit, as pairing each
    split alone (the splits a later one dominates, with the same path, are skipped, and so
    are the shares of a split whose sum cannot beat the largest so far); rho is the last
    split's, the whole age's."""
    paths = [sum(path[k:]) for k in range(SPLITS)]     # the path since each split's start
    trail = splits_of((paths, paths[1:] + [0.0], paths, [0.0] * SPLITS,
                       paths[1:] + [0.0], [0.0] * SPLITS))   # straight along x
    sight = Sight(5.0, 1.0, 0.0, 4.5, 0.8, 0.6)
    m = model(a=A, accel=ACCEL, half_base=0.4, top_speed=TOP, lag=0.04)
    got = _paired(trail, age, speed, turn_rate, up, up, m, sight)
    alone = [_paired(Splits(*([row[k]] for row in trail)), age * (k + 1) / SPLITS, speed,
                     turn_rate, up, up, m, sight) for k in range(SPLITS)]
    assert got == (max(r[0] for r in alone), max(r[1] for r in alone), alone[-1][2])


@settings(max_examples=200, deadline=None)
@given(speed=st.floats(0.0, 3.0), turn_rate=st.floats(-2.0, 2.0), age=st.floats(0.0, 0.02),
       moved=st.floats(0.0, 0.06), angle=st.floats(-math.pi, math.pi),
       up=st.floats(0.2, 2.0))
def test_data_younger_than_a_period_pairs_one_motion(speed, turn_rate, age, moved, angle,
                                                     up):
    """Data younger than the robot's period: every split of its age starts after the last
    recorded position and ends at the newest, so the robot moved as much over each; the
    last split, with the latest end, gives the discs, bit for bit as pairing each alone."""
    east, north = moved * math.cos(angle), moved * math.sin(angle)
    trail = splits_of(([moved] * SPLITS, [0.0] * SPLITS, [east] * SPLITS,
                       [north] * SPLITS, [0.0] * SPLITS, [0.0] * SPLITS))
    sight = Sight(3.0, 0.6, 0.8, 2.9, 0.8, 0.6)
    m = model(a=A, accel=ACCEL, half_base=0.4, top_speed=TOP, lag=0.04)
    got = _paired(trail, age, speed, turn_rate, up, up, m, sight)
    alone = [_paired(Splits(*([row[k]] for row in trail)), age * (k + 1) / SPLITS, speed,
                     turn_rate, up, up, m, sight) for k in range(SPLITS)]
    assert got == (max(r[0] for r in alone), max(r[1] for r in alone), alone[-1][2])


def test_a_split_is_skipped_only_where_its_sum_cannot_round_above_the_largest():
    """A split's shares are skipped when a + its travel + its path cannot beat the largest
    sum so far; that bound is summed as the term it stands for. Summed the other way round
    it came out an ulp lower than this split's term, whose share is its whole path (this
    robot 5 cm from the report), and the disc lost that ulp."""
    p0, p3 = 0.7054340045891819, 0.10543400458918173
    paths, inner = [p0, p3, p3, p3], [p3, p3, p3, 0.0]
    trail = splits_of((paths, inner, paths, [0.0] * SPLITS, inner, [0.0] * SPLITS))
    sight = Sight(0.05, -1.0, 0.0, 0.0, 1.0, 0.0)  # 5 cm behind the report, on its segment
    m = model(a=0.5, accel=2.0, half_base=0.4, top_speed=3.0, lag=0.04)
    args = (1.5, 5.0, 2.0, 2.0, m, sight)
    got = _paired(trail, 0.4, *args)
    alone = [_paired(Splits(*([row[k]] for row in trail)), 0.4 * (k + 1) / SPLITS, *args)
             for k in range(SPLITS)]
    assert got[:2] == (max(r[0] for r in alone), max(r[1] for r in alone))


@settings(max_examples=400, deadline=None)
@given(rel_x=st.floats(-6.0, 6.0), rel_y=st.floats(-6.0, 6.0),
       heading=st.floats(-math.pi, math.pi), speed=st.floats(-3.0, 3.0),
       turn_rate=st.floats(-2.0, 2.0), age=st.floats(0.0, 0.45), own=st.floats(0.0, 3.0),
       angle=st.floats(-math.pi, math.pi))
@example(rel_x=-4.0, rel_y=0.5, heading=0.0, speed=3.0, turn_rate=0.0, age=0.4, own=0.0,
         angle=0.0)                        # driving at this robot: the all-round bound counts
def test_the_claim_is_that_of_both_bounds_over_every_split(rel_x, rel_y, heading, speed,
                                                           turn_rate, age, own, angle):
    """neighbour_radii leaves the all-round bound out where even its least value leaves
    no more room than the capsule; its claim is, bit for bit, that of both bounds taken
    over every split."""
    trail = straight(own, math.cos(angle), math.sin(angle), age, SPLITS)
    speed_up, lag = 1.0, 0.04
    m = model(a=A, accel=ACCEL, half_base=0.4, top_speed=TOP, staleness=STALE, stop_time=STOP,
              wheel_top=3.5, speed_up=speed_up, lag=lag, turn_up=speed_up)
    hx, hy = math.cos(heading), math.sin(heading)
    _, _, off, seg_x, seg_y = _nearest_on_report(rel_x, rel_y, hx, hy, speed, age)
    dist = math.sqrt(rel_x * rel_x + rel_y * rel_y)
    far_x, far_y = seg_x - rel_x, seg_y - rel_y
    far = max(math.sqrt(far_x * far_x + far_y * far_y), 1e-9)
    near = max(dist, 1e-9)
    sight = Sight(dist, -rel_x / near, -rel_y / near, off, far_x / far, far_y / far)
    around, reach, _ = _paired(trail, age, speed, turn_rate, speed_up, speed_up, m, sight)
    within, beyond = dist - around, off - reach
    want = off - (within if within > beyond else beyond)
    got = neighbour_radii(rel_x, rel_y, heading, speed, turn_rate, age, trail, m).claim
    assert got == want
    assert _grow(age, abs(speed), TOP, 0.5 * ACCEL, 0.5 * speed_up, ACCEL * lag,
                 ACCEL * lag * lag) + A <= around      # the least value the shortcut takes


@settings(max_examples=200, deadline=None)
@given(v=st.floats(0.0, 6.0), accel=st.floats(0.5, 25.0), age=st.floats(0.0, 3.0),
       later=st.floats(0.0, 3.0))
def test_a_neighbour_s_disc_never_shrinks_as_its_data_ages(v, accel, age, later):
    """Heard from, the shared disc only grows with the data's age; silent, the full disc is
    the one it has at the staleness limit, however old the data."""
    m = model(a=A, accel=accel, top_speed=TOP, staleness=STALE, stop_time=STOP)

    def disc(t):
        return neighbour_hazard(v, 0.0, t, 0.0, m)
    (full0, half0), (full1, half1) = disc(age), disc(age + later)
    if age + later <= STALE:
        assert full0 == full1 == -math.inf and half1 >= half0 - 1e-12
    elif age > STALE:
        assert half0 == half1 == -math.inf and full1 == full0 > A


@settings(max_examples=100, deadline=None)
@given(v=st.floats(0.0, 6.0), accel=st.floats(0.5, 25.0), died=st.floats(0.0, 1.0))
def test_a_silent_neighbour_that_died_late_in_its_silence_stays_in_its_disc(v, accel, died):
    """Reported moving straight at v, it drove on at up to its top speed until it died
    ``died`` x the staleness limit after the report, then its drivers stopped it: its
    centre ends inside the silent disc (less a)."""
    v = min(v, TOP)
    drive = died * STALE
    top_at = max(TOP - v, 0.0) / accel                    # s to reach the top speed
    t1 = min(drive, top_at)
    path = v * t1 + 0.5 * accel * t1 * t1 + TOP * max(drive - top_at, 0.0)
    speed = min(v + accel * drive, TOP)
    path += stopping(speed, accel, STOP)
    full, half = neighbour_hazard(v, 0.0, 10.0, 0.0,
                                  model(a=A, accel=accel, top_speed=TOP, staleness=STALE,
                                        stop_time=STOP))
    assert half == -math.inf and path <= full - A + 1e-9


@settings(max_examples=1000, deadline=None)
@given(nb=neighbour, profile=st.sampled_from([(2.0, 0.4, 3.0, 2.0, 1.5),
                                              (25.0, 0.2, 8.0, 2.0, 2.0),
                                              (math.inf, 0.4, 3.0, math.inf, math.inf)]))
def test_the_floor_bounds_every_disc_a_neighbour_can_get(nb, profile):
    """neighbour_floor is at most the free distance this robot owns toward the disc
    neighbour_radii gives (round its claim, or the stop strip behind the neighbour), as
    the governor measures it from the disc's centre (agent.governor.fold_hazard), and its
    top at least the claim."""
    rel_x, rel_y, heading, speed, turn, age, pieces, bend = nb
    accel, half_base, top_speed, speed_up, turn_up = profile
    trail = walk(pieces, bend)
    m = model(a=A, accel=accel, half_base=half_base, top_speed=top_speed, staleness=STALE,
              stop_time=STOP, wheel_top=top_speed, speed_up=speed_up, lag=0.04,
              turn_up=turn_up)
    full, half, east, north, claim = neighbour_radii(rel_x, rel_y, heading, speed, turn, age,
                                                     trail, m)
    floor, top = neighbour_floor(rel_x, rel_y, speed, age, trail.walked[0], m)
    dx, dy = east - rel_x, north - rel_y       # the disc's centre from this robot
    d = math.sqrt(dx * dx + dy * dy)
    assert floor <= min(d - full, 0.5 * (d - half))
    assert claim <= top
