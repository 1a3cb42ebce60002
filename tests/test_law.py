"""Unit tests of the three-mode bounded law and each addition of docs/controller.md, run
interpreted (as agents run it) and compiled (as the batch simulator runs it)."""
import math
from pathlib import Path

import lawcase
import numpy as np
import pytest
from lawcase import single, step

from agent.config import ControlParams
from agent.law import LawMemory
from common.vocabulary import Mode

P = ControlParams()


@pytest.fixture(autouse=True, params=lawcase.IMPLS)
def impl(request, monkeypatch):
    """Every test runs on the law interpreted and compiled."""
    monkeypatch.setattr(lawcase, "IMPL", request.param)
    return request.param


def motion(out, theta):
    """Direction of travel (v cos theta, v sin theta) of robot 0."""
    return out.v[0] * np.array([math.cos(theta), math.sin(theta)])


def test_track_far_from_reference_drives_toward_it_at_full_speed():
    out = step(single([0, 0, 0], [20, 0]))
    assert out.mode[0] == Mode.TRACK
    assert out.v[0] == pytest.approx(P.K * P.D_max)
    assert out.u[0] == pytest.approx(0.0)


def test_track_speed_is_proportional_near_the_reference():
    out = step(single([0, 0, 0], [0.5, 0]))
    assert out.v[0] == pytest.approx(P.K * 0.5)


def test_at_the_reference_the_law_is_at_rest():
    out = step(single([3, 4, 1.0], [3, 4]))
    assert out.v[0] == 0.0 and out.u[0] == 0.0


@pytest.mark.parametrize("turns", [-3, -1, 1, 2])
def test_e_theta_is_wrapped(turns):
    base = step(single([0, 0, 0.3], [10, 0]))
    wound = step(single([0, 0, 0.3 + 2 * math.pi * turns], [10, 0]))
    assert wound.u[0] == pytest.approx(base.u[0])
    assert wound.v[0] == pytest.approx(base.v[0])
    assert base.u[0] == pytest.approx(-P.K_theta * 0.3)


def test_robot_behind_its_reference_turns_and_reverses():
    # reference behind: e_theta = pi, cos = -1, the robot backs toward it
    out = step(single([0, 0, 0], [-1, 0]))
    assert out.v[0] == pytest.approx(-P.K * 1.0)


@pytest.mark.parametrize("theta", [0.0, 0.7, math.pi, -2.0])
def test_robot_closer_than_b_moves_away_from_its_neighbour(theta):
    pose, nbr = np.array([0.0, 0.0, theta]), np.array([1.5, 0.0])
    out = step(single(pose, [-30, 0], nbrs=[nbr]))
    assert out.mode[0] == Mode.AVOID
    # the motion has a component away from the neighbour, unless the robot is broadside
    # to it (then it first turns)
    away = motion(out, theta) @ (pose[:2] - nbr)
    if abs(math.cos(theta)) > 0.1:
        assert away > 0


def test_avoid_speed_follows_the_potential_gradient():
    r = 1.5
    out = step(single([0, 0, math.pi], [30, 0], nbrs=[[r, 0]]))
    grad = P.K_ij * abs(math.tanh(r - P.c))
    assert out.v[0] == pytest.approx(P.K * min(P.D_max, grad))   # facing away: e_theta = 0
    assert out.u[0] == pytest.approx(0.0)


def test_hysteresis_on_neighbour_avoidance():
    inp = single([0, 0, 0], [20, 0], nbrs=[[P.b + 0.25, 0]])
    fresh = step(inp)
    assert fresh.mode[0] == Mode.TRACK                 # entering needs r < b
    avoiding = LawMemory(avoiding=True)
    held = step(inp, avoiding)
    assert held.mode[0] == Mode.AVOID                  # leaving needs r > b + hysteresis
    released = step(single([0, 0, 0], [20, 0], nbrs=[[P.b + P.hysteresis + 0.1, 0]]),
                    avoiding)
    assert released.mode[0] == Mode.TRACK


