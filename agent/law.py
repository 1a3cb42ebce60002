"""The bounded formation control law of Nguyen & La, with this project's additions: the one
law, written once (docs/controller.md is its specification).

Every period the robot picks one of three modes:

* AVOID (Theorem 2) when a pair with a neighbour is active or an obstacle surface is closer
  than b. A pair becomes active closer than b and stays active until it is farther than b +
  hysteresis (:func:`pair_active`; per pair, or with ``pair_hysteresis`` off per robot: every
  neighbour within b + hysteresis while the robot avoided one). The robot descends the
  potential sum V = K_ij ln cosh(r - c) of the active neighbours and obstacle virtual agents, with
  any component toward a neighbour or obstacle closer than b removed:
  theta_d = atan2(-g), u = -K_theta e_theta, v = K cos(e_theta) min(D_max, |g|).
* ROTATE when not avoiding and an obstacle within c blocks the straight path to the
  reference (the segment passes within b of its surface), or while a circulation side is
  latched. Heading is the obstacle's tangent on the side facing the reference; the side is
  latched until the path is clear of every obstacle within 2c, and a corner rule hands over
  to a neighbouring obstacle that turns the robot further out; an obstacle on the other
  side, less than 2b from the followed one, closes the way and flips the side. Speed law
  as in TRACK.
* TRACK (Theorem 1) otherwise: e = p - p_d, theta_d = atan2(-e), u = -K_theta e_theta +
  theta_d_hat_dot, v = K cos(e_theta) min(D_max, |e|).

On a robot with a braking deceleration a_brake, TRACK and ROTATE close in on the reference
no faster than w + sqrt(a_brake |e|), w the reference's speed away from the robot (p_d_dot
along -e), so that it arrives instead of overshooting (the paper's K |e| asks for a
deceleration of K v). In TRACK it follows the reference's velocity plus that closing speed,
w = p_d_dot - min(K min(D_max, |e|), sqrt(a_brake |e|)) e/|e|, theta_d = atan2(w), speed
min(|w|, K D_max) (docs/controller.md A16), so it neither lags nor turns round when it
comes past.

On such a robot the heading loop also turns no faster than lets it stop turning within
e_theta at half its ramp (docs/controller.md A15). Then |u| is clipped to u_max (|v| <=
K D_max holds by construction), the safety governor
(:mod:`agent.governor`) lowers |v| only as far as needed for the robot to stop before every
hazard, and the command is brought within what the wheel drivers can follow: the wheel speed
limit (curvature kept) and the ramp from the last command. Nothing after the law clips it.

The law is pure, for one robot, in plain floats: an agent runs it interpreted every period
(numpy's cost per call would dominate for one robot), and the batch simulator compiles this
same source with numba and runs it for every robot (:mod:`firmware_sim.compiled`). So it
uses only floats, ints, NamedTuples and indexable sequences of floats (lists in an agent,
arrays when compiled), and ``math.sqrt`` for lengths. Metres, radians, world frame ENU.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

from agent.avoidance import (
    EPS,
    HALF_PI,
    clearance,
    corner_takeover,
    remove_toward,
    segment_distance,
    tangent_side,
    way_closed,
)
from agent.config import ControlParams, RobotParams
from agent.governor import braking_speed, limit_frame, slip_margin, turn_limit
from agent.kinematics import TWO_PI, body_velocity, wheel_command, wrap_angle
from common.vocabulary import Mode

if TYPE_CHECKING:
    from agent.avoidance import FloatSeq
    from agent.governor import Frame

TRACK, AVOID, ROTATE = int(Mode.TRACK), int(Mode.AVOID), int(Mode.ROTATE)


class LawParams(NamedTuple):
    """The gains and distances the law reads (from :class:`agent.config.ControlParams`)."""

    K: float            # 1/s
    K_theta: float      # 1/s
    D_max: float        # m
    K_ij: float         # 1
    b: float            # m
    c: float            # m
    u_max: float        # rad/s
    hysteresis: float   # m
    accel: float        # m/s^2, braking deceleration (inf: an ideal robot)
    speed_up: float     # m/s^2, the most the law speeds up |v|
    turn_up: float      # m/s^2, the most the law speeds up the wheels' half difference
    latency: float      # s, from a command to the drivers applying it
    wheel_radius: float  # m
    wheel_base: float   # m
    speed_limit: float  # rev/s per wheel (inf: none)
    ramp: float         # rev/s^2 per wheel (inf: none)
    watchdog: float     # s the drivers go on with the last command should the agent die
    slip: float         # 1, the wheels' slip the governor allows for (0: none)
    governor: bool      # the safety governor acts
    sidestep: bool      # TRACK passes a neighbour in the way on its right
    pair_hysteresis: bool   # AVOID's hysteresis per pair (else per robot)
    exchange: float     # m^2, the least gain of a place exchange (0: none; agent.exchange)

    @classmethod
    def of(cls, control: ControlParams, robot: RobotParams | None) -> "LawParams":
        """The law's view of the controller and of the robot (None: an ideal robot, whose
        wheels follow any command at once). ``law = "paper"`` turns the deadlock resolution
        off (sidestep, per-pair hysteresis and place exchange)."""
        inf = math.inf
        limits = ((robot.a_max, robot.a_up, robot.a_turn_up, robot.drive_latency,
                   robot.wheel_radius, robot.wheel_base, robot.wheel_speed_limit,
                   robot.wheel_ramp, robot.watchdog_timeout, robot.wheel_slip)
                  if robot is not None else (inf, inf, inf, 0.0, 1.0, 1.0, inf, inf, 0.0,
                                             0.0))
        resolve = control.law != "paper"
        return cls(control.K, control.K_theta, control.D_max, control.K_ij, control.b,
                   control.c, control.u_max, control.hysteresis, *limits, control.governor,
                   control.sidestep and resolve, control.pair_hysteresis and resolve,
                   control.exchange if resolve else 0.0)


def pair_active(d2: float, held: bool, b: float, hysteresis: float) -> bool:
    """Whether the pair with a neighbour at squared distance ``d2`` [m^2] is active (the
    neighbour is avoided): closer than ``b`` [m], or closer than b + ``hysteresis`` [m] while
    it was active in the last period (``held``). The caller keeps ``held`` per neighbour,
    from this very function, for :func:`law_step`'s ``nbr_held``."""
    reach = b + hysteresis if held else b
    return d2 < reach * reach


