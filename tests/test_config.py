import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from agent.braking import braking_speed
from agent.config import CONTROL_PARAMS, ControlParams, RobotParams
from agent.envelope import speed_envelope
from common.schema import ConfigError, add_arguments, fields, from_table, section_from_args


def test_paper_defaults():
    p = ControlParams()
    assert (p.K, p.K_theta, p.D_max, p.K_ij, p.a, p.b, p.c) == (4, 3, 3, 3, 1, 2, 4)
    assert p.period_bound == pytest.approx(1 / 24)
    assert p.v_max == 12.0


def test_period_breaking_the_bound_is_refused_with_the_numbers():
    with pytest.raises(ConfigError) as exc:
        ControlParams(period=0.05)
    msg = str(exc.value)
    assert "ControlParams.period: period 0.05" in msg and "0.0417" in msg
    assert "(b - a)/(2 K D_max)" in msg


def test_lower_gains_allow_a_longer_period():
    assert ControlParams(period=0.1, K=1.0, D_max=2.0).period == 0.1


@pytest.mark.parametrize("kw, field", [({"a": 2.5}, "a < b < c"), ({"K": -1.0}, "K"),
                                       ({"period": 0.0}, "period"),
                                       ({"hysteresis": float("nan")}, "hysteresis")])
def test_bad_values_name_the_field(kw, field):
    with pytest.raises(ConfigError, match=field):
        ControlParams(**kw)


def test_from_table_refuses_unknown_and_non_numbers():
    with pytest.raises(ConfigError, match=r"x.toml \[control\]: unknown field\(s\) Kp"):
        from_table(ControlParams, {"Kp": 1.0}, "x.toml [control]")
    with pytest.raises(ConfigError, match=r"x.toml \[control\]: ControlParams.K: expected a "
                                          r"number, got '4'"):
        from_table(ControlParams, {"K": "4"}, "x.toml [control]")
    with pytest.raises(ConfigError, match=r"x.toml \[robot\]: RobotParams.wheel_radius: must "
                                          r"be > 0 \[m\], got 0.0"):
        from_table(RobotParams, {"wheel_radius": 0}, "x.toml [robot]")
    assert from_table(ControlParams, {"K": 2}, "t").K == 2.0


def test_the_speed_envelope_states_what_the_governor_allows():
    cart = RobotParams(wheel_radius=0.0825, wheel_speed_limit=5.79, wheel_ramp=3.86,
                       drive_latency=0.02)
    free = speed_envelope(ControlParams(), cart, 8.0, 0.05)
    assert free.top == pytest.approx(3.0, abs=0.01) and free.head_on > free.top
    assert "never limits" in free.describe()
    slow = speed_envelope(ControlParams(), RobotParams(wheel_ramp=5.0), 8.0, 0.05)
    # 12 m/s top, 6.3 m/s^2: each robot owns (8 - 1)/2 - 12 * 0.05 = 2.9 m
    assert slow.head_on == pytest.approx(braking_speed(2.9, 2 * math.pi * 0.2 * 5.0, 0.02))
    assert "limits the robot to" in slow.describe()


@pytest.mark.parametrize("profile, old_apart", [("cart", (2.5, 5.0)), ("fast", (2.5, 5.0))])
def test_the_envelope_says_how_far_apart_robots_at_the_pace_must_be_to_pass_between(
        profile, old_apart):
    """A robot beside another, both at the places' pace (half the top speed): its disc is
    a (and a little) on fresh data and grows with the data's age; a robot passes between
    two such robots only more than two discs apart. With 0.5 s old data, places 5 m apart
    let a cart through, and the fast profile, whose law speeds it and its turn up slower
    than its wheels can (docs/controller.md A17; without that, 6.5 m)."""
    from hil.files.robot_profile import load_robot_profile
    robot = load_robot_profile(Path(__file__).resolve().parent.parent / "robots"
                               / f"{profile}.toml")
    p = ControlParams()
    pace = 0.5 * min(p.v_max, robot.v_wheel_max)
    fresh = speed_envelope(p, robot, 10.0, p.period, pace)
    old = speed_envelope(p, robot, 10.0, 0.5 + p.period, pace)
    assert p.a < fresh.beside < old.beside
    assert fresh.passable == pytest.approx(2 * fresh.beside) and fresh.passable < 2.6
    assert old_apart[0] < old.passable < old_apart[1]
    assert f"more than {old.passable:.2f} m apart" in old.describe()