@pytest.mark.parametrize("per_pair", [True, False])
def test_hysteresis_per_pair_holds_only_the_pairs_that_came_within_b(per_pair):
    """A robot between two neighbours 2.3 m away (between b and b + hysteresis), the pair
    with the one on its left active last period, the other not: per pair, only the left
    one is avoided, so the robot moves away from it (to the right, -y); per robot, both
    are, and their pushes cancel across the robot's axis (it goes neither way)."""
    d = P.b + 0.3
    inp = single([0, 0, 0], [0, 20], nbrs=[(0, d), (0, -d)])._replace(held=[1.0, 0.0])
    out = step(inp, LawMemory(avoiding=True),
               params=ControlParams(pair_hysteresis=per_pair))
    assert out.mode[0] == Mode.AVOID
    if per_pair:
        # descend away from the left neighbour: heading -pi/2, e_theta = pi/2
        assert out.u[0] == pytest.approx(-P.K_theta * math.pi / 2)
    else:
        assert out.v[0] == pytest.approx(0.0, abs=1e-9)


def test_pair_active_enters_below_b_and_leaves_beyond_b_plus_hysteresis():
    from agent.law import pair_active
    b, h = P.b, P.hysteresis
    assert pair_active((b - 0.01) ** 2, False, b, h)
    assert not pair_active((b + 0.01) ** 2, False, b, h)
    assert pair_active((b + h - 0.01) ** 2, True, b, h)
    assert not pair_active((b + h + 0.01) ** 2, True, b, h)


def test_law_paper_turns_the_deadlock_resolution_off():
    from agent.params import LawParams
    on = LawParams.of(ControlParams(sidestep=True, pair_hysteresis=True), None)
    paper = LawParams.of(ControlParams(sidestep=True, pair_hysteresis=True, law="paper"), None)
    assert (on.sidestep, on.pair_hysteresis) == (True, True)
    assert (paper.sidestep, paper.pair_hysteresis) == (False, False)
    out = step(single([0, 0, 0], [20, 0], nbrs=[(3, 0)]), params=ControlParams(law="paper"))
    assert out.u[0] == pytest.approx(0.0)          # drives at the neighbour in the way


def test_obstacle_closer_than_b_triggers_avoid_away_from_it():
    # obstacle surface 1.5 m ahead; reference beyond it
    out = step(single([0, 0, math.pi], [20, 0], obstacles=[((4.5, 0), 3.0)]))
    assert out.mode[0] == Mode.AVOID
    assert motion(out, math.pi) @ np.array([-1.0, 0.0]) > 0


def test_obstacle_priority_removes_the_push_into_an_obstacle():
    # two neighbours on the left push the robot right, into an obstacle 1.5 m to its right
    inp = single([0, 0, 0], [0, 30], nbrs=[[-1.2, 0.3], [-1.2, -0.3]],
                 obstacles=[((4.5, 0), 3.0)])
    out = step(inp)
    assert out.mode[0] == Mode.AVOID
    for theta in np.linspace(-math.pi, math.pi, 13):
        o = step(single([0, 0, theta], [0, 30], nbrs=[[-1.2, 0.3], [-1.2, -0.3]],
                        obstacles=[((4.5, 0), 3.0)]))
        assert motion(o, theta)[0] <= 1e-9            # never toward the obstacle (+x)


def test_rotate_heads_along_the_obstacle_tangent():
    obstacle = ((0.0, 0.0), 3.0)
    pos = np.array([-5.5, 0.5])                        # surface 2.5 m away: b < 2.5 < c
    phi = math.atan2(-pos[1], -pos[0])
    tangent = phi + math.pi / 2                        # reference right of the obstacle,
    out = step(single([*pos, tangent], [10, 0], obstacles=[obstacle]))   # robot above it
    assert out.mode[0] == Mode.ROTATE
    assert out.u[0] == pytest.approx(0.0, abs=1e-12)   # already on the tangent
    assert out.v[0] > 0
    assert out.memory.side == 1
    # the other side of the obstacle picks the other tangent
    below = step(single([-5.5, -0.5, 0.0], [10, 0], obstacles=[obstacle]))
    assert below.memory.side == -1


