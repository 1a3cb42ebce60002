"""The bounded formation control law of Nguyen & La, with this project's additions: the one
law, written once, in the stages of docs/controller.md section 5.

Every period the robot picks one of the paper's three modes, each a stage below:

* :func:`track` (Theorem 1): follow the reference p_d. e = p - p_d, theta_d = atan2(-e),
  u = -K_theta e_theta + theta_d_hat_dot, v = K cos(e_theta) min(D_max, |e|); the error
  is remembered for the feed-forward's finite difference (A2). On a robot with a braking
  deceleration it follows the reference's velocity, closing in no faster than it can
  arrive (A12, A16).
* :func:`avoid` (Theorem 2), when a pair with a neighbour is active (A3, hysteresis) or an
  obstacle surface is closer than b: descend the potential sum V = K_ij ln cosh(r - c) of
  the active neighbours and obstacle virtual agents, with any component toward a neighbour
  or obstacle closer than b removed (A6).
* :func:`rotate`, when not avoiding and an obstacle within c blocks the straight path to
  the reference, or while a circulation side is latched: the obstacle's tangent on the
  side facing the reference (A4), with the corner rule (A5).

Then TRACK passes a neighbour in the way (:func:`pass_in_the_way`, A13), the speed and the
turn are set (:func:`speed`, A12 and A16; :func:`turn`, A15 and A1), the safety governor
lowers |v| only as far as needed for the robot to stop before every hazard
(:func:`govern`, A10 and A14; the limits come from agent.governor), and the command is
brought within what the wheel drivers can follow (:func:`to_wheels`, section 6 and A17).
Nothing after the law clips it.

The law is pure, for one robot, in plain floats: an agent runs it interpreted every period,
and the batch simulator compiles this same source with numba (:mod:`firmware_sim.compiled`).
So it uses only floats, ints, NamedTuples and indexable sequences of floats (lists in an
agent, arrays when compiled), and ``math.sqrt`` for lengths. Metres, radians, world frame
ENU.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

from agent.avoidance import (
    EPS,
    HALF_PI,
    Surroundings,
    clearance,
    corner_takeover,
    remove_toward,
    segment_distance,
    tangent_side,
    way_closed,
)
from agent.braking import braking_speed
from agent.governor import Limits, turn_limit
from agent.kinematics import TWO_PI, body_velocity, wheel_command, wrap_angle
from common.vocabulary import Mode

if TYPE_CHECKING:
    from agent.params import LawParams

TRACK, AVOID, ROTATE = int(Mode.TRACK), int(Mode.AVOID), int(Mode.ROTATE)


class Reference(NamedTuple):
    """The robot's reference p_d(t) [m] and its velocity p_d_dot(t) [m/s]."""

    x: float
    y: float
    vx: float
    vy: float


class LawMemory(NamedTuple):
    """One robot's mode memory, carried from one period to the next."""

    prev_ex: float = 0.0        # m, e(t - T), valid when has_prev
    prev_ey: float = 0.0        # m
    has_prev: bool = False      # False before the first step
    avoiding: bool = False      # in neighbour-AVOID (hysteresis)
    side: int = 0               # latched circulation side (+1, -1) or 0
    center_x: float = 0.0       # m, centre of the obstacle being circled
    center_y: float = 0.0       # m
    radius: float = 0.0         # m
    wheel_r: float = 0.0        # rev/s, the right wheel's last set-point
    wheel_l: float = 0.0        # rev/s, the left wheel's
    passing: int = 0            # side a neighbour in the way is passed on (A13): -1 its
                                # right, +1 its left, 0 none in the way


class Aim(NamedTuple):
    """Where the robot heads in a period, as the stages refine it."""

    theta_d: float      # rad, the heading to take
    length: float       # m, what sets the speed: |e|, or the descent's length in AVOID
    ff: float           # rad/s, the heading rate's feed-forward
    mode: int           # TRACK, AVOID or ROTATE
    follow: float       # m/s, the speed of the velocity to follow (A16)


class Latch(NamedTuple):
    """ROTATE's latched circulation (A4): the side and the obstacle followed."""

    side: int           # +1, -1, or 0: none
    center_x: float     # m
    center_y: float     # m
    radius: float       # m


