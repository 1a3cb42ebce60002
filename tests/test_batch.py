"""Closed-loop tests of the batch simulator on simulated time (deterministic)."""
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from agent.config import ControlParams, RobotParams
from agent.formation import Formation, FormationKind, formation_offsets
from firmware_sim.batch import SimOptions, simulate
from firmware_sim.plant import PlantKind
from firmware_sim.world import Obstacles
from hil.files.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"


def run(sc, **kw):
    opts = dict(duration=sc.duration, sensing_range=sc.sensing_range, substeps=sc.substeps,
                plant=sc.plant)
    opts.update(kw)
    res = simulate(sc.ids, sc.poses, sc.formation, sc.obstacles, sc.control, sc.robot,
                   SimOptions(**opts))
    return res, res.metrics.summary(sc.name, opts["duration"])


def test_paper_example():
    sc = load_scenario(SCENARIOS / "paper.toml")
    res, m = run(sc)
    p = sc.control
    assert m["converged"] and m["convergence_time"] <= 10.0
    assert m["min_pair_distance"] > p.a and m["min_obstacle_clearance"] > p.a
    assert m["max_abs_u"] <= p.u_max + 1e-9 and m["max_abs_v"] <= p.K * p.D_max + 1e-9
    assert m["collisions"] == 0
    # this implementation's published figures (docs/controller.md)
    assert m["convergence_time"] == pytest.approx(7.32)
    assert round(m["min_pair_distance"], 4) == 1.9707
    assert round(m["min_obstacle_clearance"], 2) == 1.95
    # robots trail their references by |p_d_dot|/K = 0.5 m in steady state
    assert m["final_max_tracking_error"] == pytest.approx(0.5, abs=0.01)
    assert {1, 2} <= set(np.unique(res.mode))           # obstacles were avoided/passed


def test_paper_example_under_the_paper_law():
    """law = "paper" (no sidestep, hysteresis per robot) reproduces the same figures."""
    sc = load_scenario(SCENARIOS / "paper.toml")
    sc = dataclasses.replace(sc, control=dataclasses.replace(sc.control, law="paper"))
    _, m = run(sc)
    assert m["convergence_time"] == pytest.approx(7.32)
    assert round(m["min_pair_distance"], 4) == 1.9707


def test_paper_example_with_wheel_limits():
    sc = load_scenario(SCENARIOS / "paper.toml")
    _, m = run(sc, plant=PlantKind.WHEELS)
    assert m["converged"] and m["collisions"] == 0 and m["min_pair_distance"] > 1.0


@pytest.mark.parametrize("name", ["head_on_swap", "narrow_gap", "wedge", "circle", "grid"])
def test_bundled_scenarios_converge_safely(name):
    sc = load_scenario(SCENARIOS / f"{name}.toml")
    _, m = run(sc)
    assert m["collisions"] == 0 and m["min_pair_distance"] > sc.control.a
    assert m["converged"], m["stuck_robots"]


@pytest.mark.parametrize("lateral", [0.0, 0.3, -1.0])
def test_head_on_swap_resolves(lateral):
    poses = np.array([[-10, 0, 0.0], [10, lateral, math.pi]])
    form = Formation(np.array([[10.0, 0], [-10.0, 0]]), (0.0, 0.0))
    res = simulate(np.array([1, 2]), poses, form, Obstacles.empty(),
                   ControlParams(exchange=0.0), RobotParams(), SimOptions(duration=20.0))
    m = res.metrics.summary("swap", 20.0)
    assert m["converged"] and m["min_pair_distance"] > 1.0
    assert res.pose[-1, 0, 0] > 9 and res.pose[-1, 1, 0] < -9   # they did swap


def test_robots_facing_each_others_places_exchange_them():
    """With place exchange (the default), the two robots of the head-on swap take each
    other's place where they stand instead of driving through each other."""
    poses = np.array([[-4, 0, 0.0], [4, 0.0, math.pi]])     # within sensing range
    form = Formation(np.array([[4.0, 0], [-4.0, 0]]), (0.0, 0.0))
    res = simulate(np.array([1, 2]), poses, form, Obstacles.empty(), ControlParams(),
                   RobotParams(), SimOptions(duration=5.0))
    m = res.metrics.summary("swap", 5.0)
    assert m["place_changes"] == 2 and m["shared_places"] == []
    assert m["converged"] and m["convergence_time"] < 1.0
    assert np.abs(res.pose[-1, :, 0] - poses[:, 0]).max() < 0.5   # they stayed


def test_pair_hysteresis_is_kept_across_periods():
    """Head on without the sidestep, hysteresis per pair: the batch simulator's held lists
    keep the pair active above b, so the swap resolves with few mode switches (held lists
    that forgot would be no hysteresis at all: over a thousand switches, no swap)."""
    poses = np.array([[-10, 0, 0.0], [10, 0.0, math.pi]])
    form = Formation(np.array([[10.0, 0], [-10.0, 0]]), (0.0, 0.0))
    res = simulate(np.array([1, 2]), poses, form, Obstacles.empty(),
                   ControlParams(sidestep=False, pair_hysteresis=True), RobotParams(),
                   SimOptions(duration=20.0))
    m = res.metrics.summary("swap", 20.0)
    assert m["converged"] and m["mode_switches"] < 100


