"""Property tests: the law's outputs are finite and bounded for any finite input, and the
compiled law (the batch simulator's) returns exactly what the interpreted one (an agent's)
does."""
import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import agent.governor
import agent.law
from agent.avoidance import Surroundings
from agent.config import ControlParams, RobotParams
from agent.governor import NO_GAPS, NO_LIMITS, braking_of, fold_hazard, frame_limits, limit_frame
from agent.kinematics import body_velocity
from agent.law import LawMemory, Reference, last_velocity, law_step
from agent.params import LawParams
from firmware_sim import compiled

P = ControlParams()
CART = RobotParams(wheel_radius=0.08, wheel_base=0.6, wheel_speed_limit=6.0, wheel_ramp=4.0,
                   drive_latency=0.02)
# a sporty robot whose law speeds it up at 2 m/s^2 though its wheels ramp at 25 (A17)
SPORTY = RobotParams(wheel_radius=0.1, wheel_base=0.5, wheel_speed_limit=12.73,
                     wheel_ramp=39.8, drive_latency=0.01, speed_up=2.0)
LP = LawParams.of(P, None)              # the ideal robot
LP_CART = LawParams.of(P, CART)         # wheels with limits: the governor and the ramp act
LP_SPORTY = LawParams.of(P, SPORTY)
coord = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False)
near = st.floats(-6.0, 6.0, allow_nan=False, allow_infinity=False)
angle = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
point = st.tuples(near, near)


@st.composite
def cases(draw):
    """(pose, ref, nbr_x, nbr_y, nbr_held, nbr_grow, obs_x, obs_y, obs_r, hazards x, y,
    full, half, moving, memory)
    around a random base point; references and neighbours may coincide with the robot
    (D = 0, r = 0); the hazards are the neighbours and obstacles, as agents build them."""
    bx, by = draw(coord), draw(coord)
    dx, dy = draw(point)
    pose = (bx + dx, by + dy, draw(angle))
    on_robot = st.just((pose[0], pose[1]))
    around = point.map(lambda q: (bx + q[0], by + q[1]))
    ref = draw(st.one_of(on_robot, around))
    nbrs = draw(st.lists(st.one_of(on_robot, around), max_size=4))
    obs = draw(st.lists(st.tuples(around, st.floats(0.1, 5.0)), max_size=3))
    mem = LawMemory()
    if draw(st.booleans()):
        centre = obs[0] if obs else ((0.0, 0.0), 0.0)
        wheels = st.floats(-6.0, 6.0)
        prev_x, prev_y = draw(point)
        (centre_x, centre_y), radius = centre
        mem = LawMemory(prev_x, prev_y, True, draw(st.booleans()),
                        draw(st.sampled_from([-1, 0, 1])), centre_x, centre_y, radius,
                        draw(wheels), draw(wheels), draw(st.sampled_from([-1, 0, 1])))
    grow = [draw(st.floats(0.0, 3.0)) for _ in nbrs]
    hazards = [(q[0], q[1], -math.inf, P.a + g, 1.0) for q, g in zip(nbrs, grow)] + \
        [(o[0][0], o[0][1], o[1] + P.a, -math.inf, 0.0) for o in obs]
    held = [float(draw(st.booleans())) for _ in nbrs]
    return (pose, ref, [q[0] for q in nbrs], [q[1] for q in nbrs], held, grow,
            [o[0][0] for o in obs], [o[0][1] for o in obs], [o[1] for o in obs],
            *([h[c] for h in hazards] for c in range(5)), mem)


law_module = SimpleNamespace(**vars(agent.law), **{
    name: getattr(agent.governor, name)
    for name in ("braking_of", "limit_frame", "fold_hazard", "frame_limits")})