class LawOut(NamedTuple):
    """One period's command and the memory carried to the next."""

    v: float            # m/s
    u: float            # rad/s
    right: float        # rev/s, the wheels' set-points (the memory's, with infinite limits)
    left: float         # rev/s
    mode: int           # a :class:`Mode` value
    governed: float     # m/s, the speed the governor allowed when it lowered the command
    #                     (inf: it did not)
    memory: LawMemory


def pair_active(d2: float, held: bool, b: float, hysteresis: float) -> bool:
    """Whether the pair with a neighbour at squared distance ``d2`` [m^2] is active (the
    neighbour is avoided): closer than ``b`` [m], or closer than b + ``hysteresis`` [m] while
    it was active in the last period (``held``), A3. The caller keeps ``held`` per
    neighbour, from this very function."""
    reach = b + hysteresis if held else b
    return d2 < reach * reach


def grown_by(now: float, change: float, up: float) -> float:
    """``change`` to a quantity at ``now``, its magnitude grown by at most ``up`` beyond
    |now| (toward zero at any rate, past zero by at most ``up``)."""
    new = now + change
    new = min(max(new, -up), now + up) if now >= 0.0 else min(max(new, now - up), up)
    return new - now


def moved_estimate(mem: LawMemory, dx: float, dy: float) -> LawMemory:
    """The memory after the robot's pose estimate moved by (dx, dy) [m] while the robot did
    not (a pose fix corrected it), or its reference by -(dx, dy) (a place exchange): the
    remembered error moves with it, so that the error's finite difference, and the
    heading-rate feed-forward taken from it, see motion only. Otherwise every fix's
    correction, divided by one period, becomes a heading rate: with 2 mm of fix noise,
    tenths of a rad/s."""
    return LawMemory(mem.prev_ex + dx, mem.prev_ey + dy, mem.has_prev, mem.avoiding, mem.side,
                     mem.center_x, mem.center_y, mem.radius, mem.wheel_r, mem.wheel_l,
                     mem.passing)     # field by field: compiled too (firmware_sim.compiled)


def last_velocity(mem: LawMemory, p: LawParams) -> tuple[float, float]:
    """(v [m/s], u [rad/s]) of the robot's last command, its wheels' set-points in ``mem``."""
    return body_velocity(TWO_PI * mem.wheel_r, TWO_PI * mem.wheel_l, p.wheel_radius,
                         p.wheel_base)


def law_step(x: float, y: float, theta: float, ref: Reference, around: Surroundings,
             limits: Limits, mem: LawMemory, p: LawParams, dt: float) -> LawOut:
    """One period for one robot at (x, y, theta) [m, m, rad] with reference ``ref``, among
    ``around`` (neighbours in range, extrapolated to now, with the pairs active last period
    and their governor discs; obstacles in range), under the safety governor's ``limits``
    (agent.governor, in the frame of agent.governor.braking_of; read only with the
    governor on); ``dt`` [s] the time since the last step."""
    ex, ey = x - ref.x, y - ref.y
    D = math.sqrt(ex * ex + ey * ey)
    aim = track(ex, ey, D, ref, mem, p, dt)
    avoiding, avoid_now = avoid_active(x, y, around, mem, p)
    aim, latch = rotate(x, y, ref, around, mem, avoid_now, aim, p)
    if avoid_now:
        aim = avoid(x, y, theta, around, mem, p)
    aim, passing = pass_in_the_way(x, y, D, around, mem, aim, p)
    v, e_theta = speed(theta, ex, ey, D, ref, aim, p)
    u = turn(e_theta, aim.ff, p, dt)
    v_now, _ = last_velocity(mem, p)
    v, u, governed = govern(v, u, limits, p, dt)
    fwd, bwd = (limits.fwd, limits.bwd) if p.governor else (math.inf, math.inf)
    v, u, right, left = to_wheels(v, u, v_now, fwd, bwd, mem, p, dt)
    return LawOut(v, u, right, left, aim.mode, governed,
                  LawMemory(ex, ey, True, avoiding, latch.side, latch.center_x,
                            latch.center_y, latch.radius, right, left, passing))