def test_rotate_tangent_has_a_positive_component_toward_the_reference():
    unclipped = ControlParams(u_max=4.0 * math.pi)     # |K_theta e_theta| <= 3 pi < u_max
    for y in np.linspace(-2.5, 2.5, 11):
        pos = np.array([-5.6, y])
        out = step(single([*pos, 0.0], [12, -y / 2], obstacles=[((0, 0), 3.0)]),
                   params=unclipped)
        assert out.mode[0] == Mode.ROTATE and abs(out.u[0]) < unclipped.u_max
        theta_d = 0.0 + out.u[0] / P.K_theta           # u = -K_theta (0 - theta_d)
        ref_dir = np.array([12, -y / 2]) - pos
        assert np.array([math.cos(theta_d), math.sin(theta_d)]) @ ref_dir > 0


def test_no_rotate_when_the_path_is_clear():
    out = step(single([-5.5, 6.0, 0.0], [10, 6.0], obstacles=[((0, 0), 3.0)]))
    assert out.mode[0] == Mode.TRACK
    assert out.memory.side == 0


def test_latched_side_kept_until_the_path_is_clear():
    obstacle = [((0.0, 0.0), 3.0)]
    first = step(single([-5.5, 0.5, 0.0], [10, 0], obstacles=obstacle))
    assert first.memory.side == 1
    # now below the axis: a fresh robot would pick side -1, the latched one keeps +1
    fresh = step(single([-5.5, -0.8, 0.0], [10, 0], obstacles=obstacle))
    assert fresh.memory.side == -1
    kept = step(single([-5.5, -0.8, 0.0], [10, 0], obstacles=obstacle), first.memory)
    assert kept.mode[0] == Mode.ROTATE and kept.memory.side == 1
    # past the obstacle, the straight path to the reference is clear: latch released
    clear = step(single([4.0, 3.6, 0.0], [10, 5.0], obstacles=obstacle), kept.memory)
    assert clear.memory.side == 0 and clear.mode[0] == Mode.TRACK


def test_latch_survives_an_avoid_episode():
    obstacle = [((0.0, 0.0), 3.0)]
    first = step(single([-5.5, 0.5, 0.0], [10, 0], obstacles=obstacle))
    avoid = step(single([-5.5, -0.8, 0.0], [10, 0], nbrs=[[-5.5, -2.0]], obstacles=obstacle),
                 first.memory)
    assert avoid.mode[0] == Mode.AVOID and avoid.memory.side == 1


def test_corner_rule_hands_over_to_the_obstacle_ahead():
    # going north past A (A on the right, side +1); B ahead on the right, close to A
    a, b_ = ((0.0, 0.0), 3.0), ((-1.0, 5.5), 1.5)
    first = step(single([-5.5, 0.5, 1.5], [10, 2], obstacles=[a]))
    assert first.mode[0] == Mode.ROTATE and first.memory.side == 1
    both = step(single([-5.2, 2.5, 1.5], [10, 2], obstacles=[a, b_]), first.memory)
    assert both.mode[0] == Mode.ROTATE
    assert (both.memory.center_x, both.memory.center_y) == (-1.0, 5.5)
    assert both.memory.side == 1
    # an obstacle on the other (left) side does not take over
    left = step(single([-5.2, 2.5, 1.5], [10, 2], obstacles=[a, ((-9.5, 4.0), 1.5)]),
                first.memory)
    assert (left.memory.center_x, left.memory.center_y) == (0.0, 0.0)


def test_u_is_clipped():
    # the reference jumped across the robot: the finite-difference heading rate is huge
    mem = LawMemory(prev_ex=0.0, prev_ey=-0.01, has_prev=True)
    out = step(single([0, 0, 0], [-0.01, 0.0]), mem)
    assert abs(out.u[0]) == pytest.approx(P.u_max)
    small = ControlParams(u_max=1.0)
    assert abs(step(single([0, 0, 0], [0, 5]), params=small).u[0]) == pytest.approx(1.0)