def run(law, case, columns=list, lp=LP, fns=law_module):
    """``law`` on ``case``, the governor's limits among its hazards by ``fns`` (agent.law
    and agent.governor's functions, or their compiled versions)."""
    pose, ref, *cols, mem = case
    hx, hy, hr, hh, hm = cols[7:]
    frame = fns.limit_frame(pose[2], *fns.last_velocity(mem, lp), fns.braking_of(lp, P.period))
    gaps = NO_GAPS
    for h in range(len(hr)):
        gaps = fns.fold_hazard(gaps, frame, hx[h] - pose[0], hy[h] - pose[1], hr[h], hh[h],
                               hm[h])
    nx, ny, held, grow, ox, oy, orad = (columns(c) for c in cols[:7])
    around = Surroundings(nx, ny, held, grow, len(cols[0]), ox, oy, orad, len(cols[6]))
    return law(*pose, Reference(ref[0], ref[1], 1.0, -0.5), around,
               fns.frame_limits(gaps, frame), mem, lp, P.period)


def nothing() -> Surroundings:
    """No neighbours, no obstacles."""
    return Surroundings([], [], [], [], 0, [], [], [], 0)


@settings(max_examples=300, deadline=None)
@given(cases(), st.sampled_from([LP, LP_CART]))
def test_outputs_finite_and_bounded(case, lp):
    out = run(law_step, case, lp=lp)
    v, u, mode, governed, mem = out.v, out.u, out.mode, out.governed, out.memory
    assert math.isfinite(v) and math.isfinite(u)
    # within the bounds, or no farther from them than the wheels' speeds it starts from
    # (the ramp takes time to bring a robot spinning too fast back)
    was = case[-1]
    v0, u0 = body_velocity(2 * math.pi * was.wheel_r, 2 * math.pi * was.wheel_l,
                           CART.wheel_radius, CART.wheel_base) if lp is LP_CART else (0, 0)
    assert abs(u) <= max(P.u_max, abs(u0)) + 1e-9
    assert abs(v) <= max(P.K * P.D_max, abs(v0)) + 1e-9
    assert mode in (0, 1, 2)
    assert math.isfinite(mem.prev_ex) and math.isfinite(mem.prev_ey)
    assert math.isinf(governed) or governed >= 0.0
    # the memory it returns can be fed back in
    again = run(law_step, (*case[:-1], mem), lp=lp)
    assert math.isfinite(again.v) and math.isfinite(again.u)


@settings(max_examples=300, deadline=None)
@given(cases())
def test_commands_are_ones_the_wheels_can_follow(case):
    """Within the wheel speed limit, and each wheel within one period's ramp of its last
    set-point: nothing after the law has to clip. The set-points are what (v, u) make and
    what the law remembers."""
    mem = case[-1]
    out = run(law_step, case, lp=LP_CART)
    new = out.memory
    assert (out.right, out.left) == (new.wheel_r, new.wheel_l)
    v, u = body_velocity(2 * math.pi * out.right, 2 * math.pi * out.left, CART.wheel_radius,
                         CART.wheel_base)
    assert (v, u) == (out.v, out.u)
    step = CART.wheel_ramp * P.period + 1e-9
    assert abs(new.wheel_r - mem.wheel_r) <= step and abs(new.wheel_l - mem.wheel_l) <= step
    assert max(abs(new.wheel_r), abs(new.wheel_l)) <= CART.wheel_speed_limit + 1e-9


@settings(max_examples=300, deadline=None)
@given(cases())
def test_the_law_speeds_up_no_faster_than_it_commits_to(case):
    """On a robot whose law speeds it up slower than its wheels ramp (A17): its speed and
    its wheels' half difference grow by at most speed_up x T a period, past zero included;
    slowing down may take the whole ramp."""
    mem = case[-1]
    new = run(law_step, case, lp=LP_SPORTY).memory
    ground = 2 * math.pi * SPORTY.wheel_radius            # m/s per rev/s
    up = SPORTY.speed_up * P.period + 1e-9

    def grew(before: float, after: float) -> float:
        return abs(after) - abs(before) if before * after >= 0.0 else abs(after)

    assert grew(0.5 * ground * (mem.wheel_r + mem.wheel_l),
                0.5 * ground * (new.wheel_r + new.wheel_l)) <= up
    assert grew(0.5 * ground * (mem.wheel_r - mem.wheel_l),
                0.5 * ground * (new.wheel_r - new.wheel_l)) <= up
    step = SPORTY.wheel_ramp * P.period + 1e-9
    assert abs(new.wheel_r - mem.wheel_r) <= step and abs(new.wheel_l - mem.wheel_l) <= step
    assert max(abs(new.wheel_r), abs(new.wheel_l)) <= SPORTY.wheel_speed_limit + 1e-9


