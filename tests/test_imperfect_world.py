"""The imperfect world of the batch simulator ([world]): each imperfection shows its effect,
runs are reproducible from their seed, and bad values are refused by name."""
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from agent.neighbours import Reports
from common import drivers
from firmware_sim import world_step
from firmware_sim.batch import SimOptions, simulate
from firmware_sim.mocap_sim import MocapParams, Outage
from firmware_sim.plant import PlantKind
from firmware_sim.world import Kill, WorldParams
from hil.cli import main
from hil.cli.exit_codes import EXIT_BAD_INPUT, EXIT_OK
from hil.files.robot_profile import load_robot_profile
from hil.files.scenario import ScenarioError, load_scenario, parse_scenario

ROOT = Path(__file__).resolve().parent.parent
PAPER = load_scenario(ROOT / "scenarios" / "paper.toml")
CART = load_robot_profile(ROOT / "robots" / "cart.toml")


def run(world=None, robot=None, plant=PlantKind.WHEELS, duration=20.0, record_every=0,
        governor=True, mocap=None):
    sc = PAPER
    return simulate(sc.ids, sc.poses, sc.formation, sc.obstacles,
                    dataclasses.replace(sc.control, governor=governor), robot or sc.robot,
                    SimOptions(duration=duration, plant=plant, record_every=record_every),
                    world=world, mocap=mocap)


def summary(result):
    return result.metrics.summary("paper", 20.0)


def test_a_scenario_without_world_is_the_ideal_world():
    assert PAPER.world == WorldParams() and PAPER.world.ideal
    a = summary(run(None, plant=PlantKind.IDEAL))
    b = summary(run(WorldParams(seed=9), plant=PlantKind.IDEAL))    # the seed alone: ideal
    assert a == b
    assert a["convergence_time"] == pytest.approx(7.32)
    assert a["min_pair_distance"] == pytest.approx(1.9707, abs=1e-4)
    assert a["max_pose_error"] == 0.0


def test_link_delay_makes_the_governor_work_harder():
    """The grid scenario with the fast robot speeding up at its wheels' ramp (6 m/s,
    6 m/s^2, no speed_up or turn_up): with neighbour states 0.3 s old the safety governor
    must lower the speed in a quarter again as many periods as with fresh ones, and the
    robots pass each other wider (the discs it keeps clear of grow with the data's age)."""
    sc = load_scenario(ROOT / "scenarios" / "grid.toml")
    fast = load_robot_profile(ROOT / "campaigns" / "profiles" / "fast-ramp.toml")

    def metrics(delay):
        r = simulate(sc.ids, sc.poses, sc.formation, sc.obstacles, sc.control, fast,
                     SimOptions(duration=20.0, plant=PlantKind.WHEELS, record_every=0),
                     world=WorldParams(link_delay=delay))
        return r.metrics.summary("grid", 20.0)

    fresh, late = metrics(0.0), metrics(0.3)
    assert late["governor_share"] > 1.25 * fresh["governor_share"]
    assert late["min_pair_distance"] > fresh["min_pair_distance"] > sc.control.a


def test_a_killed_robot_stands_still_after_its_watchdog_and_braking():
    at = 3.0
    result = run(WorldParams(kill=(Kill(robot=3, at=at),)), robot=CART, duration=10.0,
                 record_every=1)
    i = int(np.flatnonzero(PAPER.ids == 3)[0])
    speed = np.hypot(*np.diff(result.pose[:, i, :2], axis=0).T) / PAPER.control.period
    t = result.t[1:]
    assert speed[(t > at - 1.0) & (t <= at)].max() > 1.0              # moving when killed
    stop = at + drivers.WATCHDOG + CART.drive_latency + CART.v_wheel_max / CART.a_max
    assert speed[t > stop + 0.05].max() < 1e-9                        # then stands still
    assert summary(result)["killed_robots"] == [3]


def test_wheel_slip_makes_odometry_drift_from_truth():
    slipping = summary(run(WorldParams(seed=1, wheel_slip=0.05)))
    noisy = summary(run(WorldParams(seed=1, encoder_noise=0.001)))
    assert slipping["max_pose_error"] > 1.0
    assert 0.0 < noisy["max_pose_error"] < 0.5
    assert summary(run(WorldParams(seed=1)))["max_pose_error"] == 0.0


def test_motion_capture_fixes_hold_the_pose_on_slipping_wheels():
    """The agent's estimator in the batch: with fixes at 100 Hz (1 cm noise, 20 ms late,
    5 % lost) the robots know where they are to a few centimetres on 5 % slip, where
    odometry alone is metres off; the same seed gives the same run."""
    world = WorldParams(seed=1, wheel_slip=0.05)
    mocap = MocapParams(rate=100.0, noise=0.01, latency=0.02, dropout=0.05)
    alone = summary(run(world, robot=CART))
    fused = summary(run(world, robot=CART, mocap=mocap))
    assert alone["max_pose_error"] > 1.0
    assert 0.0 < fused["max_pose_error"] < 0.1
    assert fused == summary(run(world, robot=CART, mocap=mocap))
    assert fused["pose_failsafe_robots"] == []
    assert fused["min_pair_distance"] > PAPER.control.a
    # without slip or encoder noise the robots know their pose: fixes change nothing
    ideal = WorldParams(seed=1)
    assert summary(run(ideal, robot=CART, mocap=mocap)) == summary(run(ideal, robot=CART))


