"""The safety governor's limits (agent.governor, agent.braking): braking speeds, limits, and
the promise that a robot braking from the speed it allows stops outside every hazard."""
import math
from pathlib import Path

import pytest
from governor_cases import ACCEL, STALE, STOP, TOP, A, neighbour, speed_limits, walk
from helpers import model
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.braking import braking_speed, stopping
from agent.discs import neighbour_floor, neighbour_radii
from agent.governor import (
    MOVING_PAD,
    NO_GAPS,
    Braking,
    binding,
    fold_hazard,
    frame_limits,
    limit_frame,
    slip_margin,
    turn_limit,
)
from agent.kinematics import wrap_angle
from firmware_sim.batch import SimOptions, simulate
from firmware_sim.plant import PlantKind
from firmware_sim.world import WorldParams
from hil.files.robot_profile import load_robot_profile
from hil.files.scenario import load_scenario


def test_braking_speed_uses_exactly_the_free_distance():
    v = braking_speed(2.0, ACCEL, 0.04)
    assert v * 0.04 + v * v / (2 * ACCEL) == pytest.approx(2.0)
    assert braking_speed(0.0, ACCEL, 0.04) == 0.0 and braking_speed(-1.0, ACCEL, 0.04) == 0.0
    assert braking_speed(0.5, math.inf, 0.02) == pytest.approx(25.0)   # an ideal robot
    # no reaction time and a turn that underflows to nothing over accel (found by hypothesis)
    assert braking_speed(1.0, 2.0, 0.0, 5e-324) == pytest.approx(braking_speed(1.0, 2.0, 0.0))


def limits(hx, hy, r=2.0, half=-math.inf, moving=0.0, theta=0.0, v_now=0.0, u_now=0.0,
           turn_rate=0.0, wheel_base=0.0):
    return speed_limits(0.0, 0.0, theta, v_now, u_now, [hx], [hy], [r], [half], [moving],
                        ACCEL, 0.04, 0.0, turn_rate, wheel_base)[:2]


def test_a_hazard_ahead_limits_forward_only():
    fwd, bwd = limits(5.0, 0.0)
    assert fwd == pytest.approx(braking_speed(3.0, ACCEL, 0.04)) and bwd == math.inf
    fwd, bwd = limits(-5.0, 0.0)
    assert fwd == math.inf and bwd == pytest.approx(braking_speed(3.0, ACCEL, 0.04))


@settings(max_examples=300, deadline=None)
@given(bearing=st.floats(-math.pi, math.pi), theta=st.floats(-math.pi, math.pi),
       d=st.floats(2.5, 8.0), moving=st.sampled_from([0.0, 1.0]))
def test_a_hazard_counts_with_the_cosine_of_its_angle_beyond_the_heading(bearing, theta, d,
                                                                         moving):
    """A robot at rest, not turning: a hazard ``bearing`` off the world's x axis limits
    each way of travel as if its free distance were shortened by the cosine of its angle
    from that way (less MOVING_PAD for a moving one), not at all beyond 90 degrees."""
    hx, hy = d * math.cos(bearing), d * math.sin(bearing)
    pad = MOVING_PAD if moving else 0.0
    ahead = abs(wrap_angle(bearing - theta))
    for off, got in ((ahead - pad, limits(hx, hy, moving=moving, theta=theta)[0]),
                     (math.pi - ahead - pad, limits(hx, hy, moving=moving, theta=theta)[1])):
        c = 1.0 if off <= 0.0 else math.cos(off)
        if abs(c) < 1e-6:
            continue                           # at 90 degrees: either answer is right
        want = braking_speed((d - 2.0) / c, ACCEL, 0.04) if c > 0.0 else math.inf
        assert got == pytest.approx(want, rel=1e-9)


def test_a_static_hazard_abeam_does_not_limit_but_a_moving_one_does():
    assert limits(0.0, 5.0) == (math.inf, math.inf)
    fwd, bwd = limits(0.0, 5.0, moving=1.0)
    assert fwd < math.inf and bwd < math.inf


def test_a_turning_robot_counts_what_its_heading_sweeps_while_it_stops():
    """Abeam at first, but the robot turns toward it at 2 rad/s while it brakes from 2 m/s."""
    assert limits(0.0, 5.0, v_now=2.0, u_now=0.0)[0] == math.inf
    assert limits(0.0, 5.0, v_now=2.0, u_now=2.0)[0] == pytest.approx(
        braking_speed(3.0, ACCEL, 0.04))


