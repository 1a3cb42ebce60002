"""Multi-process SITL smoke tests: the launcher, plant and agent processes on loopback.

Each test runs ``boundswarm sitl`` as a child process and, pass or fail, ends it and every
process it started (by PID, from the run manifest).
"""
import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh
from helpers import alive, free_port, judge_liveness

from common.payloads import MissionMsg
from firmware_sim.batch import SimOptions, simulate
from firmware_sim.plant import PlantKind
from hil.files.robot_profile import load_robot_profile
from hil.files.run_folder import read_run
from hil.files.scenario import load_scenario
from hil.ground.recorder import read_messages

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ROOT / "scenarios"


class Launcher:
    def __init__(self, tmp_path: Path, scenario: str, *extra: str, preexec_fn=None):
        self.out = tmp_path / "run"
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "hil.cli", "sitl", str(SCENARIOS / scenario), "--out",
             str(self.out), "--no-live", "--can-base-port", str(44000 + os.getpid() % 1000 * 10),
             *extra], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            preexec_fn=preexec_fn)

    def manifest(self) -> dict:
        try:
            return json.loads((self.out / "manifest.json").read_text())
        except (OSError, ValueError):
            return {}

    def pids(self) -> list[int]:
        m = self.manifest()
        return [p for p in list(m.get("plants", {}).values())
                + [r.get("pid") for r in m.get("robots", {}).values()]
                + [m.get("router_pid")] if p]

    def wait(self, timeout: float) -> tuple[int, str]:
        out, _ = self.proc.communicate(timeout=timeout)
        return self.proc.returncode, out.decode(errors="replace")

    def cleanup(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        for pid in self.pids():
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
        assert not [p for p in self.pids() if alive(p)], "processes left running"


@pytest.fixture
def launch(tmp_path):
    started = []

    def start(scenario, *extra):
        started.append(Launcher(tmp_path, scenario, *extra))
        return started[-1]
    yield start
    for launcher in started:
        launcher.cleanup()


# wall clock: a paused and resumed VM jumps the mission's reference ahead of robots that
# stood still (the run warns "no truth for ... s"); one rerun
@pytest.mark.flaky(reruns=1)
def test_sitl_paper_scenario(launch):
    sc = load_scenario(SCENARIOS / "paper.toml")
    # the paper's ideal robot, to compare with the batch simulator's ideal plant
    # two tick groups (one is the default) so that their phases are checked below
    run = launch("paper.toml", "--duration", "12", "--robot", str(ROOT / "robots" / "ideal.toml"),
                 "--tick-groups", "2")
    code, out = run.wait(timeout=150)
    assert code == 0, out
    m = json.loads((run.out / "metrics.json").read_text())
    a = sc.control.a
    assert m["min_pair_distance"] > a and m["min_obstacle_clearance"] > a
    assert m["collisions"] == 0
    s = m["sitl"]
    assert s["lost_processes"] == {} and s["agents_reporting"] == 9
    assert 0.0 <= s["cpu_steal"] <= 1.0, s["cpu_steal"]        # the host's, in the mission
    assert 0.0 < s["cpu_busy"] <= 1.0, s["cpu_busy"]           # a swarm ran: never idle
    # the router ran in a process of its own; each agent's neighbour-state age is split
    # into stages (router timestamps)
    assert run.manifest()["router_pid"]
    assert set(s["neighbour_age_stages_ms"]["1"]) == {"publish_to_router", "router_to_agent",
                                                     "in_agent"}
    assert s["neighbour_age_worst"]["stage"] in s["neighbour_age_stages_ms"]["1"]
    # every process is gone, the run folder is complete
    assert not [p for p in run.pids() if alive(p)]
    for name in ("run.mcap", "trajectories.csv", "figures/xy.png", "config/robot_1.toml"):
        assert (run.out / name).exists(), name
    per_agent = s["missed_in_mission_per_agent"]
    print("deadline misses in the mission:", per_agent, "in all:", s["deadline_misses"])
    assert s["deadline_misses_in_mission"] <= s["deadline_misses"]
    # the agents' loops keep real time: a loop that cannot keep up misses a tenth or more of
    # the mission's 600 periods, a stall of this shared VM a few (up to 12 seen in CI);
    # beyond 2 % the machine, not the swarm, is under test
    judge_liveness(s["cpu_steal"], max(per_agent.values()) * sc.control.period / 12)
    # the recording holds every state they published
    assert s["recording"]["states_published"] > 9 * 12 * 50 * 0.9
    assert s["recording"]["states_missing"] == {}, s["recording"]
    assert m["converged"] and m["convergence_time"] <= 12.0, out
    assert sum(s["watchdog_trips"].values()) == 0, s["watchdog_trips"]
    assert s["truth_gap"]["seconds"] < 0.1, s["truth_gap"]
    # the agents tick on the wall-clock grid in two groups half a period apart: each state
    # is stamped at its tick's start, a little after the phase (its jitter)
    T = sc.control.period
    phases: dict[int, list[float]] = {}
    for _, kind, _, msg in read_messages(run.out / "run.mcap"):
        if kind == "state":
            phases.setdefault(msg["robot_id"], []).append((msg["stamp"] % T) * 1e3)
    for index, rid in enumerate(sc.ids):
        assert f"tick_phase = {(index % 2) * T / 2}" in (
            run.out / "config" / f"robot_{rid}.toml").read_text()
        late = (np.median(phases[int(rid)]) - (index % 2) * T / 2 * 1e3) % (T * 1e3)
        assert late < 5.0, (rid, late)           # ms after its phase, mostly at once
    # settled (a second after convergence: at that instant a robot may still be closing in,
    # a little earlier or later than in the batch), each robot within 0.5 m of the batch
    # simulation of the same robot (its wheels, which make the law follow the reference's
    # velocity: controller.md A16)
    data = read_run(run.out)
    ideal = load_robot_profile(str(ROOT / "robots" / "ideal.toml"))
    batch = simulate(sc.ids, sc.poses, sc.formation, sc.obstacles, sc.control, ideal,
                     SimOptions(duration=12.0, plant=PlantKind.WHEELS))
    after = data.t >= m["convergence_time"] + 1.0
    k = np.searchsorted(batch.t, data.t[after])
    gap = np.hypot(*(data.pose[after, :, :2] - batch.pose[k, :, :2]).transpose(2, 0, 1))
    assert gap.max() < 0.5, gap.max()


@pytest.mark.flaky(reruns=1)      # wall clock, as test_sitl_paper_scenario
def test_sitl_agents_exchange_places_over_their_state_messages(launch, tmp_path):
    """Robots 1 and 3 of sitl_small start at each other's places: their agents exchange
    places over Zenoh (agent.exchange), and the run measures every robot against the place
    it holds."""
    text = (SCENARIOS / "sitl_small.toml").read_text()
    for old, new in (("[-12.0, -4.5, 0.0]", "[-12.0, 4.5, 0.0]"),
                     ("[-12.0, 4.0, 0.0]", "[-12.0, -4.0, 0.0]")):
        assert old in text
        text = text.replace(old, new)
    scenario = tmp_path / "exchange.toml"
    scenario.write_text(text)
    run = launch(str(scenario), "--duration", "15")
    code, out = run.wait(timeout=120)
    assert code == 0, out
    m = json.loads((run.out / "metrics.json").read_text())
    assert m["place_changes"] >= 2 and m["shared_places"] == []
    assert m["converged"] and m["collisions"] == 0      # measured against the places held
    last = {msg["robot_id"]: msg["slot"] for _, kind, _, msg in read_messages(run.out / "run.mcap")
            if kind == "state"}
    assert sorted(last.values()) == [0, 1, 2]    # which robot holds which varies run to run


def test_mission_misses_are_the_overruns_between_epoch_and_end():
    from hil.sitl.report import missed_in
    loop = {"overruns": 6, "overrun_events": [[99.5, 1], [100.0, 2], [107.2, 1], [110.1, 2]]}
    assert missed_in(loop, 100.0, 110.0) == 3          # start-up and shut-down left out
    assert missed_in({"overrun_events": []}, 100.0, 110.0) == 0
    # beyond the loop's event log: when is unknown, so they count as in the mission
    assert missed_in({**loop, "overruns_unlogged": 4}, 100.0, 110.0) == 7


def agent_stats(p99: float, tails: dict | None, published: int = 100) -> dict:
    stages = ({k: {"p50": 1.0, "p99": 2.0, "tail": v} for k, v in tails.items()}
              if tails is not None else None)
    return {"agent": {"neighbour_age_ms": {"p50": 1.0, "p99": p99, "count": 10},
                      "neighbour_age_stages_ms": stages},
            "zenoh": {"published": published}}


def test_a_gap_in_the_truth_is_found_with_its_start():
    from hil.sitl.report import truth_gap
    samples = np.concatenate([np.arange(0.0, 11.2, 0.01), np.arange(19.5, 20.0, 0.01)])
    gap = truth_gap(samples, 20.0)
    assert gap["seconds"] == pytest.approx(19.5 - samples[1119]) and gap["at"] == samples[1119]
    assert truth_gap(np.arange(0.0, 5.0, 0.01), 5.0)["seconds"] == pytest.approx(0.01)
    # a stall at the end (the clock jumped past it) or before the first sample
    end = truth_gap(np.arange(0.0, 8.4, 0.01), 9.0)
    assert end["seconds"] == pytest.approx(0.61) and end["at"] == pytest.approx(8.39)
    assert truth_gap(np.array([1.0]), 1.5) == {"seconds": 1.0, "at": 0.0}


def test_the_worst_agent_and_the_stage_of_its_oldest_data():
    from hil.cli.sitl import describe_stage, worst_age
    stats = {1: agent_stats(20.0, {"publish_to_router": 1.0, "router_to_agent": 3.0,
                                   "in_agent": 2.0}),
             2: agent_stats(90.0, {"publish_to_router": 2.0, "router_to_agent": 80.0,
                                   "in_agent": 5.0}),
             3: agent_stats(40.0, None)}
    worst = worst_age(stats)
    assert worst is not None
    assert worst["robot"] == 2 and worst["p99_ms"] == 90.0
    assert worst["stage"] == "router_to_agent"
    assert "router -> the agent's ring" in describe_stage(worst) and "80 ms" in describe_stage(
        worst)
    # without router timestamps the stage is unknown, and said so
    none = worst_age({3: agent_stats(40.0, None)})
    assert none is not None
    assert none["stage"] is None and "unknown" in describe_stage(none)
    assert worst_age({}) is None


def test_the_governors_share_and_least_speed_come_from_the_agents_counts():
    """A SITL run's governor figures are what the agents counted: the share of the periods in
    which the law ran, in all and per robot, and the least speed allowed (a killed agent
    wrote no statistics: it is not among them)."""
    from hil.cli.sitl import governor_from_agents

    def counted(steps, governed, least):
        return {"agent": {"law_steps": steps, "governed": governed,
                          "governor_share": governed / steps, "governor_min_allowed": least}}

    got = governor_from_agents({3: counted(1000, 250, 0.8), 1: counted(500, 0, None)})
    assert got == {"governor_share": 250 / 1500, "governor_share_by_robot": {1: 0.0, 3: 0.25},
                   "governor_min_allowed": 0.8}
    assert governor_from_agents({}) == {"governor_share": 0.0, "governor_share_by_robot": {},
                                        "governor_min_allowed": None}


def test_missing_states_are_counted_per_robot():
    from hil.cli.sitl import recording_check
    from hil.sitl.swarm import SitlRun
    run = SitlRun(agent_stats={1: agent_stats(1.0, None, 100), 2: agent_stats(1.0, None, 50)},
                  recorded={1: 100, 2: 47})
    assert recording_check(run) == {"states_published": 150, "states_recorded": 147,
                                    "states_missing": {2: 3}}


def test_a_bad_router_setting_is_refused_naming_the_flag(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "hil.cli", "sitl",
                           str(SCENARIOS / "sitl_small.toml"), "--out", str(tmp_path / "run"),
                           "--router-threads", "0"],
                          cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert "--router-threads" in proc.stderr and not (tmp_path / "run").exists()


def test_sigkill_of_an_agent_and_malformed_payloads(launch):
    sc = load_scenario(SCENARIOS / "sitl_small.toml")
    run = launch("sitl_small.toml")
    deadline = time.monotonic() + 60
    while not (run.manifest().get("robots", {}).get("2", {}).get("pid")
               and (run.out / "run.mcap").exists()) and time.monotonic() < deadline:
        time.sleep(0.2)
    manifest = run.manifest()
    victim = manifest["robots"]["2"]["pid"]
    # garbage on robot 1's state key, through the swarm's own router
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([manifest["zenoh_router"]]))
    session = zenoh.open(conf)
    missions = []
    sub = session.declare_subscriber(f"boundswarm/{manifest['swarm']}/mission",
                                     lambda sample: missions.append(sample.payload.to_bytes()))
    try:
        deadline = time.monotonic() + 60
        while not missions and time.monotonic() < deadline:
            time.sleep(0.05)
        assert missions, "no mission published"
        epoch = MissionMsg.decode(missions[0]).epoch
        time.sleep(max(0.0, epoch + 1.0 - time.time()))     # moving, before the obstacle
        for _ in range(5):
            session.put(f"boundswarm/{manifest['swarm']}/robot/1/state", b"\x01\x01garbage")
            time.sleep(0.05)
        os.kill(victim, signal.SIGKILL)
    finally:
        sub.undeclare()
        session.close()
    code, out = run.wait(timeout=90)
    assert code == 3, out                        # a process was lost, the run was safe
    assert "agent_2" in out and "exited with -9" in out
    m = json.loads((run.out / "metrics.json").read_text())
    assert m["collisions"] == 0 and m["min_pair_distance"] > sc.control.a
    s = m["sitl"]
    assert s["lost_processes"] == {"agent_2": -9}
    assert s["watchdog_trips"]["2"] >= 1         # its drivers stopped on their own
    assert s["watchdog_trips"]["1"] == 0 and s["watchdog_trips"]["3"] == 0
    assert s["zenoh_dropped"]["3"].get("size", 0) >= 1   # counted, not used
    assert not [p for p in run.pids() if alive(p)]


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_ends_the_launcher_and_every_process_it_started(tmp_path, signum):
    """Started as a script's background job (SIGINT inherited as ignored), the launcher still
    ends on SIGINT, and on SIGTERM, as on Ctrl-C: its agents, plant and router are gone."""
    run = Launcher(tmp_path, "sitl_small.toml", "--duration", "300",
                   preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        deadline = time.monotonic() + 60
        while len(run.pids()) < 5 and time.monotonic() < deadline:   # 3 agents, plant, router
            time.sleep(0.2)
        pids = run.pids()
        assert len(pids) == 5, run.manifest()
        run.proc.send_signal(signum)
        code, out = run.wait(timeout=30)
        assert code == 130, out
        assert "interrupted" in out
        assert not [p for p in pids if alive(p)]
    finally:
        run.cleanup()


def test_a_start_up_too_slow_names_the_timeout_and_the_robots_and_leaves_nothing(tmp_path):
    """--startup-timeout shorter than the plant takes to publish its first truth: the
    launcher says which robots it waited for and under which option, and ends every process
    it started."""
    run = Launcher(tmp_path, "sitl_small.toml", "--startup-timeout", "0.01")
    try:
        code, out = run.wait(timeout=60)
        pids = run.pids()
        assert code != 0, out
        assert "the plant did not come up within 0.01 s (--startup-timeout)" in out, out
        assert "no truth from robot(s) 1, 2, 3" in out, out
        assert pids and not [p for p in pids if alive(p)]
    finally:
        run.cleanup()


def test_bad_agent_config_is_refused_naming_the_field(tmp_path):
    bad = tmp_path / "agent.toml"
    bad.write_text('robot_id = 300\nswarm = "x"\ninitial_pose = [0.0, 0.0, 0.0]\n')
    proc = subprocess.run([sys.executable, "-m", "hil.cli", "agent", "--config", str(bad)],
                          cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert str(bad) in proc.stderr and "robot_id" in proc.stderr


def test_configs_that_cannot_share_a_process_are_refused_naming_why(tmp_path):
    """Two agent configs in one process need the same loop and session: a different tick
    phase is named; so is a --stats count that does not match the --config count."""
    from common.schema import to_toml
    from hil.sitl.swarm import SitlOptions, agent_settings
    sc = load_scenario(SCENARIOS / "sitl_small.toml")
    paths = []
    for index in (0, 1):
        s = agent_settings(sc, index, "x", "tcp/127.0.0.1:7447", SitlOptions(), 14550)
        if index:
            s = dataclasses.replace(s, tick_phase=0.01)
        paths.append(tmp_path / f"robot_{index}.toml")
        paths[-1].write_text(to_toml(s))
    cmd = [sys.executable, "-m", "hil.cli", "agent", "--config", str(paths[0]),
           "--config", str(paths[1])]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert "robots 1 and 2 cannot share a process: their tick_phase differ" in proc.stderr
    proc = subprocess.run(cmd + ["--stats", str(tmp_path / "one.json")], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert "2 --config but 1 --stats" in proc.stderr
    proc = subprocess.run(cmd + ["--stats", str(tmp_path / "one.json")] * 2, cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "--stats: a file given twice" in proc.stderr, proc.stderr
    # two robots on one bus would each read the other's drivers' frames
    from agent.process import check_group
    one, two = (agent_settings(sc, index, "x", "tcp/127.0.0.1:7447", SitlOptions(), 14550)
                for index in (0, 1))
    with pytest.raises(ValueError, match="two robots on one CAN bus"):
        check_group([one, dataclasses.replace(two, can=one.can)])
    check_group([one, two])


def test_agents_are_grouped_by_phase_and_a_robot_the_world_kills_runs_alone():
    from agent.settings import AgentSettings
    from hil.sitl.swarm import agent_hosts
    settings = [AgentSettings(robot_id=i, swarm="t", initial_pose=(0.0, 0.0, 0.0),
                              tick_phase=(i % 2) * 0.01) for i in range(1, 10)]
    hosts = agent_hosts(settings, 3, killed={4})
    ids = [[s.robot_id for s in h] for h in hosts]
    assert ids == [[4], [1, 3, 5], [7, 9], [2, 6, 8]]
    assert [[s.robot_id for s in h] for h in agent_hosts(settings, 1, set())] == [
        [i] for i in range(1, 10)]


def test_the_agents_share_processes_by_default_only_beyond_eight_robots_a_core():
    """(tick groups, agents per process): shared processes tick in four groups, about two
    processes per core, each group's robots split evenly."""
    from hil.sitl.launch import LaunchSettings, agent_layout
    auto = LaunchSettings()
    assert agent_layout(16, 2, auto) == (1, 1)          # a process per robot, one phase
    assert agent_layout(17, 2, auto) == (4, 5)          # four groups, 4 processes
    assert agent_layout(50, 2, auto) == (4, 13)
    assert agent_layout(64, 8, auto) == (1, 1)
    assert agent_layout(100, 8, auto) == (4, 7)         # 16 processes on 8 cores
    assert agent_layout(100, 4, auto) == (4, 13)        # 8 processes on 4 cores
    assert agent_layout(50, 2, LaunchSettings(tick_groups=2)) == (2, 13)   # as given
    assert agent_layout(30, 3, auto) == (4, 4)          # 8 processes of 4 or fewer
    assert agent_layout(50, 2, LaunchSettings(agents_per_process=1)) == (1, 1)
    assert agent_layout(50, 2, LaunchSettings(tick_groups=1)) == (1, 13)
    assert agent_layout(9, 2, LaunchSettings(agents_per_process=3)) == (4, 3)


def test_old_data_with_many_processes_per_core_suggests_sharing_them():
    from hil.cli.sitl import sharing_hint
    hint = sharing_hint(30, 2, 1)
    assert hint is not None and "--agents-per-process 8 runs them in 4" in hint
    assert sharing_hint(4, 2, 1) is None                # a process per robot keeps up
    assert sharing_hint(30, 2, 8) is None               # already shared


def test_agents_sharing_a_process_are_the_same_swarm(launch):
    """--agents-per-process 2 at one phase: robots 1 and 2 run in one process (one loop, one Zenoh
    session: each hears the other through it), robot 3 in its own; each reports its own
    statistics, the run is safe and converges, and the recording holds every state."""
    run = launch("sitl_small.toml", "--agents-per-process", "2", "--tick-groups", "1")
    code, out = run.wait(timeout=120)
    assert code == 0, out
    pids = {r: v["pid"] for r, v in run.manifest()["robots"].items()}
    assert pids["1"] == pids["2"] != pids["3"], pids
    m = json.loads((run.out / "metrics.json").read_text())
    s = m["sitl"]
    assert s["agents_reporting"] == 3 and s["lost_processes"] == {}
    assert m["collisions"] == 0 and m["converged"], out
    assert s["recording"]["states_missing"] == {}, s["recording"]
    for rid, together in ((1, 2), (2, 2), (3, 1)):
        st = json.loads((run.out / "logs" / f"agent_{rid}.json").read_text())
        assert st["agents_in_process"] == together
        # both neighbours' states every period, less a few around the start
        assert st["zenoh"]["states"]["accepted"] > 1.8 * st["loop"]["ticks"], st["zenoh"]
    assert not [p for p in run.pids() if alive(p)]


def test_one_ground_station_port_reaches_every_agent(launch):
    """A pymavlink ground station on one UDP port sees every agent and commands robot 2
    alone (the launcher's router routes by target system)."""
    from pymavlink import mavutil
    port = free_port("udp")
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255)
    try:
        run = launch("sitl_small.toml", "--gcs-port", str(port))
        seen: set[int] = set()
        end = time.monotonic() + 60
        while seen != {1, 2, 3} and time.monotonic() < end:
            msg = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=1)
            if msg is not None:
                seen.add(msg.get_srcSystem())
        assert seen == {1, 2, 3}
        acks = {}
        for _ in range(5):
            gcs.mav.command_long_send(2, 1, mavutil.mavlink.MAV_CMD_DO_SET_MODE, 0,
                                      mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4,
                                      0, 0, 0, 0, 0)
            msg = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=2)
            if msg is not None:
                acks[msg.get_srcSystem()] = msg.result
                break
        assert acks == {2: mavutil.mavlink.MAV_RESULT_ACCEPTED}
        code, out = run.wait(timeout=90)
        assert code == 0, out
        m = json.loads((run.out / "metrics.json").read_text())
        assert m["collisions"] == 0 and m["stuck_robots"] == [2]   # robot 2 held still
    finally:
        gcs.close()


@pytest.mark.flaky(reruns=1, rerun_except="AssertionError")   # a start-up too slow only
def test_agents_periods_replay_bit_for_bit_through_the_batch_s_compiled_period(launch,
                                                                               tmp_path):
    """The SITL's agents (the cart, its governor busy, every state 0.1 s late on an
    impaired link) record every period they run; the batch simulator's compiled period
    (firmware_sim.period_replay), handed each period's inputs as the batch hands them,
    gives every agent's commands, memory and pairs bit for bit."""
    from agent.period_log import read_periods
    from firmware_sim.period_replay import replay
    text = (SCENARIOS / "sitl_small.toml").read_text()
    text = text.replace("[-12.0, 4.0, 0.0]", "[-6.0, 1.5, 3.0]")      # robot 3 comes back
    scenario = tmp_path / "periods.toml"
    scenario.write_text(text + "\n[world]\nseed = 3\nlink_delay = 0.1\nlink_jitter = 0.02\n")
    run = launch(str(scenario), "--duration", "8", "--robot", str(ROOT / "robots/cart.toml"),
                 "--record-periods")
    code, out = run.wait(timeout=120)
    assert code in (0, 1), out                   # the run's safety is not this test's
    logs = sorted((run.out / "periods").glob("robot_*.periods"))
    assert len(logs) == 3
    governed = old = 0
    for log in logs:
        records = list(read_periods(log))
        assert len(records) > 200, log           # every period of the mission
        done = replay(records)
        assert done.mismatches == [], (log.name, done.mismatches[:3])
        governed += sum(r.out.governed < float("inf") for r in records)
        old += sum(r.inputs.now - r.inputs.reports.stamp[q] > 0.08 for r in records
                   for q in range(r.inputs.n_near))
    assert governed > 20 and old > 100            # the governor acted, on old data
