"""A swarm across hosts: robot computers and a ground station as network namespaces joined by
a bridge, each robot running its deployed bundle (agent + emulated drivers on its own CAN
bus) with mutual TLS and access control through the ground station's router.

Topology (all created and removed by this test, addresses only inside its namespaces):
ground ``10.77.0.1/24`` on bridge br0 (router, world, recorder, mission); robot i at
``10.77.0.(10+i)``. The bundles say ``socketcan can0``; these namespaces have no CAN, so the
test points each robot's agent and drivers at python-can's udp_multicast inside that
robot's namespace (interface-local group, hop limit 0).

Link faults on one robot's agent (its drivers keep a sound link: they stand for its wheels):
loss with nftables at the ground station's input on a second router port (``LOSSY_PORT``)
that the agent's zenoh.json5 is pointed at; delay (this kernel has no netem) with a
delaying TCP relay (tooling.link_delay) in the ground namespace on ``10.77.0.1:7448`` in front of
the router, which that robot's zenoh.json5 is pointed at (the router certificate names
10.77.0.1, so TLS still validates on the other ports).
"""
import dataclasses
import json
import os
import re
import shutil
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import judge_liveness

from hil.files.scenario import load_scenario
from hil.ground.deploy import REALTIME_PRIORITY, deploy, load_manifest
from hil.ground.recorder import read_messages
from hil.sitl.host_cpu import cpu_times, steal_share
from hil.sitl.report import analyse_recording, missed_in

ROOT = Path(__file__).resolve().parent.parent
BIN = str(Path(sys.executable).parent / "boundswarm")
SCENARIO = ROOT / "scenarios" / "sitl_small.toml"
PAPER = ROOT / "scenarios" / "paper.toml"
FAULT_RUN = 20.0                    # s of mission in the fault tests (recovery time)
RELAY_PORT = 7448                   # the delaying relay, on the ground station's address
LOSSY_PORT = 7449                   # the router's second port, for a lossy robot's agent
# The fault tests' drivers' watchdog [s]. On this shared 2-core VM, with 13 processes of the
# swarm and a busy host, an agent's loop now and then goes 0.1 s (the default) without a
# command while its drivers run: their watchdog stops the wheels, the agent's failsafe holds
# the robot for the rest of the run (as it should on a robot), and the run says nothing of
# the link fault under test. The governor counts the watchdog in its reaction time, so a
# longer one slows the robots: converged at 8-9 s with 0.1 s, 10-12 s with 0.2 s, 16-19 s
# (or not by 20 s) with 0.3 s. With 0.2 s, three swarms at once tripped none in 6 runs.
FAULT_WATCHDOG = 0.2
TRUTH_LIMIT = 1.0                   # m between the world's truth and a robot's odometry
DROPPED_FELT = 10                   # segments a loss fault drops in its 4 s, at least
PREFIX = f"bs{os.getpid() % 10000}"


def _can_netns() -> str | None:
    if os.geteuid() != 0 or shutil.which("ip") is None:
        return "needs root and iproute2 for network namespaces"
    probe = f"{PREFIX}probe"
    ok = subprocess.run(["ip", "netns", "add", probe], capture_output=True).returncode == 0
    if ok:
        ok = subprocess.run(["ip", "netns", "exec", probe, "ip", "link", "add", "br0", "type",
                             "bridge"], capture_output=True).returncode == 0
        subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None if ok else "network namespaces with bridges are not available"


REASON = _can_netns()
# 21 processes on this 2-core shared VM, in wall-clock time: a stall of the machine can spoil
# a run (its failure is reported); five failures in a row fail the test. A run in which the
# host stole more than STEAL_LIMIT of the CPU has its safety judged, not its liveness
# (tests.helpers.judge_liveness)
pytestmark = [pytest.mark.skipif(REASON is not None, reason=f"multi-host test: {REASON}"),
              pytest.mark.flaky(reruns=4)]


def sh(*cmd: str) -> None:
    subprocess.run(cmd, check=True, capture_output=True)