def test_robots_starting_inside_each_others_avoidance_region_separate():
    poses = np.array([[0, 0, 0.0], [0.5, 1.2, 1.0], [1.0, -0.3, 2.0]])
    form = Formation(np.array([[0.0, 0], [0, 4], [0, -4]]), (20.0, 0.0))
    res = simulate(np.array([1, 2, 3]), poses, form, Obstacles.empty(), ControlParams(),
                   RobotParams(), SimOptions(duration=15.0))
    m = res.metrics.summary("inside", 15.0)
    assert res.mode[0].tolist() == [1, 1, 1]              # all start in AVOID
    assert m["collisions"] == 0 and m["min_pair_distance"] > 1.0 and m["converged"]


def sparse_field(rng, n, kind, c=4.0, b=2.0):
    """Robots left of a band of obstacles (gaps >= 2c), formation ending past the band."""
    obstacles: list[tuple[np.ndarray, float]] = []
    while len(obstacles) < 6:
        centre, r = rng.uniform([-10, -25], [25, 25]), rng.uniform(1.0, 3.5)
        if all(np.linalg.norm(centre - oc) - r - orr >= 2 * c for oc, orr in obstacles):
            obstacles.append((centre, r))
    poses: list[np.ndarray] = []
    while len(poses) < n:
        p = rng.uniform([-75, -30], [-35, 30])
        if all(np.linalg.norm(p - q[:2]) >= b for q in poses):
            poses.append(np.array([*p, rng.uniform(-math.pi, math.pi)]))
    spacing = 5.0            # >= 2 (b + hysteresis): a robot can pass between two others
    form = Formation(formation_offsets(kind, n, spacing), (-35.0, 0.0), (2.0, 0.0))
    return np.array(poses), form, Obstacles(np.array([o[0] for o in obstacles]),
                                            np.array([o[1] for o in obstacles]))


@pytest.mark.parametrize("seed, n, kind", [(1, 9, FormationKind.LINE),
                                           (2, 12, FormationKind.WEDGE),
                                           (3, 16, FormationKind.GRID),
                                           (4, 10, FormationKind.CIRCLE),
                                           (5, 30, FormationKind.GRID),
                                           (6, 30, FormationKind.LINE)])
def test_random_sparse_fields(seed, n, kind):
    rng = np.random.default_rng(seed)
    poses, form, obstacles = sparse_field(rng, n, kind)
    res = simulate(np.arange(1, n + 1), poses, form, obstacles, ControlParams(),
                   RobotParams(), SimOptions(duration=50.0, record_every=0))
    m = res.metrics.summary("field", 50.0)
    assert m["collisions"] == 0 and m["min_pair_distance"] > 1.0
    assert m["min_obstacle_clearance"] > 1.0
    assert m["converged"], f"not converged: {m['stuck_robots']}"


def test_deterministic():
    sc = load_scenario(SCENARIOS / "paper.toml")
    a, _ = run(sc, duration=3.0)
    b, _ = run(sc, duration=3.0)
    assert np.array_equal(a.pose, b.pose)


def test_progress_is_reported():
    sc = load_scenario(SCENARIOS / "paper.toml")
    seen: list[float] = []
    simulate(sc.ids, sc.poses, sc.formation, sc.obstacles, sc.control, sc.robot,
             SimOptions(duration=1.0), progress=seen.append)
    assert seen[0] == 0.0 and seen[-1] == 1.0 and seen == sorted(seen) and len(seen) > 10


def test_bad_options_are_refused():
    with pytest.raises(ValueError, match="duration"):
        SimOptions(duration=-1.0)
    sc = load_scenario(SCENARIOS / "paper.toml")
    with pytest.raises(ValueError, match="formation has 9 places for 2 robots"):
        simulate(sc.ids[:2], sc.poses[:2], sc.formation, sc.obstacles, sc.control, sc.robot,
                 SimOptions(duration=1.0))


@pytest.mark.parametrize("seed", [11, 12])
def test_cluttered_fields_never_collide(seed):
    """Obstacle gaps below 2b: best effort for convergence, but no collision ever."""
    rng = np.random.default_rng(seed)
    obstacles: list[tuple[np.ndarray, float]] = []
    while len(obstacles) < 14:
        centre, r = rng.uniform([-15, -20], [25, 20]), rng.uniform(1.0, 3.0)
        gaps = [np.linalg.norm(centre - oc) - r - orr for oc, orr in obstacles]
        if all(g >= 1.0 for g in gaps):               # narrow passages allowed
            obstacles.append((centre, r))
    n = 16
    poses = np.column_stack([rng.uniform(-60, -40, n), np.linspace(-20, 20, n),
                             np.zeros(n)])
    form = Formation(formation_offsets(FormationKind.GRID, n, 5.0), (-40.0, 0.0), (2.0, 0.0))
    obs = Obstacles(np.array([o[0] for o in obstacles]), np.array([o[1] for o in obstacles]))
    res = simulate(np.arange(1, n + 1), poses, form, obs, ControlParams(), RobotParams(),
                   SimOptions(duration=50.0, record_every=0))
    m = res.metrics.summary("cluttered", 50.0)
    assert m["collisions"] == 0 and m["min_pair_distance"] > 1.0
    assert m["min_obstacle_clearance"] > 1.0
    assert len(m["stuck_robots"]) <= n // 4             # most converge