def track(ex: float, ey: float, D: float, ref: Reference, mem: LawMemory, p: LawParams,
          dt: float) -> Aim:
    """TRACK (Theorem 1) toward the reference, the error (``ex``, ``ey``) [m] of length
    ``D`` [m]: theta_d = atan2(-e), and the heading rate's feed-forward from the error's
    finite difference (A2, Assumption 2). On a robot with a finite braking deceleration it
    follows the reference's velocity plus a closing speed of at most sqrt(accel |e|), w =
    p_d_dot - min(K min(D_max, |e|), sqrt(accel |e|)) e/|e|, theta_d = atan2(w), at
    min(|w|, K D_max) (A16, A12); theta_d is not the error's bearing then, so its rate is
    no feed-forward."""
    px, py = (mem.prev_ex, mem.prev_ey) if mem.has_prev else (ex, ey)
    edx, edy = (ex - px) / dt, (ey - py) / dt
    ff = (ex * edy - ey * edx) / max(D * D, EPS) if D > EPS else 0.0
    theta_d = math.atan2(-ey, -ex)
    follow = 0.0
    if not math.isinf(p.accel):
        close = min(p.K * min(p.D_max, D), math.sqrt(p.accel * D)) / D if D > EPS else 0.0
        wx, wy = ref.vx - close * ex, ref.vy - close * ey
        follow, ff = min(math.sqrt(wx * wx + wy * wy), p.K * p.D_max), 0.0
        if follow > EPS:
            theta_d = math.atan2(wy, wx)
    return Aim(theta_d, D, ff, TRACK, follow)


def avoid_active(x: float, y: float, around: Surroundings, mem: LawMemory, p: LawParams
                 ) -> tuple[bool, bool]:
    """(a pair with a neighbour is active, AVOID): the AVOID decision (Theorem 2), with
    hysteresis on the neighbour part (A3: per pair, or with ``pair_hysteresis`` off per
    robot: every neighbour within b + hysteresis while the robot avoided one), or an
    obstacle surface closer than b."""
    avoiding = False
    for j in range(around.n_nbr):
        dx, dy = around.nbr_x[j] - x, around.nbr_y[j] - y
        held = around.nbr_held[j] > 0.5 if p.pair_hysteresis else mem.avoiding
        if pair_active(dx * dx + dy * dy, held, p.b, p.hysteresis):
            avoiding = True
    obs_near = False
    for k in range(around.n_obs):
        if clearance(x, y, around.obs_x[k], around.obs_y[k], around.obs_r[k]) < p.b:
            obs_near = True
    return avoiding, avoiding or obs_near


def rotate(x: float, y: float, ref: Reference, around: Surroundings, mem: LawMemory,
           avoid_now: bool, aim: Aim, p: LawParams) -> tuple[Aim, Latch]:
    """ROTATE when an obstacle is in sight (A4, A5): keep a latched side while its obstacle
    is in sight and the path is not clear of every obstacle within 2c; latch a new side,
    when not in AVOID, on the nearest obstacle within c that blocks the straight path to
    the reference (the segment passes within b of its surface), on the side facing the
    reference. While rotating, the corner rule hands over to a neighbouring obstacle that
    turns the robot further out (A5), and an obstacle on the other side, less than 2b
    from the followed one, closes the way and flips the side; theta_d is the followed
    obstacle's tangent on the side, without feed-forward. A robot that senses no obstacle
    drops its latch."""
    latch = Latch(0, mem.center_x, mem.center_y, mem.radius)
    if around.n_obs == 0:
        return aim, latch
    obs_x, obs_y, obs_r = around.obs_x, around.obs_y, around.obs_r
    sx, sy = ref.x - x, ref.y - y                       # segment robot -> reference
    clear_2c = True
    nearest_blocking, best = -1, math.inf
    followed, match = 0, math.inf
    for k in range(around.n_obs):
        clear = clearance(x, y, obs_x[k], obs_y[k], obs_r[k])
        on_path = segment_distance(sx, sy, obs_x[k] - x, obs_y[k] - y) < obs_r[k] + p.b
        if on_path and clear < 2.0 * p.c:
            clear_2c = False
        if on_path and clear < p.c and clear < best:
            nearest_blocking, best = k, clear
        mx, my = obs_x[k] - mem.center_x, obs_y[k] - mem.center_y
        off = math.sqrt(mx * mx + my * my)
        if off < match:
            followed, match = k, off
    # keep a latched side while its obstacle is in sight and the path is not clear
    in_sight = match <= max(mem.radius, EPS)
    side = 0 if clear_2c or not in_sight else mem.side
    # latch a new side on the obstacle that blocks the path
    if side == 0 and not avoid_now and nearest_blocking >= 0:
        followed = nearest_blocking
        side = tangent_side(math.atan2(obs_y[followed] - y, obs_x[followed] - x),
                            math.atan2(ref.y - y, ref.x - x))
    rotating = not avoid_now and side != 0
    if rotating:
        followed = corner_takeover(followed, side, x, y, around, p.b, p.c)
        if way_closed(followed, side, x, y, around, p.b, p.c):
            side = -side                    # round the other side of the obstacle
    if side != 0:
        latch = Latch(side, obs_x[followed], obs_y[followed], obs_r[followed])
    if rotating:
        theta_d = math.atan2(obs_y[followed] - y, obs_x[followed] - x) + side * HALF_PI
        aim = Aim(theta_d, aim.length, 0.0, ROTATE, aim.follow)
    return aim, latch


