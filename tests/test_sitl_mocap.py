"""The SITL's simulated motion capture (firmware_sim.mocap_sim): the fixes it publishes, the
scenario's [mocap] table, and a short SITL run on slipping wheels with one robot's fixes
stopped (every process it started ended, pass or fail)."""
import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import alive

from common.payloads import FixMsg
from firmware_sim.mocap_sim import MocapParams, Outage, SimulatedMocap
from hil.files.scenario import ScenarioError, load_scenario

ROOT = Path(__file__).resolve().parent.parent


class _Robot:
    def __init__(self, robot_id, pose):
        self.robot_id, self.pose = robot_id, pose


def _capture(params, seconds, epoch=None, dt=0.005, t0=1000.0):
    """Fixes published by a system stepped every ``dt`` for ``seconds``: (time, FixMsg)."""
    got = []
    robots = [_Robot(1, (1.0, 2.0, 0.5)), _Robot(2, (-3.0, 4.0, -1.0))]
    mocap = SimulatedMocap(params, lambda rid, data: got.append((now, FixMsg.decode(data))),
                           lambda: epoch)
    for k in range(int(round(seconds / dt))):
        now = t0 + k * dt
        mocap.step(now, robots)
    return got, mocap


def test_fixes_come_at_the_rate_late_by_the_latency_with_the_noise():
    p = MocapParams(rate=100.0, noise=0.01, heading_noise=0.02, latency=0.03, seed=4)
    got, mocap = _capture(p, 10.0)
    one = [(t, m) for t, m in got if m.robot_id == 1]
    assert 990 <= len(one) <= 1001 and mocap.lost == 0
    late = np.array([t - m.stamp for t, m in one])
    assert late.min() >= 0.03 - 1e-9 and late.max() <= 0.03 + 0.005 + 1e-9
    xs = np.array([m.x for _, m in one])
    ths = np.array([m.theta for _, m in one])
    assert abs(xs.mean() - 1.0) < 0.002 and 0.009 < xs.std() < 0.011
    assert 0.018 < ths.std() < 0.022
    assert one[0][1].error == pytest.approx(0.03)             # three standard deviations
    assert [m.seq for _, m in one] == sorted(m.seq for _, m in one)


def test_dropouts_and_outages_lose_fixes():
    got, mocap = _capture(MocapParams(dropout=0.2, seed=1), 10.0)
    assert 0.17 < mocap.lost / (mocap.lost + mocap.published) < 0.23
    out = MocapParams(outage=(Outage(robot=2, at=3.0, duration=1.0),))
    got, _ = _capture(out, 10.0, epoch=1000.0)
    two = np.array([m.stamp for _, m in got if m.robot_id == 2]) - 1000.0
    assert not ((two >= 3.0) & (two < 4.0)).any()
    assert ((two > 2.9) & (two < 3.0)).any() and ((two >= 4.0) & (two < 4.1)).any()
    assert len([m for _, m in got if m.robot_id == 1]) > 990    # the others go on
    got, _ = _capture(out, 10.0, epoch=None)                    # no mission yet: no outage
    assert len([m for _, m in got if m.robot_id == 2]) > 990


SCENARIO = """name = "mocap_tiny"
duration = {duration}
[formation]
kind = "line"
spacing = 4.0
center0 = [0.0, 0.0]
velocity = [1.0, 0.0]
[[robots]]
id = 1
pose = [-6.0, -4.5, 0.0]
[[robots]]
id = 2
pose = [-6.5, 0.5, 0.0]
[[robots]]
id = 3
pose = [-6.0, 4.0, 0.0]
[world]
seed = 5
wheel_slip = 0.03
{mocap}
"""

MOCAP = """[mocap]
rate = 100.0
noise = 0.002
latency = 0.01
dropout = 0.05
fix_timeout = 0.5
[[mocap.outage]]
robot = 2
at = 3.0
duration = 1.0
"""


def _scenario(tmp_path, mocap=MOCAP, duration=8.0):
    path = tmp_path / "tiny.toml"
    path.write_text(SCENARIO.format(duration=duration, mocap=mocap))
    return path, load_scenario(path)


def test_the_mocap_table_is_checked_naming_file_and_field(tmp_path):
    _, sc = _scenario(tmp_path)
    assert sc.mocap.outage == (Outage(robot=2, at=3.0, duration=1.0),)
    with pytest.raises(ScenarioError, match=r"tiny.toml: \[mocap.outage\]\[0\].robot: no "
                                            r"robot 7"):
        _scenario(tmp_path, MOCAP.replace("robot = 2", "robot = 7"))
    with pytest.raises(ScenarioError, match=r"tiny.toml \[mocap\]: unknown field\(s\) hz"):
        _scenario(tmp_path, "[mocap]\nhz = 100\n")
    with pytest.raises(ScenarioError, match=r"\[mocap\]: MocapParams.rate: must be <= 1000"):
        _scenario(tmp_path, "[mocap]\nrate = 5000\n")
    with pytest.raises(ScenarioError, match="fix_timeout: must exceed the latency"):
        _scenario(tmp_path, "[mocap]\nlatency = 0.3\nfix_timeout = 0.25\n")
    _, none = _scenario(tmp_path, "")
    assert none.mocap is None