def test_heading_rate_feed_forward_from_the_error_difference():
    # the error rotates by 0.01 rad in one period: theta_d_dot = 0.5 rad/s
    mem = LawMemory(prev_ex=-10 * math.cos(-0.01), prev_ey=-10 * math.sin(-0.01),
                    has_prev=True)
    out = step(single([0, 0, 0], [10, 0]), mem)
    assert out.u[0] == pytest.approx(0.01 / P.period, rel=1e-3)


def test_track_passes_a_neighbour_in_the_way_on_its_right():
    """A neighbour 3 m ahead (within c) on the way to a reference 20 m ahead: the robot
    heads asin((b + hysteresis)/3) = 56 degrees to the right of it; the paper's TRACK
    (sidestep = false) drives straight at it."""
    out = step(single([0, 0, 0], [20, 0], nbrs=[(3, 0)]))
    assert out.mode[0] == Mode.TRACK
    assert out.u[0] == pytest.approx(-P.K_theta * math.asin((P.b + P.hysteresis) / 3.0))
    paper = step(single([0, 0, 0], [20, 0], nbrs=[(3, 0)]), params=ControlParams(sidestep=False))
    assert paper.u[0] == pytest.approx(0.0)


def test_track_passes_on_the_left_when_its_right_leads_toward_a_neighbour_beside_it():
    """A neighbour 3.8 m ahead in the way to a reference a little left of it, another 2.35 m
    off on the right, a little behind (within b + hysteresis, out of the way): the right
    edge of the cone of passing leads toward that one and the left edge toward none, so the
    robot heads asin((b + hysteresis)/3.8) to the left and keeps the left (the law's
    memory) while a neighbour is in its way, even once its right is clear; with its
    reference right of the neighbour in the way, or nothing beside it, it passes on the
    right."""
    cone = math.asin((P.b + P.hysteresis) / 3.8)
    ahead, beside = (3.8, 0.0), (-0.5, -2.3)
    left = step(single([0, 0, 0], [20, 1], nbrs=[ahead, beside]))
    assert left.mode[0] == Mode.TRACK and left.memory.passing == 1
    assert left.u[0] == pytest.approx(P.K_theta * cone)
    kept = step(single([0, 0, 0], [20, 1], nbrs=[ahead]), mem=left.memory)
    assert kept.memory.passing == 1 and kept.u[0] == pytest.approx(P.K_theta * cone)
    for case in (single([0, 0, 0], [20, -1], nbrs=[ahead, beside]),
                 single([0, 0, 0], [20, 1], nbrs=[ahead])):
        right = step(case)
        assert right.memory.passing == -1 and right.u[0] == pytest.approx(-P.K_theta * cone)
    clear = step(single([0, 0, 0], [20, 1], nbrs=[(-3.0, 0.0)]), mem=left.memory)
    assert clear.memory.passing == 0                      # none in the way: side forgotten


@pytest.mark.parametrize("nbr", [(1.0, 3.0), (5.0, 0.0), (-3.0, 0.0)])
def test_track_does_not_sidestep_a_neighbour_out_of_the_way(nbr):
    """Outside the cone of passing, farther than c, or behind: the paper's heading."""
    out = step(single([0, 0, 0], [20, 0], nbrs=[nbr]))
    assert out.mode[0] == Mode.TRACK and out.u[0] == pytest.approx(0.0)