def test_fix_noise_does_not_become_a_heading_rate():
    """A line of 8 carts in a sparse field, 5 % slip, fixes with 2 mm of noise: each fix's
    correction must not enter the error's finite difference (agent.law.moved_estimate).
    It would make a heading rate of tenths of a rad/s, and the governor, braking for the
    turn, would hold the carts behind their slots for the whole run."""
    from hil.campaign.families import family_doc
    from hil.files.scenario import parse_scenario
    doc = family_doc({"kind": "line", "robots": 8, "field": "sparse"}, 0, duration=120.0,
                     top_speed=CART.v_wheel_max)
    sc = parse_scenario(doc, "line")
    mocap = MocapParams(noise=0.002, heading_noise=0.0, latency=0.0)
    m = simulate(sc.ids, sc.poses, sc.formation, sc.obstacles, sc.control, CART,
                 SimOptions(duration=120.0, plant=PlantKind.WHEELS, record_every=0),
                 world=WorldParams(seed=291980234, wheel_slip=0.05),
                 mocap=mocap).metrics.summary("line", 120.0)
    assert m["max_pose_error"] < 0.05
    assert m["governor_share"] < 0.15
    assert m["converged"]


def test_the_governor_keeps_the_pose_uncertainty_clear(monkeypatch):
    """Every hazard grows by the robot's position uncertainty: made 2 m, the robots keep
    about 2 m more from the obstacles' surfaces than at 0 m."""
    from firmware_sim import batch_pose
    step = batch_pose.BatchPoseSource.step

    def clearance(u):
        def uncertain(self, *args):
            out = step(self, *args)
            out[:, 3] = u
            return out
        monkeypatch.setattr(batch_pose.BatchPoseSource, "step", uncertain)
        return summary(run(WorldParams(seed=1, wheel_slip=0.01), robot=CART, duration=40.0,
                           mocap=MocapParams()))["min_obstacle_clearance"]

    a = PAPER.control.a
    assert clearance(0.0) < a + 1.0
    assert clearance(2.0) > a + 1.9


def test_a_robot_whose_fixes_stop_holds_and_stops():
    """Robot 5's fixes stop at 4 s: once its last fix is older than fix_timeout it is held
    (failsafe HOLD, as its agent) and comes to rest within its braking distance."""
    mocap = MocapParams(rate=50.0, fix_timeout=0.5,
                        outage=(Outage(robot=5, at=4.0, duration=30.0),))
    result = run(WorldParams(seed=1, wheel_slip=0.03), robot=CART, duration=10.0,
                 record_every=1, mocap=mocap)
    assert summary(result)["pose_failsafe_robots"] == [5]
    i = int(np.flatnonzero(PAPER.ids == 5)[0])
    speed = np.hypot(*np.diff(result.pose[:, i, :2], axis=0).T) / PAPER.control.period
    t = result.t[1:]
    held = 4.0 + 0.5 + PAPER.control.period
    assert speed[(t > held - 1.0) & (t <= held - 0.1)].max() > 0.5       # moving, then
    stop = held + CART.drive_latency + CART.v_wheel_max / CART.a_max
    assert speed[t > stop + 0.05].max() < 1e-3                          # at rest


def test_a_world_is_reproducible_from_its_seed():
    world = WorldParams(seed=4, link_delay=0.1, link_jitter=0.05, link_loss=0.2,
                        loss_burst=3.0, wheel_slip=0.02, detection_noise=0.1)
    a, b = summary(run(world, duration=6.0)), summary(run(world, duration=6.0))
    c = summary(run(dataclasses.replace(world, seed=5), duration=6.0))
    assert a == b
    assert a != c


def losses(loss, burst, steps=40_000, seed=2):
    """The loss pattern of one robot's states over ``steps`` periods."""
    hist, arrive = np.zeros((3, 1, 9)), np.zeros((3, 1))
    bad, lost = np.zeros(1, np.int64), np.zeros(steps, bool)
    est, cmd, alive = np.zeros((1, 3)), np.zeros((1, 3)), np.ones(1, bool)
    places = np.zeros((1, 3), np.int64)
    for step in range(steps):
        world_step.publish(step, 0.02, est, cmd, places, alive, seed, 0.0, 0.0, loss, burst,
                           bad, hist, arrive)
        lost[step] = math.isinf(arrive[step % 3, 0])
    edges = np.flatnonzero(np.diff(np.r_[0, lost.astype(int), 0]))
    runs = edges[1::2] - edges[::2]
    return lost.mean(), runs.mean()


