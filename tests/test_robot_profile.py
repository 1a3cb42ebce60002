"""Robot profiles (robots/*.toml): the shipped ones load with the limits they claim, bad ones
are refused naming the file and the field, and sim and plant take them."""
import json
from pathlib import Path

import pytest

from agent.config import RobotParams
from common.schema import ConfigError
from hil.cli import main
from hil.files.robot_profile import load_robot_profile

ROOT = Path(__file__).resolve().parent.parent
ROBOTS = ROOT / "robots"


@pytest.mark.parametrize("name, speed, accel", [("cart", 3.0, 2.0), ("fast", 6.0, 6.0)])
def test_real_robots_have_the_speed_and_acceleration_they_claim(name, speed, accel):
    robot = load_robot_profile(ROBOTS / f"{name}.toml")
    assert robot.v_wheel_max == pytest.approx(speed, rel=0.01)     # m/s
    assert robot.a_max == pytest.approx(accel, rel=0.01)           # m/s^2


def test_the_ideal_profile_is_the_sitl_default_robot():
    assert load_robot_profile(ROBOTS / "ideal.toml") == RobotParams()


@pytest.mark.parametrize("text, named", [
    ("[robot]\nwheel_ramp = -1.0\n", "wheel_ramp"),
    ("[robot]\nwheel_radius = 'big'\n", "wheel_radius"),
    ("[robot]\nwheels = 2\n", "wheels"),
    ("colour = 'red'\n[robot]\n", "colour"),
    ("name = 'x'\n", "[robot]"),
    ("[robot\n", "not valid TOML"),
])
def test_a_bad_profile_is_refused_naming_the_file_and_the_field(tmp_path, text, named):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match="bad.toml") as err:
        load_robot_profile(path)
    assert named in str(err.value)


def test_sim_with_a_profile_runs_the_wheel_plant_with_its_limits(tmp_path):
    out = tmp_path / "run"
    code = main(["sim", str(ROOT / "scenarios" / "paper.toml"), "--out", str(out),
                 "--robot", str(ROBOTS / "cart.toml"), "--duration", "1", "--record-every",
                 "0"])
    metrics = json.loads((out / "metrics.json").read_text())
    assert code == (0 if metrics["collisions"] == 0 else 1)
    assert metrics["plant"] == "wheels"
    assert metrics["robot"]["wheel_ramp"] == 3.86


def test_plant_refuses_a_bad_profile_before_starting(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[robot]\nwheel_base = 0\n")
    code = main(["plant", "sitl", "--scenario", str(ROOT / "scenarios" / "paper.toml"),
                 "--robot", str(bad), "--swarm", "x", "--zenoh-connect", "tcp/127.0.0.1:1"])
    assert code == 2
    assert "bad.toml" in capsys.readouterr().err
