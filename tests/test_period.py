"""One robot's period (agent.period): what it senses, what it hands the law, what it keeps."""
import math
import random

import numpy as np
import pytest

from agent.config import ControlParams, RobotParams
from agent.exchange import NOBODY, Exchange
from agent.formation import Places
from agent.kinematics import wheel_command
from agent.law import LawMemory, moved_estimate
from agent.neighbours import Reports, extrapolate
from agent.node import _workspace
from agent.params import PeriodParams
from agent.period import Detections, Inputs, Memory, Own, robot_period, sense
from agent.trail import OwnPath

CART = RobotParams(wheel_radius=0.0825, wheel_speed_limit=5.79, wheel_ramp=3.86,
                   drive_latency=0.02)
PARAMS = PeriodParams.of(ControlParams(), CART, 8.0, 0.5, CART.watchdog_timeout)
NOW = 100.0


def reports(rows) -> Reports:
    """Reports of (id, stamp, x, y, theta, v, u) rows, row k in place k + 1."""
    rows = list(rows)
    col = [[r[c] for r in rows] for c in range(7)]
    return Reports([int(i) for i in col[0]], col[1], col[2], col[3], col[4], col[5], col[6],
                   list(range(1, len(rows) + 1)), [NOBODY] * len(rows), [NOBODY] * len(rows))


def inputs(rows, x=0.0, y=0.0, theta=0.0, detections=(), held=(), jump=(0.0, 0.0),
           me=0) -> Inputs:
    rep = reports(rows)
    n = len(rep.robot)
    det = Detections([d[0] for d in detections], [d[1] for d in detections],
                     [d[2] for d in detections], len(detections))
    places = Places(np.array([[0.0, 0.0]] + [[4.0 * k, 0.0] for k in range(1, n + 1)]),
                    np.array([20.0, 0.0, 0.0, 0.0, 0.0]))
    path = OwnPath([NOW], [x], [y], [0.0], 0, 1, 1)
    return Inputs(Own(me, x, y, theta, 0.0, *jump), NOW, 10.0, 0.02, rep, list(range(n)), n,
                  det, places, path, list(held), len(held))


def sensed(inp: Inputs, p: PeriodParams = PARAMS):
    ws = _workspace(2 * (inp.n_near + inp.detections.n) + 1)
    n_nbr, n_obs, n_cand = sense(inp, p, ws)
    rows = inp.reports.robot
    return ([(ws.nbr_x[q], ws.nbr_y[q]) for q in range(n_nbr)],
            [(ws.obs_x[k], ws.obs_y[k], ws.obs_r[k]) for k in range(n_obs)],
            sorted(rows[ws.cand_row[c]] for c in range(n_cand)),
            [rows[ws.nbr_row[q]] for q in range(n_nbr)])


def test_fresh_neighbours_are_moved_along_their_arcs_and_stale_ones_are_obstacles():
    got, obstacles, _, ids = sensed(inputs([
        (1, NOW - 0.1, 1.0, 0.0, 0.0, 2.0, 0.0),           # east at 2 m/s: 1.2 m
        (2, NOW - 1.0, 3.0, 4.0, 0.0, 0.0, 0.0),           # silent for 1 s
        (3, NOW - 0.1, 20.0, 0.0, 0.0, 0.0, 0.0)],         # out of range
        detections=[(5.0, 5.0, 1.0)]))
    assert ids == [1] and got == [pytest.approx((1.2, 0.0))]
    # the detection, then the silent robot with its silent disc less a
    assert obstacles[0] == (5.0, 5.0, 1.0)
    assert obstacles[1][:2] == (3.0, 4.0) and obstacles[1][2] >= 0.5 * ControlParams().a


def test_its_own_row_and_rows_never_heard_are_passed_over():
    _, _, cands, ids = sensed(inputs([(0, NOW, 1.0, 0.0, 0.0, 0.0, 0.0),
                                      (1, -math.inf, 1.0, 0.0, 0.0, 0.0, 0.0),
                                      (2, NOW, 2.0, 0.0, 0.0, 0.0, 0.0)]))
    assert ids == [2] and cands == [2]


def test_a_future_stamp_is_not_extrapolated_backwards():
    got, _, _, _ = sensed(inputs([(1, NOW + 5.0, 1.0, 0.0, 0.0, 1.0, 0.0)]))
    assert got == [pytest.approx((1.0, 0.0))]


def test_the_governor_looks_at_every_neighbour_that_may_be_in_range_by_now():
    """A report within the sensing range plus what the fastest robot travels in its data's
    age (the staleness limit at most) may be within the range now: a hazard of the
    governor, even where its report puts it out of range; beyond that, none."""
    top = PARAMS.model.top_speed
    r = PARAMS.sensing_range
    _, _, cands, ids = sensed(inputs([
        (1, NOW - 0.1, r + 0.9 * top * 0.1, 0.0, 0.0, 0.0, 0.0),     # may be in range
        (2, NOW - 0.1, r + 1.1 * top * 0.1, 0.0, 0.0, 0.0, 0.0),     # cannot be
        (3, NOW - 2.0, r + 0.9 * top * 0.5, 0.0, 0.0, 0.0, 0.0),     # silent: its limit
        (4, NOW, r + 0.01, 0.0, 0.0, 0.0, 0.0)]))                   # fresh, out of range
    assert ids == [] and cands == [1, 3]