def avoid(x: float, y: float, theta: float, around: Surroundings, mem: LawMemory,
          p: LawParams) -> Aim:
    """AVOID (Theorem 2): descend the potential, never toward a close obstacle or
    neighbour (A6). g, the gradient of the potential sum, points toward the active
    neighbours and away from the obstacles closer than b (their virtual agents); the
    robot heads along -g less its components toward each neighbour and obstacle closer
    than b, at a speed set by that direction's length, without feed-forward. A neighbour
    on the robot pushes it back along its heading."""
    gx = gy = same = 0.0
    for j in range(around.n_nbr):
        dx, dy = around.nbr_x[j] - x, around.nbr_y[j] - y
        d2 = dx * dx + dy * dy
        held = around.nbr_held[j] > 0.5 if p.pair_hysteresis else mem.avoiding
        if pair_active(d2, held, p.b, p.hysteresis):
            d = math.sqrt(d2)
            w = p.K_ij * math.tanh(d - p.c)
            if d >= EPS:
                gx, gy = gx - w * (dx / d), gy - w * (dy / d)
            else:
                same += w
    obs_x, obs_y, obs_r = around.obs_x, around.obs_y, around.obs_r
    for k in range(around.n_obs):
        clear = clearance(x, y, obs_x[k], obs_y[k], obs_r[k])
        if clear < p.b:
            dx, dy = x - obs_x[k], y - obs_y[k]
            d = max(math.sqrt(dx * dx + dy * dy), EPS)
            w = p.K_ij * math.tanh(max(clear, 0.0) - p.c)
            gx, gy = gx + w * (dx / d), gy + w * (dy / d)
    if same != 0.0:                 # a neighbour on the robot: pushed back along theta
        gx, gy = gx - same * math.cos(theta), gy - same * math.sin(theta)
    dx, dy = -gx, -gy
    for j in range(around.n_nbr):
        tx, ty = around.nbr_x[j] - x, around.nbr_y[j] - y
        d = math.sqrt(tx * tx + ty * ty)
        if d < p.b and d >= EPS:
            dx, dy = remove_toward(dx, dy, tx / d, ty / d)
    for k in range(around.n_obs):
        if clearance(x, y, obs_x[k], obs_y[k], obs_r[k]) < p.b:
            tx, ty = obs_x[k] - x, obs_y[k] - y
            d = max(math.sqrt(tx * tx + ty * ty), EPS)
            dx, dy = remove_toward(dx, dy, tx / d, ty / d)
    return Aim(math.atan2(dy, dx), math.sqrt(dx * dx + dy * dy), 0.0, AVOID, 0.0)


def pass_in_the_way(x: float, y: float, D: float, around: Surroundings, mem: LawMemory,
                    aim: Aim, p: LawParams) -> tuple[Aim, int]:
    """(aim, side) in TRACK with ``sidestep`` (A13): pass the nearest neighbour in the way
    b + hysteresis off its governor's disc, on its right; on its left, the shorter way,
    when the right leads toward another neighbour within that and the left into no
    neighbour's cone, and then on the left until no neighbour is in the way. The side: -1
    its right, +1 its left, 0 none in the way (``D`` [m] the distance to the reference)."""
    if aim.mode != TRACK or not p.sidestep:
        return aim, 0
    passing = p.b + p.hysteresis
    j_in, phi_in, cone_in = in_the_way(aim.theta_d, x, y, around, -1, passing, p.c, D)
    if j_in < 0:
        return aim, 0
    side = 1 if mem.passing > 0 or (
        wrap_angle(aim.theta_d - phi_in) > 0.0
        and in_the_way(phi_in - cone_in, x, y, around, j_in, passing, passing,
                       math.inf)[0] >= 0
        and in_the_way(phi_in + cone_in, x, y, around, j_in, passing, p.c, D)[0] < 0
    ) else -1
    return Aim(phi_in + side * cone_in, aim.length, 0.0, aim.mode, aim.follow), side


