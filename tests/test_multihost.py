"""A swarm across hosts: robot computers and a ground station as network namespaces joined by
a bridge, each robot running its deployed bundle (agent + emulated drivers on its own CAN
bus) with mutual TLS and access control through the ground station's router.

Topology (all created and removed by this test, addresses only inside its namespaces):
ground ``10.77.0.1/24`` on bridge br0 (router, world, recorder, mission); robot i at
``10.77.0.(10+i)``. The bundles say ``socketcan can0``; these namespaces have no CAN, so the
test points each robot's agent and drivers at python-can's udp_multicast inside that
robot's namespace (interface-local group, hop limit 0).
"""
import dataclasses
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hil.deploy import deploy, load_manifest
from hil.scenario import load_scenario
from hil.sitl_report import analyse_recording

ROOT = Path(__file__).resolve().parent.parent
BIN = str(Path(sys.executable).parent / "boundswarm")
SCENARIO = ROOT / "scenarios" / "sitl_small.toml"
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
pytestmark = pytest.mark.skipif(REASON is not None, reason=f"multi-host test: {REASON}")


def sh(*cmd: str) -> None:
    subprocess.run(cmd, check=True, capture_output=True)


class Hosts:
    """The namespaces and the processes started in them; everything is undone by close()."""

    def __init__(self, robots: list[int]):
        self.ground = f"{PREFIX}g"
        self.robot_ns = {r: f"{PREFIX}r{r}" for r in robots}
        self.procs: list[tuple[str, subprocess.Popen]] = []
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
        """Drop a share of the robot's outgoing TCP segments (its Zenoh link): TCP turns the
        loss into retransmission delays."""
        ns = self.robot_ns[robot]
        sh("ip", "netns", "exec", ns, "nft", "add", "table", "inet", "fault")
        sh("ip", "netns", "exec", ns, "nft", "add", "chain", "inet", "fault", "out",
           "{ type filter hook output priority 0 ; }")
        sh("ip", "netns", "exec", ns, "nft", "add", "rule", "inet", "fault", "out", "meta",
           "l4proto", "tcp", "numgen", "random", "mod", "100", "<", str(loss_percent), "drop")

    def heal(self, robot: int) -> None:
        sh("ip", "netns", "exec", self.robot_ns[robot], "nft", "delete", "table", "inet",
           "fault")

    def g(self, *cmd: str) -> None:
        sh("ip", "netns", "exec", self.ground, *cmd)

    def start(self, ns: str, name: str, args: list[str], cwd: Path, log_dir: Path
              ) -> subprocess.Popen:
        log = open(log_dir / f"{name}.log", "wb")
        proc = subprocess.Popen(["ip", "netns", "exec", ns, BIN, *args], cwd=cwd, stdout=log,
                                stderr=subprocess.STDOUT, start_new_session=True)
        log.close()
        self.procs.append((name, proc))
        return proc

    def stop(self, proc: subprocess.Popen, timeout: float = 10.0) -> None:
        for sig in (signal.SIGINT, signal.SIGKILL):
            if proc.poll() is not None:
                return
            os.killpg(proc.pid, sig)
            try:
                proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                pass

    def close(self) -> None:
        for _, proc in reversed(self.procs):
            self.stop(proc)
        for ns in [*self.robot_ns.values(), self.ground]:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)