def test_the_range_test_is_on_the_extrapolated_position_whatever_the_shortcut():
    """Robots far out of range are passed over without moving them along their arcs; the
    outcome is that of moving every one and testing its distance, also for robots whose arc
    ends right at the range (a chord is never longer than its arc)."""
    rng = random.Random(7)
    staleness, r = 0.5, 6.0
    p = PARAMS._replace(sensing_range=r)
    for _ in range(300):
        x, y = rng.uniform(-5, 5), rng.uniform(-5, 5)
        rows = []
        for i in range(1, 21):
            age = rng.choice([rng.uniform(-0.05, 0.6), 0.5, 0.0])
            rows.append((i, NOW - age, x + rng.uniform(-12, 12), y + rng.uniform(-12, 12),
                         rng.uniform(-4, 4), rng.uniform(-6, 6), rng.uniform(-3, 3)))
        # and one whose arc ends exactly at the range, from beyond it
        i, stamp, mx, my, th, v, u = rows[0]
        px, py, _ = extrapolate(mx, my, th, v, u, NOW - stamp, staleness)
        d = math.hypot(px - x, py - y)
        if d > 0:
            rows[0] = (i, stamp, mx + (x - px) * (1 - r / d), my + (y - py) * (1 - r / d), th,
                       v, u)
        got, obstacles, _, _ = sensed(inputs(rows, x, y), p)
        want_fresh: list[tuple[float, float]] = []
        want_stale: list[tuple[float, float]] = []
        for _, stamp, mx, my, th, v, u in rows:
            px, py, stale = extrapolate(mx, my, th, v, u, NOW - stamp, staleness)
            if (px - x) ** 2 + (py - y) ** 2 <= r * r:
                (want_stale if stale else want_fresh).append((px, py))
        assert got == want_fresh and [o[:2] for o in obstacles] == want_stale


def test_the_pairs_active_are_kept_by_robot_id():
    """A neighbour 2.2 m away (beyond b = 2 m, within b + hysteresis): avoided only if its
    pair was active last period, whatever its row; the period hands back the ids."""
    pair = ControlParams(pair_hysteresis=True)
    p = PeriodParams.of(pair, CART, 8.0, 0.5, CART.watchdog_timeout)
    rows = [(5, NOW, 9.0, 9.0, 0.0, 0.0, 0.0), (7, NOW, 2.2, 0.0, 0.0, 0.0, 0.0)]
    mem = Memory(LawMemory(), Exchange(0))
    for held, want in (((), 0), ((7,), 1)):
        ws = _workspace(8)
        out = robot_period(inputs(rows, held=held), mem, p, ws)
        assert out.n_held == want and list(ws.held[:want]) == [7] * want
        assert out.mode == (1 if want else 0)               # AVOID or TRACK


def test_a_pose_fix_s_jump_moves_the_remembered_error_before_the_law():
    """The period with a jump of the estimate is the period on a memory moved by it
    (agent.law.moved_estimate): bit for bit."""
    mem = LawMemory(1.5, -0.5, True, False, 0, 0.0, 0.0, 0.0, 1.0, 1.2, 0)
    a = robot_period(inputs([], jump=(0.3, -0.2)), Memory(mem, Exchange(0)), PARAMS,
                     _workspace(4))
    b = robot_period(inputs([]), Memory(moved_estimate(mem, 0.3, -0.2), Exchange(0)), PARAMS,
                     _workspace(4))
    assert a == b


def test_the_period_sends_the_set_points_the_law_made_and_remembers_them():
    out = robot_period(inputs([]), Memory(LawMemory(wheel_r=1.0, wheel_l=1.2), Exchange(0)),
                       PARAMS, _workspace(4))
    assert (out.right, out.left) == (out.memory.law.wheel_r, out.memory.law.wheel_l)
    assert (out.right, out.left) != (1.0, 1.2)
    # an ideal robot (the batch simulator's) has no wheels to remember: its set-points are
    # those of its command
    ideal = PeriodParams.of(ControlParams(), None, 8.0, 0.5, 0.1)
    out = robot_period(inputs([]), Memory(LawMemory(), Exchange(0)), ideal, _workspace(4))
    assert (out.memory.law.wheel_r, out.memory.law.wheel_l) == (0.0, 0.0)
    assert (out.right, out.left) == wheel_command(out.v, out.u, 1.0, 1.0, math.inf)


def test_the_partner_s_newest_report_is_found_by_its_id_in_any_row():
    """Robot 0 asked robot 2 for its place 2; robot 2's newest report (out of range, in
    row 0) shows it in place 0, given: robot 0 takes place 2."""
    rows = [(2, NOW - 0.1, 50.0, 0.0, 0.0, 0.0, 0.0), (1, NOW, 30.0, 0.0, 0.0, 0.0, 0.0)]
    inp = inputs(rows)
    rep = inp.reports._replace(slot=[0, 1], partner=[0, NOBODY], other=[2, NOBODY])
    asking = Exchange(0, 2, 2, False, 9.9)
    out = robot_period(inp._replace(reports=rep), Memory(LawMemory(), asking), PARAMS,
                       _workspace(8))
    assert out.memory.exchange == Exchange(2, NOBODY, NOBODY, False, 10.0)