def test_braking_takes_the_whole_ramp_though_speeding_up_does_not():
    """The sporty robot of A17 at 5 m/s: asked to stop it sheds 25 m/s^2 x T in a period;
    standing and asked to go, it gains 2 m/s^2 x T."""
    ground = 2 * math.pi * SPORTY.wheel_radius
    moving = LawMemory(wheel_r=5.0 / ground, wheel_l=5.0 / ground)
    here = Reference(0.0, 0.0, 0.0, 0.0)
    v = law_step(0.0, 0.0, 0.0, here, nothing(), NO_LIMITS, moving, LP_SPORTY, P.period).v
    assert v == pytest.approx(5.0 - SPORTY.a_max * P.period)
    ahead = Reference(5.0, 0.0, 0.0, 0.0)
    v = law_step(0.0, 0.0, 0.0, ahead, nothing(), NO_LIMITS, LawMemory(), LP_SPORTY,
                 P.period).v
    assert v == pytest.approx(SPORTY.speed_up * P.period)


@settings(max_examples=300, deadline=None)
@given(cases(), st.sampled_from([LP, LP_CART, LP_SPORTY]))
def test_compiled_law_equals_the_interpreted_one(case, lp):
    want = run(law_step, case, lp=lp)
    got = run(compiled.kernels().law_step, case, lambda c: np.array(c, dtype=float), lp=lp,
              fns=compiled.kernels())
    assert got == want                       # bit for bit, memory included


@settings(max_examples=100, deadline=None)
@given(st.floats(0.0, 1e-12), angle)
def test_reference_at_the_robot(offset, theta):
    out = law_step(1.0, 2.0, theta, Reference(1.0 + offset, 2.0, 0.0, 0.0), nothing(),
                   NO_LIMITS, LawMemory(), LP, P.period)
    assert math.isfinite(out.u) and abs(out.v) <= P.K * 1e-12 + 1e-15


def test_turning_takes_the_ramp_first_unless_the_robot_must_brake():
    """Driving ahead at 2 rev/s with its reference behind and to the left: the law wants to
    turn and reverse. Free of hazards the turn gets the whole ramp (the law slows by itself
    while its heading is off); with a hazard close ahead the robot is behind its braking
    curve and braking takes the ramp first."""
    step = CART.wheel_ramp * P.period
    mem = LawMemory(wheel_r=2.0, wheel_l=2.0)
    behind = Reference(-10.0, 5.0, 0.0, 0.0)
    free = law_step(0.0, 0.0, 0.0, behind, nothing(), NO_LIMITS, mem, LP_CART,
                    P.period).memory
    assert free.wheel_r - free.wheel_l == pytest.approx(2 * step)
    frame = limit_frame(0.0, *last_velocity(mem, LP_CART), braking_of(LP_CART, P.period))
    ahead = frame_limits(fold_hazard(NO_GAPS, frame, 1.2, 0.0, 1.0, -math.inf, 0.0), frame)
    braking = law_step(0.0, 0.0, 0.0, behind, nothing(), ahead, mem, LP_CART,
                       P.period).memory
    assert braking.wheel_r + braking.wheel_l == pytest.approx(4.0 - 2 * step)
    assert braking.wheel_r == pytest.approx(braking.wheel_l)