def speed(theta: float, ex: float, ey: float, D: float, ref: Reference, aim: Aim,
          p: LawParams) -> tuple[float, float]:
    """(v [m/s], e_theta [rad]): v = K cos(e_theta) min(D_max, length). On a robot with a
    finite braking deceleration, in TRACK the speed of the velocity to follow (A16); in
    ROTATE no faster toward the reference than the robot can shed at half its braking
    deceleration (A12: arrive, do not overshoot; the other half is left for turning)."""
    dist = aim.length
    v_set = p.K * min(p.D_max, dist)
    if aim.mode == TRACK and not math.isinf(p.accel):
        dist = v_set = aim.follow       # heading and speed of the velocity to follow (A16)
    elif aim.mode != AVOID and not math.isinf(p.accel):
        away = -(ref.vx * ex + ref.vy * ey) / D if D > EPS else 0.0   # m/s, p_d_dot along -e
        v_set = max(min(v_set, away + math.sqrt(p.accel * D)), 0.0)
    e_theta = 0.0 if dist < EPS else wrap_angle(theta - aim.theta_d)
    return math.cos(e_theta) * v_set, e_theta


def turn(e_theta: float, ff: float, p: LawParams, dt: float) -> float:
    """u [rad/s] = -K_theta e_theta + feed-forward, clipped to u_max (A1). On a robot with a
    finite braking deceleration the heading loop turns no faster than lets the robot stop
    turning within e_theta at half its ramp (each wheel's share accel / 2, so du/dt =
    accel / wheel_base) after a period and the drive latency (A15: arrive on the heading,
    do not overshoot)."""
    u = -p.K_theta * e_theta
    if not math.isinf(p.accel):
        cap = braking_speed(abs(e_theta), p.accel / p.wheel_base, dt + p.latency)
        u = min(max(u, -cap), cap)
    return min(max(u + ff, -p.u_max), p.u_max)


def govern(v: float, u: float, limits: Limits, p: LawParams, dt: float
           ) -> tuple[float, float, float]:
    """(v, u, governed): the safety governor (A10) lowers |v| to its limit the way the robot
    goes, and |u| to what the room for the drift of slipping wheels allows (A14); governed
    is the limit [m/s] where it lowered |v| below the wheels' own top speed, else inf."""
    top = TWO_PI * p.wheel_radius * p.speed_limit      # the wheels' own limit [m/s]
    fwd = bwd = math.inf
    if p.governor:
        fwd, bwd, room = limits
        u_cap = turn_limit(room, p.slip, p.accel, max(dt, p.watchdog) + p.latency,
                           p.wheel_base)
        u = min(max(u, -u_cap), u_cap)
    allowed = fwd if v >= 0.0 else bwd
    governed = allowed if abs(v) > allowed and allowed < top else math.inf
    return min(max(v, -bwd), fwd), u, governed