def test_the_turn_allowed_in_the_reaction_time_is_what_the_wheels_can_bend():
    """A cart (2 m/s^2, 0.8 m wheel base) at 1.5 m/s beside a moving neighbour 2.53 m
    abeam, its half of the gap 0.76 m. In its reaction time (watchdog 0.1 s and latency
    0.02 s) its wheels can bend its path by a tau^2 / L = 0.036 rad, not u_max tau = 1.1 rad:
    the neighbour is 90 - 17 (the moving pad) degrees off its travel and limits it little.
    Counting u_max tau, it counted in full and held the cart to 1.5 m/s, the formation's
    pace, for whole runs."""
    def fwd(accel):
        return speed_limits(0.0, 0.0, math.pi / 2, 1.5, 0.0, [-2.53], [0.0], [-math.inf],
                            [1.0], [1.0], accel, 0.1, 0.02, 3 * math.pi, 0.8, 3.0)[0]

    assert fwd(2.0) > 2.5


@settings(max_examples=200, deadline=None)
@given(free=st.floats(0.01, 20.0), accel=st.floats(0.5, 30.0), reaction=st.floats(0.0, 0.5),
       turn=st.floats(0.0, 5.0))
def test_braking_speed_fills_exactly_the_free_distance_however_the_wheels_turn(
        free, accel, reaction, turn):
    """The allowed speed is the fastest whose path with both wheels braking on their own,
    the robot turning with them ``turn`` m/s apart, ends at the free distance."""
    v = braking_speed(free, accel, reaction, turn)
    assert stopping(v, accel, reaction, turn) == pytest.approx(free, rel=1e-9, abs=1e-9)


def test_a_spinning_robot_may_go_slower_toward_a_hazard():
    """Its wheels 4 m/s apart (4 rad/s on a 1 m base): each brakes on its own, the outer
    one for longer, and the centre goes farther than when braking straight."""
    straight = limits(5.0, 0.0)[0]
    spinning = limits(5.0, 0.0, u_now=4.0, turn_rate=0.0, wheel_base=1.0)[0]
    assert spinning == pytest.approx(braking_speed(3.0, ACCEL, 0.04, 2.0))
    assert spinning < 0.85 * straight


def test_inside_a_hazard_the_robot_may_only_back_away():
    fwd, bwd = limits(1.0, 0.0)
    assert fwd == 0.0 and bwd == math.inf


@settings(max_examples=100, deadline=None)
@given(d0=st.floats(2.5, 30.0), accel=st.floats(0.5, 30.0), v_top=st.floats(0.5, 12.0),
       period=st.sampled_from([0.01, 0.02, 0.05]), lag=st.floats(0.0, 1.0))
def test_braking_from_the_allowed_speed_stops_outside_the_hazard(d0, accel, v_top, period,
                                                                  lag):
    """Straight at a hazard, commanding the allowed speed every period as the law does
    (ramped from its last command, which it takes as the speed it goes on at), applied a
    latency of up to one period late by wheels with the same ramp: the robot never enters
    the hazard."""
    radius, dt = 2.0, 0.001
    steps_per_period = round(period / dt)
    queue = [0.0] * round(lag * steps_per_period)     # commands on their way to the wheels
    latency = len(queue) * dt
    x, v, command = 0.0, 0.0, 0.0
    for k in range(int(30.0 / dt)):
        if k % steps_per_period == 0:
            fwd, _, _ = speed_limits(x, 0.0, 0.0, command, 0.0, [d0], [0.0], [radius],
                                     [-math.inf], [0.0], accel, period, latency, 0.0, 0.6)
            step = accel * period                    # the law's ramp, as the wheels'
            command = min(max(min(v_top, fwd), command - step), command + step)
            if command == 0.0 and v == 0.0:
                break
        queue.append(command)
        goal = queue.pop(0)
        v_new = v + min(max(goal - v, -accel * dt), accel * dt)
        x += 0.5 * (v + v_new) * dt                  # exact for a constant ramp
        v = v_new
        assert x <= d0 - radius + 1e-5       # (the 1 ms steps of this plant: um)


ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("scenario", ["paper", "head_on_swap", "grid", "narrow_gap"])
@pytest.mark.parametrize("profile", ["heavy", "cart", "sporty"])
def test_real_robots_keep_their_distance_in_the_bundled_scenarios(scenario, profile):
    """Closed loop, wheels plant, 0.2 s of link delay: no pair within a, no robot centre
    within a of an obstacle surface (the law alone breaks this in most of these runs)."""
    sc = load_scenario(ROOT / "scenarios" / f"{scenario}.toml")
    robot = load_robot_profile(ROOT / "robots" / f"{profile}.toml")
    m = simulate(sc.ids, sc.poses, sc.formation, sc.obstacles, sc.control, robot,
                 SimOptions(duration=20.0, plant=PlantKind.WHEELS, record_every=0),
                 world=WorldParams(link_delay=0.2, link_jitter=0.02)
                 ).metrics.summary(scenario, 20.0)
    assert m["collisions"] == 0
    assert m["min_pair_distance"] > sc.control.a
    assert m["min_obstacle_clearance"] is None or m["min_obstacle_clearance"] > sc.control.a