def grown_by(now: float, change: float, up: float) -> float:
    """``change`` to a quantity at ``now``, its magnitude grown by at most ``up`` beyond
    |now| (toward zero at any rate, past zero by at most ``up``)."""
    new = now + change
    new = min(max(new, -up), now + up) if now >= 0.0 else min(max(new, now - up), up)
    return new - now


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


def law_step(x: float, y: float, theta: float, ref_x: float, ref_y: float, ref_vx: float,
             ref_vy: float, nbr_x: FloatSeq, nbr_y: FloatSeq, nbr_held: FloatSeq,
             nbr_grow: FloatSeq, obs_x: FloatSeq, obs_y: FloatSeq,
             obs_r: FloatSeq, limits: tuple[float, float, float], mem: LawMemory,
             p: LawParams, dt: float) -> tuple[float, float, int, float, LawMemory]:
    """One period for one robot: (v [m/s], u [rad/s], mode (a :class:`Mode` value), the
    speed [m/s] the governor allowed when it lowered the command (inf: it did not), memory).

    (x, y, theta) is the robot's pose, (ref_x, ref_y) its reference p_d(t) and (ref_vx,
    ref_vy) [m/s] the reference's velocity p_d_dot(t); ``nbr_x``,
    ``nbr_y`` the neighbours in range (extrapolated to now) and ``nbr_held`` 1.0 for each
    whose pair was active in the last period (:func:`pair_active`), else 0.0, and
    ``nbr_grow`` [m] how much wider than a the governor's disc of each one's claim is
    (its half radius less a, below 0 taken as 0; 0 without the governor:
    agent.governor.neighbour_radii); ``obs_x``, ``obs_y``,
    ``obs_r``
    the obstacles in range (centre and radius); ``limits`` the safety governor's
    (forward, backward) speed limits [m/s] and room [m] among its hazards (agent.governor
    .frame_limits in the frame of :func:`governor_frame`; read only with the governor
    on); ``dt`` [s] the time since the last step.
    """
    # TRACK for everyone: error and its finite-difference heading rate (Assumption 2)
    ex, ey = x - ref_x, y - ref_y
    D = math.sqrt(ex * ex + ey * ey)
    px, py = (mem.prev_ex, mem.prev_ey) if mem.has_prev else (ex, ey)
    edx, edy = (ex - px) / dt, (ey - py) / dt
    ff = (ex * edy - ey * edx) / max(D * D, EPS) if D > EPS else 0.0
    theta_d = math.atan2(-ey, -ex)
    dist = D
    mode = TRACK
    follow = 0.0                        # m/s, the speed of the velocity to follow (A16)
    if not math.isinf(p.accel):
        # follow the reference's velocity, closing in on it as A12 allows (docs A16); theta_d
        # is not the error's bearing, so its rate is no feed-forward
        close = min(p.K * min(p.D_max, D), math.sqrt(p.accel * D)) / D if D > EPS else 0.0
        wx, wy = ref_vx - close * ex, ref_vy - close * ey
        follow, ff = min(math.sqrt(wx * wx + wy * wy), p.K * p.D_max), 0.0
        if follow > EPS:
            theta_d = math.atan2(wy, wx)

    # AVOID decision, with hysteresis on the neighbour part
    n_nbr, n_obs = len(nbr_x), len(obs_r)
    avoiding = False
    for j in range(n_nbr):
        dx, dy = nbr_x[j] - x, nbr_y[j] - y
        held = nbr_held[j] > 0.5 if p.pair_hysteresis else mem.avoiding
        if pair_active(dx * dx + dy * dy, held, p.b, p.hysteresis):
            avoiding = True
    obs_near = False
    for k in range(n_obs):
        if clearance(x, y, obs_x[k], obs_y[k], obs_r[k]) < p.b:
            obs_near = True
    avoid = avoiding or obs_near

    # ROTATE decision, when an obstacle is in sight
    side, center_x, center_y, radius = 0, mem.center_x, mem.center_y, mem.radius
    if n_obs > 0:
        sx, sy = ref_x - x, ref_y - y                       # segment robot -> reference
        clear_2c = True
        nearest_blocking, best = -1, math.inf
        followed, match = 0, math.inf
        for k in range(n_obs):
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
        if side == 0 and not avoid and nearest_blocking >= 0:
            followed = nearest_blocking
            side = tangent_side(math.atan2(obs_y[followed] - y, obs_x[followed] - x),
                                math.atan2(-ey, -ex))
        rotate = not avoid and side != 0
        if rotate:
            followed = corner_takeover(followed, side, x, y, obs_x, obs_y, obs_r, p.b, p.c)
            if way_closed(followed, side, x, y, obs_x, obs_y, obs_r, p.b, p.c):
                side = -side                    # round the other side of the obstacle
        if side != 0:
            center_x, center_y, radius = obs_x[followed], obs_y[followed], obs_r[followed]
        if rotate:
            theta_d = math.atan2(obs_y[followed] - y, obs_x[followed] - x) + side * HALF_PI
            mode = ROTATE
            ff = 0.0

    # AVOID: descend the potential, never toward a close obstacle or neighbour
    if avoid:
        # g = grad of the potential sum: toward active neighbours, away from obstacles
        gx = gy = same = 0.0
        for j in range(n_nbr):
            dx, dy = nbr_x[j] - x, nbr_y[j] - y
            d2 = dx * dx + dy * dy
            held = nbr_held[j] > 0.5 if p.pair_hysteresis else mem.avoiding
            if pair_active(d2, held, p.b, p.hysteresis):
                d = math.sqrt(d2)
                w = p.K_ij * math.tanh(d - p.c)
                if d >= EPS:
                    gx, gy = gx - w * (dx / d), gy - w * (dy / d)
                else:
                    same += w
        for k in range(n_obs):
            clear = clearance(x, y, obs_x[k], obs_y[k], obs_r[k])
            if clear < p.b:
                dx, dy = x - obs_x[k], y - obs_y[k]
                d = max(math.sqrt(dx * dx + dy * dy), EPS)
                w = p.K_ij * math.tanh(max(clear, 0.0) - p.c)
                gx, gy = gx + w * (dx / d), gy + w * (dy / d)
        if same != 0.0:                 # a neighbour on the robot: pushed back along theta
            gx, gy = gx - same * math.cos(theta), gy - same * math.sin(theta)
        dx, dy = -gx, -gy
        for j in range(n_nbr):
            tx, ty = nbr_x[j] - x, nbr_y[j] - y
            d = math.sqrt(tx * tx + ty * ty)
            if d < p.b and d >= EPS:
                dx, dy = remove_toward(dx, dy, tx / d, ty / d)
        for k in range(n_obs):
            if clearance(x, y, obs_x[k], obs_y[k], obs_r[k]) < p.b:
                tx, ty = obs_x[k] - x, obs_y[k] - y
                d = max(math.sqrt(tx * tx + ty * ty), EPS)
                dx, dy = remove_toward(dx, dy, tx / d, ty / d)
        theta_d = math.atan2(dy, dx)
        dist = math.sqrt(dx * dx + dy * dy)
        mode = AVOID
        ff = 0.0

    # TRACK: pass the nearest neighbour in the way b + hysteresis off its governor's disc,
    # on its right; on its left, the shorter way, when the right leads toward another
    # neighbour within that and the left into no neighbour's cone, and then on the left
    # until no neighbour is in the way (A13)
    passing_side = 0
    if mode == TRACK and p.sidestep:
        passing = p.b + p.hysteresis
        j_in, phi_in, cone_in = in_the_way(theta_d, x, y, nbr_x, nbr_y, nbr_grow, -1,
                                           passing, p.c, D)
        if j_in >= 0:
            passing_side = 1 if mem.passing > 0 or (
                wrap_angle(theta_d - phi_in) > 0.0
                and in_the_way(phi_in - cone_in, x, y, nbr_x, nbr_y, nbr_grow, j_in,
                               passing, passing, math.inf)[0] >= 0
                and in_the_way(phi_in + cone_in, x, y, nbr_x, nbr_y, nbr_grow, j_in,
                               passing, p.c, D)[0] < 0) else -1
            theta_d, ff = phi_in + passing_side * cone_in, 0.0

    speed = p.K * min(p.D_max, dist)
    if mode == TRACK and not math.isinf(p.accel):
        dist = speed = follow           # heading and speed of the velocity to follow (A16)
    elif mode != AVOID and not math.isinf(p.accel):
        # arrive, do not overshoot: close in on the reference no faster than the robot can
        # shed at half its braking deceleration (the other half is left for turning)
        away = -(ref_vx * ex + ref_vy * ey) / D if D > EPS else 0.0   # m/s, p_d_dot along -e
        speed = max(min(speed, away + math.sqrt(p.accel * D)), 0.0)
    e_theta = 0.0 if dist < EPS else wrap_angle(theta - theta_d)
    v = math.cos(e_theta) * speed
    turn = -p.K_theta * e_theta
    if not math.isinf(p.accel):
        # arrive on the heading, do not overshoot: turn no faster than the robot can stop
        # turning within e_theta, at half its ramp (each wheel's share accel / 2, so
        # du/dt = accel / wheel_base) after a period and the drive latency
        cap = braking_speed(abs(e_theta), p.accel / p.wheel_base, dt + p.latency)
        turn = min(max(turn, -cap), cap)
    u = min(max(turn + ff, -p.u_max), p.u_max)

    # the safety governor: no faster toward a hazard than lets the robot stop before it
    v_now, u_now = last_velocity(mem, p)
    top = TWO_PI * p.wheel_radius * p.speed_limit      # the wheels' own limit [m/s]
    fwd = bwd = math.inf
    if p.governor:
        fwd, bwd, room = limits
        u_cap = turn_limit(room, p.slip, p.accel, max(dt, p.watchdog) + p.latency,
                           p.wheel_base)
        u = min(max(u, -u_cap), u_cap)
    allowed = fwd if v >= 0.0 else bwd
    governed = allowed if abs(v) > allowed and allowed < top else math.inf
    v = min(max(v, -bwd), fwd)

    # what the wheels can follow: their speed limit, then their ramp from the last command.
    # While the robot goes faster than the governor allows, slowing down takes the ramp
    # first (the governor counts on braking at the full ramp) and turning gets what is left;
    # otherwise turning comes first, as the law slows down by itself while the heading is off
    # (v ~ cos e_theta)
    wr, wl = mem.wheel_r, mem.wheel_l
    if not (math.isinf(p.speed_limit) and math.isinf(p.ramp)):
        tr, tl = wheel_command(v, u, p.wheel_radius, p.wheel_base, p.speed_limit)
        change = p.ramp * dt
        want_common, want_turn = 0.5 * (tr + tl - wr - wl), 0.5 * (tr - tl - wr + wl)
        if -bwd <= v_now <= fwd:
            turn = min(max(want_turn, -change), change)
            left = change - abs(turn)
            common = min(max(want_common, -left), left)
        else:
            common = min(max(want_common, -change), change)
            left = change - abs(common)
            turn = min(max(want_turn, -left), left)
        if p.turn_up < p.accel:
            # speeding up (|v| or the wheels' half difference) slower than the ramp, as the
            # neighbours count on (A17); slowing down keeps the full ramp
            up = p.speed_up * dt / (TWO_PI * p.wheel_radius)     # rev/s per period
            common = grown_by(0.5 * (wr + wl), common, up)
            turn = grown_by(0.5 * (wr - wl), turn, p.turn_up * dt / (TWO_PI * p.wheel_radius))
        wr, wl = wr + common + turn, wl + common - turn
        # within the speed limit (a set-point already at it may not step beyond)
        wr = min(max(wr, -p.speed_limit), p.speed_limit)
        wl = min(max(wl, -p.speed_limit), p.speed_limit)
        v, u = body_velocity(TWO_PI * wr, TWO_PI * wl, p.wheel_radius, p.wheel_base)
    return v, u, mode, governed, LawMemory(ex, ey, True, avoiding, side, center_x, center_y,
                                           radius, wr, wl, passing_side)