def test_the_launcher_gives_the_agents_a_pose_table_only_with_mocap(tmp_path):
    from hil.sitl.swarm import SitlOptions, agent_settings
    _, sc = _scenario(tmp_path)
    s = agent_settings(sc, 1, "tiny", "tcp/127.0.0.1:7447", SitlOptions(), 14550)
    assert s.pose is not None and s.pose.fix_timeout == 0.5
    _, alone = _scenario(tmp_path, "")
    assert agent_settings(alone, 1, "tiny", "tcp/127.0.0.1:7447", SitlOptions(),
                          14550).pose is None


def test_sim_fuses_the_mocap_table_and_says_when_it_changes_nothing(tmp_path, capsys):
    """sim takes the same table: on slipping wheels the fixes keep the pose error small
    and robot 2's outage holds it; without slip it says the table changes nothing."""
    import json

    from hil.cli import main
    path, _ = _scenario(tmp_path, duration=6.0)
    assert main(["sim", str(path), "--out", str(tmp_path / "run"), "--record-every", "0"]) == 0
    fused = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert fused["max_pose_error"] < 0.1 and fused["pose_failsafe_robots"] == [2]
    path.write_text(path.read_text().replace("wheel_slip = 0.03", "wheel_slip = 0.0"))
    capsys.readouterr()
    assert main(["sim", str(path), "--out", str(tmp_path / "run2"), "--record-every", "0"]) == 0
    assert "[mocap] changes nothing here" in capsys.readouterr().out


@pytest.mark.flaky(reruns=1)      # wall clock: a stall of a shared machine can trip a timeout
def test_sitl_with_fixes_on_slipping_wheels_and_a_robot_whose_fixes_stop(tmp_path):
    """3 robots, 3 % wheel slip, fixes at 100 Hz with 5 % dropouts; robot 2's stop from 3 s
    to 4 s (0.5 s timeout): its agent brakes to a (sticky) failsafe HOLD naming the fix's
    age and stands still; the others keep their pose error small and avoid it; no collision."""
    path, sc = _scenario(tmp_path)
    out = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "hil.cli", "sitl", str(path), "--out", str(out), "--no-live",
         "--gcs-port", "0", "--can-base-port", str(46000 + os.getpid() % 1000 * 10)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)

    def pids():
        try:
            m = json.loads((out / "manifest.json").read_text())
        except (OSError, ValueError):
            return []
        return [p for p in list(m.get("plants", {}).values())
                + [r.get("pid") for r in m.get("robots", {}).values()] if p]
    try:
        raw, _ = proc.communicate(timeout=240)
        text = raw.decode(errors="replace")
        assert proc.returncode == 0, text
        m = json.loads((out / "metrics.json").read_text())
        assert m["collisions"] == 0, text
        assert "pose source: simulated motion capture at 100 Hz" in text
        for rid in ("1", "3"):
            assert m["pose_error"][rid]["p99"] < 0.05, m["pose_error"]
        failsafe = m["sitl"]["failsafes"]
        assert set(failsafe) == {"2"}, failsafe
        assert failsafe["2"].startswith("pose fix 0.5") and "(limit 0.5 s)" in failsafe["2"]
        assert "[pose]" in (out / "config" / "robot_2.toml").read_text()
        stats = json.loads((out / "logs" / "agent_1.json").read_text())["pose"]
        assert stats["applied"] > 300 and stats["fixes"]["dropped"] == {}
        # robot 2 stops within its braking distance from where it was commanded to HOLD
        # (its commanded speed just before, held for the drive latency and a period, then
        # braking at a_max: the cart's, the SITL's default profile), and stays
        traj = np.loadtxt(out / "trajectories.csv", delimiter=",", skiprows=1)
        two = traj[traj[:, 1] == 2]                            # t, id, x, y, theta, v, ...
        k = np.flatnonzero((two[:, 0] >= 3.5) & (two[:, 5] == 0.0))[0]
        assert 3.5 <= two[k, 0] <= 3.6                          # fix_timeout after the stop
        v, a_max, reaction = abs(two[k - 1, 5]), 2.0, 0.02 + 0.02
        assert v > 0.3                                          # it was moving
        rest = two[two[:, 0] >= 5.2]
        assert np.ptp(rest[:, 2]) < 0.01 and np.ptp(rest[:, 3]) < 0.01
        travel = math.hypot(rest[0, 2] - two[k, 2], rest[0, 3] - two[k, 3])
        assert travel <= v * reaction + v * v / (2.0 * a_max) + 0.05, (travel, v)
        assert not [p for p in pids() if alive(p)], "processes left running"
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for pid in pids():
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
