"""The boundswarm CLI end to end, in-process (main(argv)), and its exit codes."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hil.cli import main
from hil.cli.plant import as_subcommand
from hil.files.figures import FIGURE_FILES
from hil.files.run_folder import read_run

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ROOT / "scenarios"
DESIGN_KEYS = {"scenario", "robots", "duration", "min_pair_distance", "min_obstacle_clearance",
               "max_abs_v", "max_abs_u", "converged", "convergence_time",
               "final_max_tracking_error", "collisions", "stuck_robots", "mode_switches"}


def test_sim_writes_a_complete_run_folder_and_report_redraws_it(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["sim", str(SCENARIOS / "paper.toml"), "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert DESIGN_KEYS <= set(metrics)
    assert metrics["scenario"] == "paper" and metrics["robots"] == 9 and metrics["converged"]
    for name in FIGURE_FILES:
        assert (out / "figures" / name).stat().st_size > 10_000
    traj = np.loadtxt(out / "trajectories.csv", delimiter=",", skiprows=1)
    assert traj.shape == (9 * 1001, 10)
    assert (out / "trajectories.csv").open().readline().strip() == \
        "t,id,x,y,theta,v,u,mode,x_d,y_d"
    data = read_run(out)
    assert data.pose.shape == (1001, 9, 3) and list(data.ids) == list(range(1, 10))
    assert abs(np.linalg.norm(data.pose[-1, :, :2] - data.ref[-1], axis=1).max()
               - metrics["final_max_tracking_error"]) < 1e-3
    text = capsys.readouterr().out
    assert "convergence time" in text and "metrics.json" in text

    for name in FIGURE_FILES:
        (out / "figures" / name).unlink()
    assert main(["report", str(out)]) == 0
    assert all((out / "figures" / name).exists() for name in FIGURE_FILES)


def test_bad_scenario_exits_2_naming_the_field(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text((SCENARIOS / "paper.toml").read_text().replace("K = 4.0", "K = 40.0"))
    assert main(["sim", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "period" in err
    assert not (tmp_path / "o").exists()


def test_report_on_a_folder_that_is_not_a_run(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "scenario.toml" in capsys.readouterr().err


def test_sim_warns_when_data_this_old_make_the_places_walls(tmp_path, capsys):
    """Fast robots whose law speeds up at their wheels' full ramp, 5 m apart in a circle
    moving at 3 m/s: on a 0.5 s link the governor's discs close the gaps between places
    (docs/controller.md A10, A17), and sim says so before it runs; on a prompt link it
    does not."""
    robots = "".join(f"[[robots]]\nid = {i + 1}\npose = [{-20.0 - 3 * i}, 0.0, 0.0]\n"
                     for i in range(4))
    for delay, warned in ((0.5, True), (0.0, False)):
        sc = tmp_path / f"walls-{delay}.toml"
        sc.write_text(f'name = "walls"\nduration = 1.0\n[formation]\nkind = "circle"\n'
                      f'spacing = 5.0\nvelocity = [3.0, 0.0]\n[world]\n'
                      f'link_delay = {delay}\n{robots}')
        assert main(["sim", str(sc), "--robot",
                     str(ROOT / "campaigns" / "profiles" / "fast-ramp.toml"),
                     "--out", str(tmp_path / f"o{delay}"), "--record-every", "0"]) == 0
        out = " ".join(capsys.readouterr().out.split())
        assert ("places are as close as 5.00 m" in out) == warned, out
        assert ('([formation] assign = "shortest")' in out) == warned
        assert "a robot driving beside it at the places' 3.00 m/s" in out


def test_metrics_only_run(tmp_path):
    out = tmp_path / "m"
    assert main(["sim", str(SCENARIOS / "head_on_swap.toml"), "--out", str(out),
                 "--record-every", "0", "--duration", "2"]) == 0
    assert json.loads((out / "metrics.json").read_text())["duration"] == 2.0
    assert not (out / "figures").exists()


def test_sitl_refuses_bad_options_before_starting_anything(tmp_path, capsys):
    out = tmp_path / "o"
    args = ["sitl", str(SCENARIOS / "sitl_small.toml"), "--out", str(out), "--no-live"]
    assert main(args + ["--near-radius", "3"]) == 2
    assert "--near-radius must be 0 or at least the sensing range" in capsys.readouterr().err
    assert main(args + ["--mavlink-key", str(tmp_path / "missing.key")]) == 2
    err = capsys.readouterr().err
    assert "--mavlink-key" in err and "missing.key" in err
    assert not out.exists()


# --- exit codes: 2 for bad input only, 1 and one line for anything else -----------------
def test_a_bad_agent_config_exits_2_naming_the_field(tmp_path, capsys):
    bad = tmp_path / "agent.toml"
    bad.write_text('robot_id = 300\nswarm = "x"\ninitial_pose = [0.0, 0.0, 0.0]\n')
    assert main(["agent", "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "robot_id" in err and "Traceback" not in err


def test_a_missing_file_exits_2_naming_it(tmp_path, capsys):
    missing = tmp_path / "nowhere.toml"
    assert main(["sim", str(missing), "--out", str(tmp_path / "o")]) == 2
    assert str(missing) in capsys.readouterr().err
    assert main(["router", "--config", str(tmp_path / "nowhere.json5")]) == 2
    assert "nowhere.json5" in capsys.readouterr().err


def test_an_invalid_option_value_exits_2_naming_the_option(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["plant", "drivers", "--rate", "5"])
    assert exc.value.code == 2 and "--rate" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["mission", "--scenario", "x.toml", "--swarm", "a/b", "--connect", "tcp/x:1"])
    assert exc.value.code == 2 and "--swarm" in capsys.readouterr().err


@pytest.mark.parametrize("error", [ValueError("operands could not be broadcast\ntogether"),
                                   OSError(28, "No space left on device")])
def test_an_internal_error_exits_1_with_one_line_and_no_traceback(tmp_path, capsys,
                                                                  monkeypatch, error):
    """A bug (here a ValueError or an OSError from inside the simulator) is not the user's
    input: exit 1, one line naming the error, no traceback."""
    from firmware_sim import batch

    def broken(*args, **kwargs):
        raise error
    monkeypatch.setattr(batch, "simulate", broken)
    assert main(["sim", str(SCENARIOS / "paper.toml"), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("boundswarm sim: failed: ") and type(error).__name__ in err


def test_verbose_adds_the_traceback_of_an_internal_error(tmp_path, capsys, monkeypatch):
    from firmware_sim import batch

    def broken(*args, **kwargs):
        raise KeyError("k")
    monkeypatch.setattr(batch, "simulate", broken)
    assert main(["-v", "sim", str(SCENARIOS / "paper.toml"), "--out", str(tmp_path / "o")]) == 1
    assert "Traceback" in capsys.readouterr().err


def test_a_bus_that_cannot_be_opened_exits_1_without_traceback():
    """As a user runs it (a process): a CAN bus that cannot be opened is the machine's
    failure, not bad input."""
    proc = subprocess.run([sys.executable, "-m", "hil.cli", "plant", "drivers",
                           "--can-interface", "socketcan", "--can-channel", "nocan9"],
                          cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1
    assert "nocan9" in proc.stderr


# --- plant: three programs -------------------------------------------------------------
@pytest.mark.parametrize("argv, expected", [
    (["plant", "--drivers-only", "--rate", "300"], ["plant", "drivers", "--rate", "300"]),
    (["-v", "plant", "--can-port", "9", "--world-only"], ["-v", "plant", "world", "--can-port",
                                                          "9"]),
    (["plant", "sitl", "--scenario", "s"], ["plant", "sitl", "--scenario", "s"]),
    (["sim", "plant", "--drivers-only"], ["sim", "plant", "--drivers-only"]),
])
def test_the_flag_forms_of_plant_are_its_subcommands(argv, expected):
    assert as_subcommand(argv) == expected


def test_plant_options_belong_to_their_program(capsys):
    """Each program takes only its own options: the SITL plant and the world have no
    --rate, the drivers no --scenario."""
    for argv in (["plant", "sitl", "--scenario", "s", "--swarm", "x", "--zenoh-connect", "e",
                  "--rate", "300"],
                 ["plant", "drivers", "--scenario", "s"],
                 ["plant", "--world-only", "--scenario", "s", "--swarm", "x", "--zenoh-connect",
                  "e", "--rate", "300"]):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2 and "unrecognized arguments" in capsys.readouterr().err


def test_plant_drivers_with_zenoh_needs_robot_and_swarm(capsys):
    assert main(["plant", "drivers", "--can-interface", "virtual", "--can-channel", "t",
                 "--zenoh-connect", "tcp/127.0.0.1:1"]) == 2
    assert "--robot and --swarm" in capsys.readouterr().err


def test_drivers_flags_take_their_defaults_and_bounds_from_the_settings_schema(capsys):
    """`plant drivers`' limits are RobotParams' and CanSettings' fields: their defaults and
    units in the help, a value out of their bounds refused naming the setting."""
    from agent.config import RobotParams
    from hil.cli import main

    with pytest.raises(SystemExit):
        main(["plant", "drivers", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert f"[rev/s] (default: {RobotParams().wheel_speed_limit})" in help_text
    assert f"[rev/s^2] (default: {RobotParams().wheel_ramp})" in help_text
    code = main(["plant", "drivers", "--can-interface", "virtual", "--vel-limit", "-1"])
    assert code == 2
    assert "wheel_speed_limit" in capsys.readouterr().err