def test_turning_on_the_spot_with_slipping_wheels_never_drifts_into_a_hazard():
    """A robot ordered to spin at 3 rad/s 5 cm outside a hazard ahead, its wheels slipping
    by the profile's claim the worst way (the drift always toward the hazard): limited by
    turn_limit, it drifts ever slower and stays out for a minute; unlimited, it is in
    within half a second."""
    slip, base, accel, period = 0.1, 0.8, 2.0, 0.02
    reaction = period + 0.02

    def drift(limited: bool) -> tuple[float, float]:
        x, w, room0, first = 0.0, 0.0, 0.05, 0.0   # drift [m], wheels' half difference [m/s]
        for k in range(int(60.0 / period)):
            want = 3.0 * base / 2
            if limited:
                want = min(want, turn_limit(room0 - x, slip, accel, reaction, base) * base / 2)
            w = min(max(want, w - accel * period), w + accel * period)   # the wheels' ramp
            x += slip * w * period
            if k == 10:
                first = w
        return x, first

    x, first = drift(limited=True)
    assert x <= 0.05 + 1e-12 and first > 0.4     # in the room, having turned at first
    x, _ = drift(limited=False)
    assert x > 0.05
    assert turn_limit(math.inf, slip, accel, reaction, base) == math.inf
    assert turn_limit(0.1, 0.0, accel, reaction, base) == math.inf
    assert turn_limit(-0.01, slip, accel, reaction, base) == 0.0
    assert slip_margin(slip, base) == pytest.approx(0.1 * math.pi * 0.4)


@settings(max_examples=300, deadline=None)
@given(nbrs=st.lists(neighbour, max_size=10),
       obstacles=st.lists(st.tuples(st.floats(-8.0, 8.0), st.floats(-8.0, 8.0),
                                    st.floats(0.2, 2.0)), max_size=3),
       motion=st.tuples(st.floats(-math.pi, math.pi), st.floats(-3.0, 3.0),
                        st.floats(-2.0, 2.0)))
def test_leaving_out_the_discs_that_cannot_bind_keeps_the_limits(nbrs, obstacles, motion):
    """Obstacles first, then the neighbours' discs (agent.discs.neighbour_radii) nearest
    floor (agent.discs.neighbour_floor) first, each computed only where its floor is below
    the binding distance: the limits and the room of folding every disc, bit for bit."""
    theta, v_now, u_now = motion
    frame = limit_frame(theta, v_now, u_now,
                        Braking(ACCEL, 0.2, 0.02, 3 * math.pi, 0.8, TOP, 0.12, 1.5))
    m = model(a=A, accel=ACCEL, half_base=0.4, top_speed=TOP, staleness=STALE, stop_time=STOP,
              wheel_top=TOP, speed_up=2.0, lag=0.04, turn_up=1.5)
    every = NO_GAPS
    for x, y, r in obstacles:
        every = fold_hazard(every, frame, x, y, r + A, -math.inf, 0.0)
    kept = every

    def disc(rel_x, rel_y, heading, speed, turn, age, trail):
        full, half, east, north, _ = neighbour_radii(rel_x, rel_y, heading, speed, turn, age,
                                                     trail, m)
        return east - rel_x, north - rel_y, full, half, 1.0

    floors = []
    for rel_x, rel_y, heading, speed, turn, age, pieces, bend in nbrs:
        args = (rel_x, rel_y, heading, speed, turn, age, walk(pieces, bend))
        every = fold_hazard(every, frame, *disc(*args))
        floor, _ = neighbour_floor(rel_x, rel_y, speed, age, args[-1].walked[0], m)
        floors.append((floor, args))
    folded = 0
    for floor, args in sorted(floors, key=lambda f: f[0]):
        if floor < binding(kept, frame):
            kept = fold_hazard(kept, frame, *disc(*args))
            folded += 1
    assert frame_limits(kept, frame) == frame_limits(every, frame)
    assert folded <= len(floors)


def test_far_discs_are_left_out():
    """Behind a hazard 2 m ahead, ones whose free distance is at least 5 m, any way round,
    cannot bind."""
    frame = limit_frame(0.0, 1.0, 0.0, Braking(ACCEL, 0.2, 0.02, 3 * math.pi, 0.8, TOP, 0.12,
                                               1.5))
    gaps = fold_hazard(NO_GAPS, frame, 2.0, 0.0, 1.0, -math.inf, 0.0)
    gaps = fold_hazard(gaps, frame, -2.0, 0.0, 1.0, -math.inf, 0.0)
    assert not 5.0 < binding(gaps, frame)
    assert 0.5 < binding(gaps, frame)
    assert 0.5 < binding(NO_GAPS, frame)          # nothing yet: every disc can bind
    # inside the margin of hazards ahead and behind, a disc within the margin can bind
    # aside: its gap, below zero, grows more negative over a cosine below 1
    close = fold_hazard(NO_GAPS, frame, 1.05, 0.0, 1.0, -math.inf, 0.0)
    close = fold_hazard(close, frame, -1.05, 0.0, 1.0, -math.inf, 0.0)
    assert close.fwd < 0.0 and 0.1 < binding(close, frame)