@pytest.mark.parametrize("burst", [2.0, 5.0])
def test_loss_bursts_have_the_configured_mean_length(burst):
    fraction, mean_burst = losses(0.2, burst)
    assert fraction == pytest.approx(0.2, abs=0.02)
    assert mean_burst == pytest.approx(burst, rel=0.1)


def test_independent_losses_are_not_bursty():
    fraction, mean_burst = losses(0.2, 1.0)
    assert fraction == pytest.approx(0.2, abs=0.02)
    assert mean_burst == pytest.approx(1 / 0.8, rel=0.05)     # runs of a Bernoulli process


def test_delivered_states_arrive_late_and_turn_stale():
    """A robot moving at 1 m/s along x, its states 0.1 s late: the others see the newest
    state that arrived, extrapolated to now; once it stops publishing, its last position,
    stale after the staleness limit; its place exchange's state (slot, partner, other)
    arrives with it."""
    T, delay = 0.02, 0.1
    hist, arrive = np.zeros((8, 1, 9)), np.full((8, 1), np.inf)
    view = Reports(np.zeros(1, np.int64), np.full(1, -np.inf), *np.zeros((5, 1)),
                   *np.zeros((3, 1), np.int64))
    seen = np.zeros((1, 3))
    places = np.array([[3, 7, 5]])
    bad, cmd = np.zeros(1, np.int64), np.array([[1.0, 0.0, 0.0]])
    for step in range(30):
        t = step * T
        world_step.deliver(t, hist, arrive, view, 0.5, seen)
        if step < 5:
            assert seen[0, 2] == world_step.NONE                      # nothing arrived yet
        else:
            assert view.stamp[0] == pytest.approx(t - delay)          # the newest arrived
            assert seen[0, :2] == pytest.approx([t, 0.0])             # extrapolated to now
            assert seen[0, 2] == world_step.FRESH
            assert [view.slot[0], view.partner[0], view.other[0]] == [3, 7, 5]
        world_step.publish(step, T, np.array([[t, 0.0, 0.0]]), cmd, places, np.ones(1, bool),
                           0, delay, 0.0, 0.0, 1.0, bad, hist, arrive)
    last = view.stamp[0]
    for step in range(30, 80):                                        # dead: nothing sent
        world_step.publish(step, T, np.zeros((1, 3)), cmd, places, np.zeros(1, bool), 0,
                           delay, 0.0, 0.0, 1.0, bad, hist, arrive)
        world_step.deliver(step * T, hist, arrive, view, 0.5, seen)
    assert view.stamp[0] == pytest.approx(29 * T)
    assert last < view.stamp[0]
    assert seen[0, 2] == world_step.STALE and seen[0, 0] == pytest.approx(29 * T)


def test_detections_drop_out_and_scatter():
    noise, dropout, steps = 0.2, 0.3, 4000
    kept, dx = 0, []
    for step in range(steps):
        o_x, o_y, o_r = np.array([5.0]), np.array([0.0]), np.array([2.0])
        o_k = np.array([0])
        if world_step.detect(7, step, 3, noise, dropout, 1, o_x, o_y, o_r, o_k):
            kept += 1
            dx.append(o_x[0] - 5.0)
    assert kept / steps == pytest.approx(1 - dropout, abs=0.03)
    assert np.std(dx) == pytest.approx(noise, rel=0.1)


def _doc(world):
    doc = {"name": "w", "duration": 1.0, "robots": [{"id": 1, "pose": [0, 0, 0]},
                                                      {"id": 2, "pose": [5, 0, 0]}]}
    doc["world"] = world
    return doc


@pytest.mark.parametrize("world, named", [
    ({"link_loss": 2.0}, "WorldParams.link_loss"),
    ({"link_delay": "fast"}, "WorldParams.link_delay"),
    ({"lag": 1.0}, "unknown field(s) lag"),
    ({"kill": [{"robot": 9, "at": 1.0}]}, "[world.kill][0].robot"),
    ({"kill": [{"robot": 1}]}, "[world.kill][0]: Kill.at: missing"),
    ({"link_loss": 0.5, "loss_burst": 0.5}, "WorldParams.loss_burst"),
])
def test_bad_world_values_are_refused_by_name(world, named):
    with pytest.raises(ScenarioError) as err:
        parse_scenario(_doc(world), "s.toml")
    assert "s.toml" in str(err.value) and named in str(err.value)


def test_sim_takes_the_wheels_plant_for_odometry(tmp_path, capsys):
    scenario = tmp_path / "slip.toml"
    scenario.write_text((ROOT / "scenarios" / "paper.toml").read_text()
                        + "\n[world]\nwheel_slip = 0.01\n")
    assert main(["sim", str(scenario), "--out", str(tmp_path / "run"), "--duration", "1",
                 "--record-every", "0"]) == EXIT_OK
    assert '"plant": "wheels"' in (tmp_path / "run" / "metrics.json").read_text()
    assert main(["sim", str(scenario), "--out", str(tmp_path / "run2"), "--plant", "ideal",
                 "--duration", "1"]) == EXIT_BAD_INPUT
    assert "wheel slip" in capsys.readouterr().err