def governor_frame(theta: float, v_now: float, u_now: float, p: LawParams, dt: float
                   ) -> Frame:
    """The frame (agent.governor.limit_frame) the safety governor measures its hazards in
    for the robot of :func:`law_step`, heading ``theta`` [rad] and moving at (``v_now``
    [m/s], ``u_now`` [rad/s]), its last command: a command held for a period ``dt`` [s],
    or the drivers' watchdog should the agent die, then the drive latency; its wheels'
    top speed; room kept for the drift of a turn on the spot on slipping wheels. The
    caller folds the hazards into it (agent.governor.fold_hazard) and hands law_step the
    limits (agent.governor.frame_limits)."""
    return limit_frame(theta, v_now, u_now, p.accel, max(dt, p.watchdog), p.latency, p.u_max,
                       p.wheel_base, TWO_PI * p.wheel_radius * p.speed_limit,
                       slip_margin(p.slip, p.wheel_base), p.turn_up)


def last_velocity(mem: LawMemory, p: LawParams) -> tuple[float, float]:
    """(v [m/s], u [rad/s]) of the robot's last command, its wheels' set-points in ``mem``."""
    return body_velocity(TWO_PI * mem.wheel_r, TWO_PI * mem.wheel_l, p.wheel_radius,
                         p.wheel_base)