class Hosts:
    """The namespaces and the processes started in them; everything is undone by close()."""

    def __init__(self, robots: list[int]):
        self.ground = f"{PREFIX}g"
        self.robot_ns = {r: f"{PREFIX}r{r}" for r in robots}
        self.procs: list[tuple[str, subprocess.Popen]] = []
        self.started: dict[int, float] = {}         # pid -> monotonic start time
        try:
            self._build()
        except BaseException:
            self.close()
            raise

    def _build(self) -> None:
        sh("ip", "netns", "add", self.ground)
        self.g("ip", "link", "set", "lo", "up")
        self.g("ip", "link", "add", "br0", "type", "bridge")
        self.g("ip", "addr", "add", "10.77.0.1/24", "dev", "br0")
        self.g("ip", "link", "set", "br0", "up")
        for r, ns in self.robot_ns.items():
            sh("ip", "netns", "add", ns)
            a, b = f"{PREFIX}a{r}", f"{PREFIX}b{r}"
            sh("ip", "link", "add", a, "type", "veth", "peer", "name", b)
            sh("ip", "link", "set", a, "netns", ns)
            sh("ip", "link", "set", b, "netns", self.ground)
            self.g("ip", "link", "set", b, "master", "br0")
            self.g("ip", "link", "set", b, "up")
            for cmd in (["ip", "link", "set", "lo", "up"],
                        ["ip", "link", "set", a, "name", "eth0"],
                        ["ip", "addr", "add", f"10.77.0.{10 + r}/24", "dev", "eth0"],
                        ["ip", "link", "set", "eth0", "up"]):
                sh("ip", "netns", "exec", ns, *cmd)

    def impair(self, robot: int, loss_percent: int) -> None:
        """Lose a share of the TCP segments the robot's agent sends to the router (its
        Zenoh link, on LOSSY_PORT), as a lossy radio would: dropped where they arrive (the
        ground's input hook), so the robot's TCP has them acknowledged late or never and
        retransmits. (Dropped in the robot's own output hook they would never leave: TCP
        sees a local send error and tries again, without a retransmission.)"""
        table = f"fault{robot}"
        self.g("nft", "add", "table", "inet", table)
        self.g("nft", "add", "chain", "inet", table, "in",
               "{ type filter hook input priority 0 ; }")
        self.g("nft", "add", "rule", "inet", table, "in", "ip", "saddr",
               f"10.77.0.{10 + robot}", "tcp", "dport", str(LOSSY_PORT), "numgen", "random",
               "mod", "100", "<", str(loss_percent), "counter", "drop")

    def dropped(self, robot: int) -> int:
        """How many of the robot's segments its fault has dropped so far."""
        text = self.output(self.ground, "nft", "list", "table", "inet", f"fault{robot}")
        found = re.search(r"counter packets (\d+)", text)
        assert found is not None, text
        return int(found[1])

    def retransmitted(self, robot: int) -> int:
        """The TCP segments the robot's namespace has retransmitted so far (RetransSegs of
        /proc/net/snmp)."""
        names, values = (line.split()[1:] for line in
                         self.output(self.robot_ns[robot], "cat", "/proc/net/snmp").splitlines()
                         if line.startswith("Tcp:"))
        return int(dict(zip(names, values))["RetransSegs"])

    def output(self, ns: str, *cmd: str) -> str:
        return subprocess.run(["ip", "netns", "exec", ns, *cmd], check=True,
                              capture_output=True, text=True).stdout

    def heal(self, robot: int) -> None:
        self.g("nft", "delete", "table", "inet", f"fault{robot}")

    def g(self, *cmd: str) -> None:
        sh("ip", "netns", "exec", self.ground, *cmd)

    def start(self, ns: str, name: str, args: list[str], cwd: Path, log_dir: Path,
              program: tuple[str, ...] = (BIN,)) -> subprocess.Popen:
        log = open(log_dir / f"{name}.log", "wb")
        proc = subprocess.Popen(["ip", "netns", "exec", ns, *program, *args], cwd=cwd,
                                stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        log.close()
        self.procs.append((name, proc))
        self.started[proc.pid] = time.monotonic()
        return proc

    def stop(self, *procs: subprocess.Popen, timeout: float = 10.0) -> None:
        """SIGINT to all at once (so none runs on while another shuts down), SIGKILL to
        whatever has not ended ``timeout`` s later."""
        for sig in (signal.SIGINT, signal.SIGKILL):
            running = [p for p in procs if p.poll() is None]
            for proc in running:
                os.killpg(proc.pid, sig)
            end = time.monotonic() + timeout
            for proc in running:
                try:
                    proc.wait(timeout=max(0.1, end - time.monotonic()))
                except subprocess.TimeoutExpired:
                    pass

    def cpu_share(self) -> dict[str, float]:
        """CPU time / wall time of every running process since it started."""
        tick = os.sysconf("SC_CLK_TCK")
        shares = {}
        for name, proc in self.procs:
            try:
                fields = Path(f"/proc/{proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            cpu = (int(fields[11]) + int(fields[12])) / tick       # utime + stime
            shares[name] = round(cpu / (time.monotonic() - self.started[proc.pid]), 3)
        return shares

    def close(self) -> None:
        self.stop(*(proc for _, proc in reversed(self.procs)))
        for ns in [*self.robot_ns.values(), self.ground]:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        for r in self.robot_ns:         # a veth pair still in this namespace (failed build)
            subprocess.run(["ip", "link", "del", f"{PREFIX}a{r}"], capture_output=True)


def _wait_for(path: Path, pattern: str, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.exists() and re.search(pattern, path.read_text(errors="replace")):
            return True
        time.sleep(0.2)
    return False


@dataclasses.dataclass(frozen=True)
class Loss:
    """``percent`` of the robot's outgoing TCP segments dropped from ``t_from`` to ``t_to``
    (seconds after the mission's t = 0)."""
    robot: int
    percent: int
    t_from: float
    t_to: float


@dataclasses.dataclass(frozen=True)
class Delay:
    """``ms`` of one-way delay each way on the robot agent's Zenoh link (through the relay)
    from ``t_from`` to ``t_to`` (seconds after the mission's t = 0); 0 otherwise."""
    robot: int
    ms: float
    t_from: float
    t_to: float


def _sleep_until(wall: float) -> None:
    time.sleep(max(0.0, wall - time.time()))


def run_swarm(tmp_path: Path, scenario: Path = SCENARIO, duration: float = 14.0,
              fault: Loss | Delay | None = None, watchdog: float | None = None) -> dict:
    """Deploy and run the swarm across namespaces, with an optional link fault on one
    robot. ``watchdog`` [s]: the robots' drivers' watchdog (the scenario's [robot]
    watchdog_timeout, which the agents' governor counts in its reaction time; None: the
    scenario's). Returns the metrics, the agents' and the world's statistics, the drivers'
    watchdog trips and when the fault was on."""
    sc = load_scenario(scenario)
    if watchdog is not None:
        sc = dataclasses.replace(sc, robot=dataclasses.replace(sc.robot,
                                                               watchdog_timeout=watchdog))
        scenario = tmp_path / scenario.name
        assert sc.source is not None            # loaded from a file
        scenario.write_text(re.sub(r"\[robot\]\n", f"[robot]\nwatchdog_timeout = {watchdog}\n",
                                   sc.source.read_text()))
        assert load_scenario(scenario).robot == sc.robot
    sc = dataclasses.replace(sc, duration=duration)
    ids = [int(i) for i in sc.ids]
    manifest = tmp_path / "swarm.toml"
    manifest.write_text(
        f'version = 1\nswarm = "field"\nscenario = "{scenario}"\n'
        '[router]\naddress = "10.77.0.1"\nport = 7447\n'
        '[gcs]\nmavlink = "udpout:10.77.0.1:14550"\n'
        + "".join(f'[[robots]]\nid = {r}\nhost = "10.77.0.{10 + r}"\ncan_interface = "can0"\n'
                  for r in ids))
    out = tmp_path / "bundles"
    logs = tmp_path / "logs"
    logs.mkdir()
    deploy(load_manifest(manifest), out, wheel=ROOT / "README.md")
    for r in ids:
        agent = out / f"robot-{r}" / "agent.toml"
        agent.write_text(re.sub(r"\[can\][^\[]*", '[can]\ninterface = "udp_multicast"\n'
                                'channel = "ff11::b5:1"\nport = 43300\n\n',
                                agent.read_text()))
    drivers_conf = {r: "zenoh.json5" for r in ids}
    control = tmp_path / "delay_ms"
    if fault is not None:
        # the robot's bundle (its agent) reaches the router on a port of its own: the relay's
        # (delay) or a second one of the router's (loss, dropped by that port); its emulated
        # drivers stand for the wheels' physics, not for the robot's radio, so they keep the
        # direct link (else the world's ground truth of that robot would lag behind the
        # fault, and with it the obstacles the world detects around it)
        b = out / f"robot-{fault.robot}"
        conf = json.loads((b / "zenoh.json5").read_text())
        (b / "zenoh-direct.json5").write_text(json.dumps(conf, indent=2))
        assert conf["connect"]["endpoints"] == ["tls/10.77.0.1:7447"]
        port = RELAY_PORT if isinstance(fault, Delay) else LOSSY_PORT
        conf["connect"]["endpoints"] = [f"tls/10.77.0.1:{port}"]
        (b / "zenoh.json5").write_text(json.dumps(conf, indent=2))
        drivers_conf[fault.robot] = "zenoh-direct.json5"
        control.write_text("0\n")
        router = json.loads((out / "ground" / "router.json5").read_text())
        router["listen"]["endpoints"].append(f"tls/0.0.0.0:{LOSSY_PORT}")
        (out / "ground" / "router.json5").write_text(json.dumps(router, indent=2))
    hosts = Hosts(ids)
    result: dict = {"fault_on": None}
    try:
        ground = out / "ground"
        hosts.start(hosts.ground, "router", ["router", "--config", "router.json5"], ground, logs)
        assert _wait_for(logs / "router.log", "router running", 30)
        relay = None
        if isinstance(fault, Delay):
            relay = hosts.start(hosts.ground, "relay",
                                ["-m", "tooling.link_delay", "--listen", f"10.77.0.1:{RELAY_PORT}",
                                 "--upstream", "10.77.0.1:7447", "--delay-ms", "0",
                                 "--control", str(control), "-v"], ROOT / "tests", logs,
                                program=(sys.executable,))
            assert _wait_for(logs / "relay.log", "relaying", 30), (logs / "relay.log").read_text()
        hosts.start(hosts.ground, "world", ["plant", "world", "--scenario",
                                            "scenario.toml", "--swarm", "field",
                                            "--zenoh-config", "ground-client.json5",
                                            # physics, not a robot's computer: never starved
                                            "--realtime-priority", str(REALTIME_PRIORITY + 1),
                                            "--stats", str(logs / "world.json")],
                    ground, logs)
        recorder = hosts.start(hosts.ground, "recorder",
                               ["record", "--swarm", "field", "--out", str(tmp_path / "run.mcap"),
                                "--config", "ground-client.json5"], ground, logs)
        for r in ids:
            b = out / f"robot-{r}"
            hosts.start(hosts.robot_ns[r], f"drivers_{r}",
                        ["plant", "drivers", "--can-interface", "udp_multicast",
                         "--can-channel", "ff11::b5:1", "--can-port", "43300", "--robot",
                         str(r), "--swarm", "field", "--zenoh-config", drivers_conf[r],
                         # a robot's drivers are boards of their own: never starved by the
                         # robot computer's loops (SCHED_FIFO at REALTIME_PRIORITY)
                         "--realtime-priority", str(REALTIME_PRIORITY + 1),
                         "--watchdog", str(sc.robot.watchdog_timeout)], b, logs)
            hosts.start(hosts.robot_ns[r], f"agent_{r}",
                        ["agent", "--config", "agent.toml", "--stats",
                         str(logs / f"agent_{r}.json")], b, logs)
        mission = hosts.start(hosts.ground, "mission",
                              ["mission", "--config", "ground-client.json5", "--swarm", "field",
                               "--scenario", "scenario.toml", "--start-in", "2", "--wait", "60"],
                              ground, logs)
        assert mission.wait(timeout=90) == 0, (logs / "mission.log").read_text()
        mission_log = (logs / "mission.log").read_text()
        found = re.search(r"epoch\s+([0-9.]+)", mission_log)
        assert found is not None, mission_log
        epoch = float(found[1])
        _sleep_until(epoch)
        cpu_at_epoch = cpu_times()
        if fault is not None:
            _sleep_until(epoch + fault.t_from)
            on = time.time()
            if isinstance(fault, Loss):
                retransmitted = hosts.retransmitted(fault.robot)
                hosts.impair(fault.robot, fault.percent)
            else:
                _write_atomic(control, f"{fault.ms:g}\n")
            _sleep_until(epoch + fault.t_to)
            if isinstance(fault, Loss):
                result["dropped"] = hosts.dropped(fault.robot)
                result["retransmitted"] = hosts.retransmitted(fault.robot) - retransmitted
                hosts.heal(fault.robot)
            else:
                _write_atomic(control, "0\n")
            result["fault_on"] = (on - epoch, time.time() - epoch)
        _sleep_until(epoch + sc.duration)
        result["cpu_steal"] = steal_share(cpu_at_epoch, cpu_times())
        _sleep_until(epoch + sc.duration + 1)
        result["cpu_share"] = hosts.cpu_share()
        hosts.stop(*(proc for name, proc in hosts.procs if name.startswith("agent")))
        hosts.stop(recorder)
        world = next(p for n, p in hosts.procs if n == "world")
        hosts.stop(world)
        if relay is not None:
            hosts.stop(relay)
            assert isinstance(fault, Delay)         # the relay is there for a delay
            text = (logs / "relay.log").read_text()
            # the robot's agent went through the relay, and the delay was set
            assert f"('10.77.0.{10 + fault.robot}'," in text, text
            assert f"one-way delay now {fault.ms:g} ms" in text, text
            found = re.search(r"closed after (\d+)", text)
            assert found is not None, text
            result["relay_connections"] = int(found[1])
        for name, proc in hosts.procs:
            assert name == "mission" or proc.returncode in (0, None, -2), \
                f"{name}: {(logs / f'{name}.log').read_text()[-1500:]}"
    finally:
        hosts.close()
    assert not [p for _, p in hosts.procs if p.poll() is None]
    _, metrics, _ = analyse_recording(tmp_path / "run.mcap", sc)
    result.update(
        metrics=metrics.summary(sc.name, sc.duration), a=sc.control.a, period=sc.control.period,
        agents={r: json.loads((logs / f"agent_{r}.json").read_text()) for r in ids},
        world=json.loads((logs / "world.json").read_text()),
        watchdog_trips={r: (logs / f"drivers_{r}.log").read_text().count("watchdog expired")
                        for r in ids})
    result["missed_in_mission"] = {r: missed_in(st["loop"], epoch, epoch + sc.duration)
                                   for r, st in result["agents"].items()}
    result["uplink_ms"] = uplink_delays(tmp_path / "run.mcap", epoch)
    return result


def uplink_delays(recording: Path, epoch: float) -> dict[int, list[tuple[float, float]]]:
    """Per robot, (t of each state after the mission's t = 0 [s], how late the ground's
    router received it [ms]): the router stamps what it receives, so log time minus the
    agent's own stamp is the robot's uplink delay."""
    delays: dict[int, list[tuple[float, float]]] = {}
    for _topic, kind, log_t, msg in read_messages(recording):
        if kind == "state":
            delays.setdefault(msg["robot_id"], []).append(
                (msg["stamp"] - epoch, (log_t - msg["stamp"]) * 1e3))
    return delays


def window(delays: list[tuple[float, float]], t_from: float, t_to: float) -> list[float]:
    return [d for t, d in delays if t_from <= t <= t_to]


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(text)
    tmp.replace(path)


def judge_truth(run: dict) -> None:
    """The world builds each robot's truth from its drivers' wheel reports, sent over the
    network: reports that come late or are lost under load make it diverge from where the
    robot is (its own odometry, from the same wheels, in its states). On such a truth
    neither safety nor liveness can be judged: an expected failure, with the divergence."""
    err = run["metrics"]["max_pose_error"]
    if err > TRUTH_LIMIT:
        pytest.xfail(f"the world's truth diverged {err:.2f} m from the robots' odometry "
                     f"(limit {TRUTH_LIMIT:g} m; wheel reports late or lost under load, host "
                     f"steal {run['cpu_steal']:.0%}): the run cannot be judged")


def missed_share(run: dict, duration: float) -> float:
    """The worst agent's share of the mission's periods missed."""
    return max(run["missed_in_mission"].values()) * run["period"] / duration


def health(run: dict) -> dict:
    """What else went wrong in a run: each agent's failsafe and missed periods in the
    mission, its drivers' watchdog trips, and the CPU share of every process."""
    return {"cpu_steal": run["cpu_steal"],
            "failsafe": {r: st["failsafe"] for r, st in run["agents"].items()},
            "missed": run["missed_in_mission"], "watchdog_trips": run["watchdog_trips"],
            "cpu_share": run["cpu_share"]}


def brief(m: dict) -> dict:
    return {k: m[k] for k in ("convergence_time", "final_max_tracking_error", "stuck_robots",
                              "min_pair_distance", "min_obstacle_clearance", "collisions",
                              "max_pose_error")}


def test_swarm_across_hosts_with_tls(tmp_path):
    """The paper scenario (9 robots, two obstacles) across 9 robot hosts with TLS on meets
    the SITL acceptance: converged by 12 s, every distance and obstacle clearance above a,
    no collision, no agent failsafe, no watchdog trip; deadline misses reported (above 2 % of
    the mission's periods the machine did not keep time: tests.helpers.judge_liveness)."""
    duration = 14.0
    run = run_swarm(tmp_path, PAPER, duration=duration)
    m, a, agents = run["metrics"], run["a"], run["agents"]
    lifetime = {r: st["loop"]["overruns"] for r, st in agents.items()}
    misses = run["missed_in_mission"]
    print("paper across hosts:", brief(m), "deadline misses in the mission:", misses,
          "over the agents' lifetime:", lifetime, "world overruns:", run["world"]["overruns"],
          "CPU share:", run["cpu_share"], "steal:", run["cpu_steal"])
    assert len(agents) == 9 and sorted(misses) == sorted(agents)
    judge_truth(run)
    assert m["collisions"] == 0 and m["min_pair_distance"] > a, brief(m)
    assert m["min_obstacle_clearance"] > a, brief(m)
    judge_liveness(run["cpu_steal"], missed_share(run, duration))
    assert m["converged"] and m["convergence_time"] <= 12.0, brief(m)
    for stats in agents.values():
        assert stats["failsafe"] is None and stats["agent"]["neighbour_age_ms"]["count"] > 0
    assert sum(run["watchdog_trips"].values()) == 0, run["watchdog_trips"]


@pytest.mark.skipif(shutil.which("nft") is None, reason="nftables (nft) is not installed")
def test_link_fault_on_one_robot(tmp_path):
    """30 % loss on robot 2's link for 4 s early in the run: no distance below a, and the
    swarm converges once the link recovers."""
    run = run_swarm(tmp_path, fault=Loss(2, 30, 0.5, 4.5), duration=FAULT_RUN,
                    watchdog=FAULT_WATCHDOG)
    m = run["metrics"]
    print("loss fault on", run["fault_on"], brief(m), "ages:",
          {r: st["agent"]["neighbour_age_ms"] for r, st in run["agents"].items()},
          "dropped:", run["dropped"], "retransmitted:", run["retransmitted"], health(run))
    judge_truth(run)
    assert m["collisions"] == 0 and m["min_pair_distance"] > run["a"], brief(m)
    assert m["min_obstacle_clearance"] > run["a"], brief(m)
    judge_liveness(run["cpu_steal"], missed_share(run, FAULT_RUN))
    assert not any(st["failsafe"] for st in run["agents"].values()), health(run)
    assert m["converged"], brief(m)
    # the fault was felt: it dropped robot 2's segments and robot 2's TCP retransmitted
    # (the kernel's counters in its namespace; under load the sound links retransmit too, and
    # the machine's load moves every link's delay as much as the loss does)
    assert run["dropped"] >= DROPPED_FELT and run["retransmitted"] > 0, (run["dropped"],
                                                                         run["retransmitted"])


def test_link_delay_on_one_robot(tmp_path):
    """300 ms one-way delay on robot 2's link (both ways, through the relay) for 4 s early
    in the run, then none: no distance below a, and the swarm converges once the link
    recovers."""
    delay = Delay(2, 300.0, 0.5, 4.5)
    run = run_swarm(tmp_path, fault=delay, duration=FAULT_RUN, watchdog=FAULT_WATCHDOG)
    m, agents = run["metrics"], run["agents"]
    ages = {r: st["agent"]["neighbour_age_ms"] for r, st in agents.items()}
    print("delay fault on", run["fault_on"], brief(m), "ages:", ages, "relayed connections:",
          run["relay_connections"], health(run))
    judge_truth(run)
    assert m["collisions"] == 0 and m["min_pair_distance"] > run["a"], brief(m)
    assert m["min_obstacle_clearance"] > run["a"], brief(m)
    judge_liveness(run["cpu_steal"], missed_share(run, FAULT_RUN))
    assert not any(st["failsafe"] for st in agents.values()), health(run)
    assert m["converged"], brief(m)
    # the fault was felt: robot 2's states reached the ground and robot 3 late, robot 3's
    # reached it late (fault-free, the neighbour-state age p99 is 16-21 ms). Robot 1 drives
    # ahead of the held-back robot 2, beyond its 8 m sensing range, while the fault lasts
    on, off = run["fault_on"]
    assert statistics.median(window(run["uplink_ms"][2], on + 0.1, off - 0.1)) > 0.9 * delay.ms
    for r in (2, 3):
        assert ages[r]["p99"] > 0.75 * delay.ms, ages