@pytest.mark.parametrize("latency, still_periods", [(0.0, 0), (0.1, 5), (0.03, 1)])
def test_drive_latency_delays_the_wheels(latency, still_periods):
    """With the wheel plant a command reaches the wheels a drive latency after it was
    issued (in whole physics substeps: 0.03 s is 6 substeps of 5 ms, the first command moves
    the robot from the second period on); with the ideal plant there is none."""
    robot = RobotParams(drive_latency=latency)
    form = Formation(np.zeros((1, 2)), (30.0, 0.0))
    res = simulate(np.array([1]), np.zeros((1, 3)), form, Obstacles.empty(), ControlParams(),
                   robot, SimOptions(duration=0.2, plant=PlantKind.WHEELS))
    x = res.pose[:, 0, 0]
    assert np.all(x[:still_periods + 1] == 0.0) and x[still_periods + 1] > 0.0
    ideal = simulate(np.array([1]), np.zeros((1, 3)), form, Obstacles.empty(), ControlParams(),
                     robot, SimOptions(duration=0.2))
    assert ideal.pose[1, 0, 0] > 0.0


CART = RobotParams(wheel_radius=0.0825, wheel_base=0.8, wheel_speed_limit=5.79,
                   wheel_ramp=3.86, drive_latency=0.02)      # robots/cart.toml: 3 m/s, 2 m/s^2


def cart_run(pose, centre, velocity=(0.0, 0.0), duration=30.0):
    form = Formation(np.zeros((1, 2)), centre, velocity)
    return simulate(np.array([1]), np.array([pose], dtype=float), form, Obstacles.empty(),
                    ControlParams(), CART, SimOptions(duration=duration,
                                                      plant=PlantKind.WHEELS))


def test_a_cart_arrives_at_its_reference_without_overshooting():
    """At 3 m/s and 2 m/s^2 the paper's v = K |e| (a deceleration of K v = 12 m/s^2 asked)
    would carry the cart past its reference; the law closes in at what it can shed."""
    res = cart_run((0.0, 0.0, 0.0), (20.0, 0.0))
    x = res.pose[:, 0, 0]
    assert res.v.max() > 2.9                          # it drove at its top speed
    assert x.max() < 20.05 and abs(x[-1] - 20.0) < 0.05


def test_a_cart_follows_a_moving_reference_without_the_papers_lag():
    """The paper's law settles |p_d_dot|/K behind a moving reference (E9: 0.375 m at
    1.5 m/s); on a robot with a finite ramp the law follows the reference's velocity and
    closes the rest (controller.md A16), so the cart settles on it."""
    res = cart_run((0.0, 0.0, 0.0), (5.0, 2.0), (1.5, 0.0), duration=30.0)
    err = np.hypot(*(res.pose[:, 0, :2] - res.ref[:, 0]).T)
    assert err[res.t > 20.0].max() < 0.02


def test_a_cart_just_ahead_of_its_moving_reference_lets_it_catch_up():
    """A cart 0.3 m ahead of a reference that moves its way at 1 m/s: with the paper's
    heading atan2(-e) it would find the reference behind it, brake, turn round and
    overshoot again; following the reference's velocity it slows down, keeps its heading
    and lets the reference catch up (controller.md A16)."""
    res = cart_run((0.3, 0.0, 0.0), (0.0, 0.0), (1.0, 0.0), duration=10.0)
    err = np.hypot(*(res.pose[:, 0, :2] - res.ref[:, 0]).T)
    assert np.abs(res.pose[:, 0, 2]).max() < 0.05
    assert res.v.min() >= 0.0 and err[res.t > 5.0].max() < 0.02


def test_a_cart_turns_round_to_a_reference_behind_it_and_settles():
    """Facing away from a reference coming toward it: the cart turns, brakes as the
    reference passes, turns again and follows, its heading settling (no endless spin, as
    when braking took the whole ramp and left the turn rate frozen)."""
    res = cart_run((0.0, 0.0, 0.3), (-20.0, 0.0), (1.0, 0.0), duration=30.0)
    err = np.hypot(*(res.pose[:, 0, :2] - res.ref[:, 0]).T)
    late = res.t > 20.0
    assert err[late].max() < 1.0 / ControlParams().K + 0.25
    assert np.abs(res.u[late, 0]).max() < 0.05
    turned = np.abs(np.diff(np.unwrap(res.pose[:, 0, 2]))).sum()
    assert turned < 3 * math.pi                       # about two half turns, no spinning