def to_wheels(v: float, u: float, v_now: float, fwd: float, bwd: float, mem: LawMemory,
              p: LawParams, dt: float) -> tuple[float, float, float, float]:
    """(v, u, right, left): what the wheels can follow (section 6): their speed limit
    (curvature kept), then their ramp from the last set-points in ``mem``. While the robot
    goes faster than the governor allows (``v_now`` [m/s], its last command, beyond the
    limits ``fwd``, ``bwd``), slowing down takes the ramp first (the governor counts on
    braking at the full ramp) and turning gets what is left; otherwise turning comes
    first, as the law slows down by itself while the heading is off (v ~ cos e_theta).
    Speeding up (|v| or the wheels' half difference) is slower than the ramp where the
    profile says so, as the neighbours count on (A17); slowing down keeps the full ramp.
    With infinite limits (an ideal robot) (v, u) stand and the set-points stay."""
    wr, wl = mem.wheel_r, mem.wheel_l
    if math.isinf(p.speed_limit) and math.isinf(p.ramp):
        return v, u, wr, wl
    tr, tl = wheel_command(v, u, p.wheel_radius, p.wheel_base, p.speed_limit)
    change = p.ramp * dt
    want_common, want_turn = 0.5 * (tr + tl - wr - wl), 0.5 * (tr - tl - wr + wl)
    if -bwd <= v_now <= fwd:
        spin = min(max(want_turn, -change), change)
        left = change - abs(spin)
        common = min(max(want_common, -left), left)
    else:
        common = min(max(want_common, -change), change)
        left = change - abs(common)
        spin = min(max(want_turn, -left), left)
    if p.turn_up < p.accel:
        # speeding up (|v| or the wheels' half difference) slower than the ramp, as the
        # neighbours count on (A17); slowing down keeps the full ramp
        up = p.speed_up * dt / (TWO_PI * p.wheel_radius)     # rev/s per period
        common = grown_by(0.5 * (wr + wl), common, up)
        spin = grown_by(0.5 * (wr - wl), spin, p.turn_up * dt / (TWO_PI * p.wheel_radius))
    wr, wl = wr + common + spin, wl + common - spin
    # within the speed limit (a set-point already at it may not step beyond)
    wr = min(max(wr, -p.speed_limit), p.speed_limit)
    wl = min(max(wl, -p.speed_limit), p.speed_limit)
    v, u = body_velocity(TWO_PI * wr, TWO_PI * wl, p.wheel_radius, p.wheel_base)
    return v, u, wr, wl


def may_pass(d: float, grow: float, p: LawParams) -> bool:
    """Whether TRACK can pass (A13) a neighbour ``d`` [m] away whose governor disc is at
    most ``grow`` [m] wider than a: :func:`in_the_way`, as :func:`pass_in_the_way` calls it,
    leaves out every neighbour farther than the widest of its reaches plus the growth. A
    caller need not compute the disc of a neighbour it cannot pass."""
    return p.sidestep and d < max(p.c, p.b + p.hysteresis) + grow


def in_the_way(heading: float, x: float, y: float, around: Surroundings, skip: int,
               passing: float, within: float, limit: float) -> tuple[int, float, float]:
    """(index, bearing [rad], half-width [rad]) of the cone of passing (A13) of the
    neighbour in the way of ``heading`` [rad] from (x, y) [m], or index -1 when none is.
    A neighbour grown by its governor's disc's width beyond a is in the way when it is
    nearer than ``within`` + its growth and than ``limit`` [m], and its cone holds the
    heading: the bearings within asin(P / d) of the one to it, P = ``passing`` + its
    growth, or all within 90 degrees of it nearer than P. The nearest surface of such
    discs counts; neighbour ``skip`` (the one being passed; -1: none) is left out. The cone
    is tested with the heading's projection, no angle per neighbour."""
    nearest, j_in, reach_in = math.inf, -1, 0.0
    hx, hy = math.cos(heading), math.sin(heading)
    nbr_x, nbr_y, nbr_grow = around.nbr_x, around.nbr_y, around.nbr_grow
    for j in range(around.n_nbr):
        if j == skip:
            continue
        dx, dy = nbr_x[j] - x, nbr_y[j] - y
        d = math.sqrt(dx * dx + dy * dy)
        # min and max as conditional expressions: the same, cheaper interpreted
        grow = nbr_grow[j]
        grow = 0.0 if 0.0 > grow else grow
        bound = within + grow
        bound = limit if limit < bound else bound
        if EPS < d < bound and d - grow < nearest:
            reach = passing + grow
            along = dx * hx + dy * hy          # m, d times the cosine of the bearing's angle
            # within asin(reach / d) of the bearing: cos^2 > 1 - (reach / d)^2
            if along > 0.0 and (d <= reach or along * along > d * d - reach * reach):
                nearest, j_in, reach_in = d - grow, j, reach
    if j_in < 0:
        return -1, 0.0, 0.0
    dx, dy = nbr_x[j_in] - x, nbr_y[j_in] - y
    d = math.sqrt(dx * dx + dy * dy)
    cone = HALF_PI if d <= reach_in else math.asin(reach_in / d)
    return j_in, math.atan2(dy, dx), cone