def may_pass(d: float, grow: float, p: LawParams) -> bool:
    """Whether TRACK can pass (A13) a neighbour ``d`` [m] away whose governor disc is at
    most ``grow`` [m] wider than a: :func:`in_the_way`, as :func:`law_step` calls it,
    leaves out every neighbour farther than the widest of its reaches plus the growth. A
    caller need not compute the disc of a neighbour it cannot pass."""
    return p.sidestep and d < max(p.c, p.b + p.hysteresis) + grow


def in_the_way(heading: float, x: float, y: float, nbr_x: FloatSeq, nbr_y: FloatSeq,
               nbr_grow: FloatSeq, skip: int, passing: float, within: float,
               limit: float) -> tuple[int, float, float]:
    """(index, bearing [rad], half-width [rad]) of the cone of passing (A13) of the
    neighbour in the way of ``heading`` [rad] from (x, y) [m], or index -1 when none is.
    A neighbour grown by ``nbr_grow`` (its governor's disc's width beyond a [m]) is in the
    way when it is nearer than ``within`` + its growth and than ``limit`` [m], and its cone
    holds the heading: the bearings within asin(P / d) of the one to it, P = ``passing`` +
    its growth, or all within 90 degrees of it nearer than P. The nearest surface of such
    discs counts; neighbour ``skip`` (the one being passed; -1: none) is left out. The cone
    is tested with the heading's projection, no angle per neighbour."""
    nearest, j_in, reach_in = math.inf, -1, 0.0
    hx, hy = math.cos(heading), math.sin(heading)
    for j in range(len(nbr_x)):
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