def test_track_passes_the_governor_s_disc_of_a_neighbour_not_its_centre():
    """A neighbour 3.8 m ahead and 1.9 m right, beyond c, is out of the way of a robot with
    fresh data. With old data its governor disc is wider than a (1.5 m here: the governor
    would hold the robot behind it at its pace); then it is in the way up to c + 1.5 m off,
    and the robot heads asin((b + hysteresis + 1.5)/d) right of its bearing. A neighbour
    behind on the right as old closes the right: it passes on the left."""
    ahead, grow = (3.8, -1.9), 1.5
    bearing, d = math.atan2(ahead[1], ahead[0]), math.hypot(*ahead)
    fresh = step(single([0, 0, 0], [20, 0], nbrs=[ahead])._replace(grow=[0.0]))
    assert fresh.u[0] == pytest.approx(0.0) and fresh.memory.passing == 0
    cone = math.asin((P.b + P.hysteresis + grow) / d)
    old = step(single([0, 0, 0], [20, 0], nbrs=[ahead])._replace(grow=[grow]))
    assert old.mode[0] == Mode.TRACK and old.memory.passing == -1
    assert old.u[0] == pytest.approx(P.K_theta * (bearing - cone))
    boxed = step(single([0, 0, 0], [20, 0], nbrs=[ahead, (-0.5, -3.5)])
                 ._replace(grow=[grow, grow]))
    assert boxed.memory.passing == 1
    assert boxed.u[0] == pytest.approx(P.K_theta * (bearing + cone))
    fresh_box = step(single([0, 0, 0], [20, 0], nbrs=[ahead, (-0.5, -3.5)])
                     ._replace(grow=[0.0, 0.0]))
    assert fresh_box.u[0] == pytest.approx(0.0)


def test_track_does_not_sidestep_a_neighbour_beyond_the_reference():
    out = step(single([0, 0, 0], [2, 0], nbrs=[(3, 0)]))
    assert out.mode[0] == Mode.TRACK and out.u[0] == pytest.approx(0.0)


def _cart():
    """The 0.8 m hoverboard cart of robots/cart.toml (3 m/s, 2 m/s^2)."""
    from hil.files.robot_profile import load_robot_profile
    return load_robot_profile(str(Path(__file__).resolve().parent.parent / "robots"
                                  / "cart.toml"))


def _turn_beside_an_obstacle(robot):
    """A cart stopped 2 cm outside the governor's disc of an obstacle ahead (clearance a +
    0.02 m) turns on the spot to a reference on its right, its right wheel slipping 10 %
    (its left none): the minimum clearance [m] over 6 s and the heading turned [rad]."""
    from lawcase import Case

    from agent.kinematics import TWO_PI, arc_step, body_velocity

    params = ControlParams()
    a, r = params.a, 1.0
    cx = a + r + 0.02
    pose, mem = (0.0, 0.0, 0.0), LawMemory()
    worst = math.inf
    for _ in range(int(6.0 / params.period)):
        case = Case(pose, (0.0, -20.0), [], [(cx, 0.0, r)], [(cx, 0.0, r + a, -math.inf, 0.0)])
        out = step(case, mem, params, robot)
        mem = out.memory
        # the ground moves by (1 - slip) of each wheel's turn
        v, u = body_velocity(TWO_PI * mem.wheel_r * 0.9, TWO_PI * mem.wheel_l,
                             robot.wheel_radius, robot.wheel_base)
        pose = arc_step(*pose, v * params.period, u * params.period)
        worst = min(worst, math.hypot(cx - pose[0], pose[1]) - r)
    return worst, abs(pose[2])


def test_a_robot_turning_with_slipping_wheels_beside_an_obstacle_keeps_out_of_a():
    """The governor limits the turn to the room left for the drift of slipping wheels
    (controller.md A14), and the robot still turns to its reference."""
    worst, turned = _turn_beside_an_obstacle(_cart())
    a = ControlParams().a
    assert worst > a and turned > 1.0, (worst, turned)