def _wait_for(path: Path, pattern: str, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.exists() and re.search(pattern, path.read_text(errors="replace")):
            return True
        time.sleep(0.2)
    return False


def run_swarm(tmp_path: Path, fault: tuple[int, int, float, float] | None = None) -> dict:
    """Deploy and run the swarm across namespaces; ``fault`` = (robot, loss %, from, to)
    seconds after the mission starts. Returns the metrics and the agents' statistics."""
    sc = dataclasses.replace(load_scenario(SCENARIO), duration=14.0)
    ids = [int(i) for i in sc.ids]
    manifest = tmp_path / "swarm.toml"
    manifest.write_text(
        f'version = 1\nswarm = "field"\nscenario = "{SCENARIO}"\n'
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
    hosts = Hosts(ids)
    try:
        ground = out / "ground"
        hosts.start(hosts.ground, "router", ["router", "--config", "router.json5"], ground, logs)
        assert _wait_for(logs / "router.log", "router running", 30)
        hosts.start(hosts.ground, "world", ["plant", "--world-only", "--scenario",
                                            "scenario.toml", "--swarm", "field",
                                            "--zenoh-config", "ground-client.json5"],
                    ground, logs)
        recorder = hosts.start(hosts.ground, "recorder",
                               ["record", "--swarm", "field", "--out", str(tmp_path / "run.mcap"),
                                "--config", "ground-client.json5"], ground, logs)
        for r in ids:
            b = out / f"robot-{r}"
            hosts.start(hosts.robot_ns[r], f"drivers_{r}",
                        ["plant", "--drivers-only", "--can-interface", "udp_multicast",
                         "--can-channel", "ff11::b5:1", "--can-port", "43300", "--robot",
                         str(r), "--swarm", "field", "--zenoh-config", "zenoh.json5"], b, logs)
            hosts.start(hosts.robot_ns[r], f"agent_{r}",
                        ["agent", "--config", "agent.toml", "--stats",
                         str(logs / f"agent_{r}.json")], b, logs)
        mission = hosts.start(hosts.ground, "mission",
                              ["mission", "--config", "ground-client.json5", "--swarm", "field",
                               "--scenario", "scenario.toml", "--start-in", "2", "--wait", "60"],
                              ground, logs)
        assert mission.wait(timeout=90) == 0, (logs / "mission.log").read_text()
        started = time.monotonic()
        if fault is not None:
            robot, loss, t_from, t_to = fault
            time.sleep(2 + t_from)
            hosts.impair(robot, loss)
            time.sleep(t_to - t_from)
            hosts.heal(robot)
        time.sleep(max(0.0, 2 + sc.duration + 1 - (time.monotonic() - started)))
        for name, proc in hosts.procs:
            if name.startswith("agent"):
                hosts.stop(proc)
        hosts.stop(recorder)
        for name, proc in hosts.procs:
            assert name == "mission" or proc.returncode in (0, None, -2), \
                f"{name}: {(logs / f'{name}.log').read_text()[-1500:]}"
    finally:
        hosts.close()
    assert not [p for _, p in hosts.procs if p.poll() is None]
    _, metrics, _ = analyse_recording(tmp_path / "run.mcap", sc)
    return {"metrics": metrics.summary(sc.name, sc.duration), "a": sc.control.a,
            "agents": {r: json.loads((logs / f"agent_{r}.json").read_text()) for r in ids}}


def brief(m: dict) -> dict:
    return {k: m[k] for k in ("convergence_time", "final_max_tracking_error", "stuck_robots",
                              "min_pair_distance", "collisions")}


def test_swarm_across_hosts_with_tls(tmp_path):
    run = run_swarm(tmp_path)
    m = run["metrics"]
    assert m["collisions"] == 0 and m["min_pair_distance"] > run["a"], brief(m)
    assert m["converged"] and m["convergence_time"] <= 12.0, brief(m)
    for stats in run["agents"].values():
        assert stats["failsafe"] is None and stats["agent"]["neighbour_age_ms"]["count"] > 0


@pytest.mark.skipif(shutil.which("nft") is None, reason="nftables (nft) is not installed")
def test_link_fault_on_one_robot(tmp_path):
    """30 % loss on robot 2's link for 4 s early in the run: no distance below a, and the
    swarm converges once the link recovers."""
    run = run_swarm(tmp_path, fault=(2, 30, 0.5, 4.5))
    m = run["metrics"]
    assert m["collisions"] == 0 and m["min_pair_distance"] > run["a"], brief(m)
    assert m["converged"], brief(m)
    ages = run["agents"][1]["agent"]["neighbour_age_ms"]
    assert ages["p99"] > run["agents"][1]["loop"]["period_s"] * 1e3   # the fault was felt