def test_every_field_is_documented_with_a_unit():
    for f in fields(ControlParams) + fields(RobotParams):
        assert f.doc, f.name
        if f.type is bool:                  # a switch has no unit
            assert isinstance(f.default, bool), f.name
        elif f.type is str:                 # a choice has its choices
            assert f.default in f.meta["choices"], f.name
        else:
            assert f.unit and isinstance(f.default, float), f.name


def test_control_params_as_runtime_parameters():
    names = [p.name for p in CONTROL_PARAMS]
    assert names == ["BS_K", "BS_K_THETA", "BS_D_MAX", "BS_K_IJ", "BS_A", "BS_B", "BS_C",
                     "BS_PERIOD", "BS_U_MAX", "BS_HYST", "BS_EXCHANGE"]
    # every numeric field, in order; the switches and the law's name are no runtime
    # parameters
    switches = ("governor", "sidestep", "pair_hysteresis", "law")
    assert [p.field for p in CONTROL_PARAMS] == [f.name for f in dataclasses.fields(ControlParams)
                                                 if f.name not in switches]
    assert [p.index for p in CONTROL_PARAMS] == list(range(len(names)))
    period = CONTROL_PARAMS[names.index("BS_PERIOD")]
    assert period.read_only and "read-only at runtime" in period.read_only
    assert all(p.read_only is None for p in CONTROL_PARAMS if p is not period)
    k = CONTROL_PARAMS[0]
    assert (k.unit, k.lo, k.hi) == ("1/s", 0.0, None) and "translational gain" in k.doc


def test_flags_derived_from_a_section():
    parser = argparse.ArgumentParser()
    add_arguments(parser, RobotParams, prefix="robot-")
    helps = {a.dest: a.help for a in parser._actions}
    speed_help = helps["robot_wheel_speed_limit"]
    assert speed_help is not None and "[rev/s]" in speed_help
    assert "10.0" in parser.format_help()
    assert section_from_args(RobotParams, parser.parse_args([]), "robot-") == RobotParams()
    args = parser.parse_args(["--robot-wheel-ramp", "200", "--robot-wheel-radius", "0.1"])
    assert section_from_args(RobotParams, args, "robot-") == RobotParams(wheel_ramp=200.0,
                                                                          wheel_radius=0.1)
    with pytest.raises(ConfigError, match=r"--robot-wheel-base: must be > 0 \[m\]"):
        section_from_args(RobotParams, parser.parse_args(["--robot-wheel-base", "-1"]),
                          "robot-")
    with pytest.raises(SystemExit):
        parser.parse_args(["--robot-wheel-base", "wide"])


@pytest.mark.parametrize("room, trails", [(-0.5, True), (0.5, False)])
def test_the_envelope_says_how_close_behind_another_a_robot_keeps_the_pace(room, trails):
    """Two sporty robots in a convoy at 3.5 m/s on a 0.5 s link, starting in their places:
    with the places ``room`` [m] more than the envelope's following distance apart, the
    one behind keeps its place; with less, the governor holds it back and it trails its
    place by what is missing (closed loop, the batch simulator)."""
    from agent.formation import Formation
    from firmware_sim.batch import SimOptions, simulate
    from firmware_sim.plant import PlantKind
    from firmware_sim.world import Obstacles, WorldParams
    from hil.files.robot_profile import load_robot_profile
    robot = load_robot_profile(Path(__file__).resolve().parent.parent / "robots"
                               / "sporty.toml")
    p, pace, delay = ControlParams(), 3.5, 0.5
    follow = speed_envelope(p, robot, 10.0, delay + p.period, pace).follow
    assert 4.5 < follow < 6.0
    gap = follow + room
    form = Formation(np.array([[0.0, 0.0], [-gap, 0.0]]), (0.0, 0.0), (pace, 0.0))
    poses = np.array([[0.0, 0.0, 0.0], [-gap, 0.0, 0.0]])
    res = simulate(np.array([1, 2]), poses, form, Obstacles.empty(), p, robot,
                   SimOptions(duration=20.0, plant=PlantKind.WHEELS, record_every=10),
                   world=WorldParams(link_delay=delay))
    behind = res.ref[-1, 1, 0] - res.pose[-1, 1, 0]        # m, the rear robot's lag
    assert behind == pytest.approx(-room if trails else 0.0, abs=0.1)