def test_a_robot_inside_a_disc_that_grew_round_it_still_gets_out():
    """A neighbour beside a cart falls silent: its disc grows round the cart (3 m, the cart
    2.5 m from its centre, abeam). Abeam, the disc holds the cart's speed to 0 both ways
    (the heading the cart may still turn to in its reaction time brings the disc ahead and
    behind), so only turning gets it out; the disc it is inside does not limit the turn
    (controller.md A14): it turns, drives off and reaches its reference 20 m ahead."""
    from lawcase import Case

    from agent.kinematics import arc_step

    cart, params = _cart(), ControlParams()
    a, silent = params.a, 3.0                # m, the silent neighbour's disc
    pose, mem = (0.0, 0.0, 0.0), LawMemory()
    out = step(Case(pose, (20.0, 0.0), [], [(0.0, 2.5, silent - a)],
                    [(0.0, 2.5, silent, -math.inf, 0.0)]), mem, params, cart)
    assert out.v[0] == 0.0                   # held both ways at first
    for _ in range(int(40.0 / params.period)):
        case = Case(pose, (20.0, 0.0), [], [(0.0, 2.5, silent - a)],
                    [(0.0, 2.5, silent, -math.inf, 0.0)])
        out = step(case, mem, params, cart)
        mem = out.memory
        pose = arc_step(*pose, out.v[0] * params.period, out.u[0] * params.period)
    assert math.hypot(pose[0] - 20.0, pose[1]) < 0.5, pose





@pytest.mark.parametrize("error", [0.6, 1.0, 1.5])
def test_a_cart_turning_faster_than_it_can_stop_within_its_heading_error_turns_slower(error):
    """A cart turning at 3 rad/s toward its heading, ``error`` rad away, its reference far
    ahead on it: its turn rate changes at most at 2a/L = 5 rad/s^2 (the wheels' ramp), so
    from 3 rad/s it needs 0.9 rad to stop turning, more at half the ramp. The heading loop's
    K_theta e_theta (1.8-4.5 rad/s) would hold or raise the turn and overshoot; the law turns
    no faster than lets it stop within e_theta at half the ramp (controller.md A15)."""
    from lawcase import Case

    from agent.braking import braking_speed
    from agent.kinematics import body_velocity

    cart, params = _cart(), ControlParams()
    spin = 3.0 * cart.wheel_base / (2.0 * 2.0 * math.pi * cart.wheel_radius)   # rev/s
    ref = (100.0 * math.cos(error), 100.0 * math.sin(error))
    out = step(Case((0.0, 0.0, 0.0), ref, [], [], []), LawMemory(wheel_r=spin, wheel_l=-spin),
               params, cart)
    _, u = body_velocity(2.0 * math.pi * out.memory.wheel_r, 2.0 * math.pi * out.memory.wheel_l,
                         cart.wheel_radius, cart.wheel_base)
    alpha = cart.a_max / cart.wheel_base                   # rad/s^2, half the ramp's
    wanted = braking_speed(error, alpha, params.period + cart.drive_latency)
    change = 2.0 * 2.0 * math.pi * cart.wheel_radius * cart.wheel_ramp * params.period \
        / cart.wheel_base                                  # rad/s, one period of the ramp
    assert u == pytest.approx(max(wanted, 3.0 - change), abs=1e-9)
    assert u < 3.0

def test_a_cart_between_two_obstacles_too_close_to_pass_goes_round_the_other_side():
    """A cart in the notch between obstacle A (r 2.8 m) and a disc B (r 4.1 m, a dead
    robot's) 3.45 m apart, less than 2b, with its reference beyond A on B's side: going
    round A on the side facing the reference leads into the gap, where AVOID pushes it
    back (a robot of the campaign circled there for 100 s). The way is closed, so the law
    goes round A on the other side (controller.md A5) and gets away toward its reference."""
    from lawcase import Case

    from agent.kinematics import arc_step

    cart, params = _cart(), ControlParams()
    obstacles = [(-9.0, 22.0, 2.79), (-1.6, 14.8, 4.08)]
    hazards = [(x, y, r + params.a, -math.inf, 0.0) for x, y, r in obstacles]
    pose, mem = (-7.2, 17.6, math.radians(150.0)), LawMemory()
    for _ in range(int(20.0 / params.period)):
        out = step(Case(pose, (41.0, 218.0), [], obstacles, hazards), mem, params, cart)
        mem = out.memory
        pose = arc_step(*pose, out.v[0] * params.period, out.u[0] * params.period)
    assert pose[1] > 30.0, pose                          # beyond A, on the way
