"""The boundswarm CLI end to end, in-process (main(argv))."""
import json
from pathlib import Path

import numpy as np

from hil.cli import main
from hil.figures import FIGURE_FILES
from hil.run_folder import read_run

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"
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
