"""Bundles for robot computers and the ground station, from a swarm manifest.

Swarm manifest (TOML, ``version = 1``)::

    version = 1
    swarm = "field"
    scenario = "paper.toml"          # formation, gains, robot limits, initial poses (relative
                                     # to the manifest)
    [router]
    address = "192.0.2.10"           # how the robots reach the ground station
    port = 7447
    [gcs]
    mavlink = "udpout:192.0.2.10:14550"
    [mocap]                          # optional: a motion-capture pose source
    system = "vicon"                 # hil.ground.mocap.SYSTEMS
    hostname = "192.0.2.20"          # the motion-capture server
    options = []                     # further connect options, key=value
    error = 0.005                    # m, each fix's position error bound
    latency = 0.0                    # s, capture to arrival at the ground station
    fix_timeout = 0.5                # s, the robots' [pose] fix_timeout
    [[robots]]
    id = 1
    host = "robot-1.local"           # name or address of the robot computer
    can_interface = "can0"
    bitrate = 500000
    rigid_body = "robot-1"           # its name in the motion-capture system (default)

A complete example: examples/swarm.toml.

``boundswarm deploy MANIFEST --out DIR`` writes ``DIR/robot-<id>/`` for each robot (agent
config, Zenoh client config with mutual TLS, the robot's certificate and private key, the
CA certificate, a MAVLink signing key, a systemd unit whose documentation is the bundle's
README (installed with it), an install script, the project's wheel) and ``DIR/ground/``
(the router's config with TLS and access control, its certificate and key, the CA, the
scenario, notes for the ground-control station and, with ``[mocap]``, the motion-capture
bridge's config ``mocap.toml``; the robots' agent configs then have a ``[pose]`` table). The
access-control rules let each robot publish only under its own keys; the ground station
publishes the fixes.
"""
from __future__ import annotations

import json
import secrets
import shutil
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

from agent.pose import PoseSettings
from agent.settings import AgentSettings, SensingSettings
from common.schema import ConfigError, TableReader, from_table, load_toml, to_toml
from hil.files.scenario import load_scenario
from hil.ground.certs import SwarmCA, write_private
from hil.ground.mocap import MocapSettings
from transport.settings import CanSettings, MavlinkSettings, ZenohSettings

ROOT = Path(__file__).resolve().parents[2]
PREFIX = "/opt/boundswarm"          # where install.sh puts the venv on a robot
ETC = "/etc/boundswarm"


class DeployError(ValueError):
    """A swarm manifest is wrong, or the scenario it names."""


@dataclass(frozen=True)
class RobotEntry:
    id: int
    host: str
    can_interface: str
    bitrate: int
    rigid_body: str = ""          # its name in the motion-capture system


@dataclass(frozen=True)
class SwarmManifest:
    path: Path
    swarm: str
    scenario: Path
    router_address: str
    router_port: int
    mavlink: str
    robots: tuple[RobotEntry, ...]
    mocap: MocapSettings | None = None    # the ground station's bridge (ground client)
    pose: PoseSettings | None = None      # the robots' [pose] with a motion-capture system


def load_manifest(path: str | Path) -> SwarmManifest:
    path = Path(path)
    doc = load_toml(path, "swarm manifest", DeployError)
    rd = TableReader(str(path), DeployError)
    rd.only(doc, {"version", "swarm", "scenario", "router", "gcs", "robots", "mocap"},
            "top level")
    if rd.integer(doc, "version", "version") != 1:
        raise rd.fail("version", f"this boundswarm reads version 1, got {doc['version']}")
    router = rd.table(doc, "router")
    rd.only(router, {"address", "port"}, "[router]")
    gcs = rd.table(doc, "gcs")
    rd.only(gcs, {"mavlink"}, "[gcs]")
    robots = []
    for i, r in enumerate(rd.array_of_tables(doc, "robots", required=True)):
        f = f"robots[{i}]"
        rd.only(r, {"id", "host", "can_interface", "bitrate", "rigid_body"}, f)
        rid = rd.integer(r, "id", f"{f}.id", lo=1, hi=255)
        robots.append(RobotEntry(rid, rd.string(r, "host", f"{f}.host"),
                                 rd.string(r, "can_interface", f"{f}.can_interface", "can0"),
                                 rd.integer(r, "bitrate", f"{f}.bitrate", 500_000,
                                            lo=10_000, hi=1_000_000),
                                 rd.string(r, "rigid_body", f"{f}.rigid_body", f"robot-{rid}")))
    ids = [r.id for r in robots]
    if len(set(ids)) != len(ids):
        raise rd.fail("robots", f"duplicate robot ids in {ids}")
    scenario = (path.parent / rd.string(doc, "scenario", "scenario")).resolve()
    swarm = rd.string(doc, "swarm", "swarm")
    mocap = pose = None
    if "mocap" in doc:
        mocap, pose = _mocap(rd.table(doc, "mocap"), swarm, robots, f"{path} [mocap]")
    return SwarmManifest(path, swarm, scenario,
                         rd.string(router, "address", "[router] address"),
                         rd.integer(router, "port", "[router] port", 7447, lo=1, hi=65535),
                         rd.string(gcs, "mavlink", "[gcs] mavlink", MavlinkSettings.url),
                         tuple(robots), mocap, pose)


MOCAP_KEYS = {"system", "hostname", "options", "error", "latency"}


def _mocap(table: dict, swarm: str, robots: list[RobotEntry], where: str
           ) -> tuple[MocapSettings, PoseSettings]:
    """The bridge's settings (the ground client's session, each robot's rigid body) and the
    robots' [pose] from the manifest's ``[mocap]`` table."""
    unknown = sorted(set(table) - MOCAP_KEYS - {"fix_timeout"})
    if unknown:
        raise DeployError(f"{where}: unknown field(s) {', '.join(unknown)}; allowed: "
                          f"{', '.join(sorted(MOCAP_KEYS | {'fix_timeout'}))}")
    bridge = {k: v for k, v in table.items() if k in MOCAP_KEYS}
    bridge.update(swarm=swarm, zenoh={"config": "ground-client.json5"},
                  bodies=[{"name": r.rigid_body, "robot": r.id} for r in robots])
    pose = {"fix_timeout": table["fix_timeout"]} if "fix_timeout" in table else {}
    try:
        return (from_table(MocapSettings, bridge, where),
                from_table(PoseSettings, pose, where))
    except ConfigError as exc:
        raise DeployError(str(exc)) from None


def _tls(prefix: str, cn: str, mode: str) -> dict:
    side = "listen" if mode == "router" else "connect"
    return {"root_ca_certificate": f"{prefix}/certs/ca.pem",
            f"{side}_private_key": f"{prefix}/certs/{cn}.key",
            f"{side}_certificate": f"{prefix}/certs/{cn}.pem",
            "enable_mtls": True}


def router_config(m: SwarmManifest, prefix: str) -> dict:
    """Zenoh router config: TLS with client certificates, each robot may publish only under
    its own keys; every authenticated peer may subscribe to the swarm."""
    base = f"boundswarm/{m.swarm}"
    rules = [{"id": "subscribe", "permission": "allow", "flows": ["ingress", "egress"],
              "messages": ["declare_subscriber", "declare_liveliness_subscriber",
                           "liveliness_query"], "key_exprs": [f"{base}/**"]},
             {"id": "deliver", "permission": "allow", "flows": ["egress"],
              "messages": ["put", "delete", "liveliness_token"], "key_exprs": [f"{base}/**"]}]
    subjects, policies = [], []
    for r in m.robots:
        rules.append({"id": f"own-{r.id}", "permission": "allow", "flows": ["ingress"],
                      "messages": ["put", "delete", "liveliness_token"],
                      "key_exprs": [f"{base}/robot/{r.id}", f"{base}/robot/{r.id}/**"]})
        subjects.append({"id": f"robot-{r.id}", "cert_common_names": [f"robot-{r.id}"]})
        policies.append({"rules": ["subscribe", "deliver", f"own-{r.id}"],
                         "subjects": [f"robot-{r.id}"]})
    rules.append({"id": "ground", "permission": "allow", "flows": ["ingress", "egress"],
                  "messages": ["put", "delete", "liveliness_token"], "key_exprs": [f"{base}/**"]})
    subjects.append({"id": "ground", "cert_common_names": ["ground"]})
    policies.append({"rules": ["subscribe", "ground"], "subjects": ["ground"]})
    return {"mode": "router", "scouting": {"multicast": {"enabled": False}},
            "listen": {"endpoints": [f"tls/0.0.0.0:{m.router_port}"]},
            "transport": {"link": {"tls": _tls(prefix, "router", "router")}},
            "access_control": {"enabled": True, "default_permission": "deny", "rules": rules,
                               "subjects": subjects, "policies": policies}}


def client_config(m: SwarmManifest, cn: str, prefix: str) -> dict:
    # a robot may boot before the ground station: keep trying the router for 60 s
    return {"mode": "client", "scouting": {"multicast": {"enabled": False}},
            "connect": {"endpoints": [f"tls/{m.router_address}:{m.router_port}"],
                        "timeout_ms": 60000, "exit_on_failure": True},
            "transport": {"link": {"tls": _tls(prefix, cn, "client")}}}


REALTIME_PRIORITY = 40      # SCHED_FIFO priority of the control loop on robot computers

UNIT = """[Unit]
Description=boundswarm agent of robot {id}
Documentation=file://{prefix}/README.md
After=network-online.target
Wants=network-online.target

[Service]
Type=notify
NotifyAccess=main
User=boundswarm
# the control loop thread runs SCHED_FIFO (agent.toml realtime_priority), Zenoh's one below
LimitRTPRIO={rtprio}
WorkingDirectory={etc}
ExecStartPre=+/usr/sbin/ip link set {can} down
ExecStartPre=+/usr/sbin/ip link set {can} up type can bitrate {bitrate} restart-ms 100
ExecStart={prefix}/venv/bin/boundswarm agent --config {etc}/agent.toml
# READY once both drivers are armed; the watchdog is fed only while the loop is on time
WatchdogSec=2
TimeoutStartSec=30
# SIGTERM: zero velocity, drivers IDLE, liveliness dropped
KillSignal=SIGTERM
TimeoutStopSec=5
Restart=on-failure
RestartSec=2

[Install]
WantedBy=multi-user.target
"""

INSTALL = """#!/bin/sh
# Install the boundswarm agent of robot {id} on this computer (run as root).
set -eu
HERE=$(cd "$(dirname "$0")" && pwd)
id -u boundswarm >/dev/null 2>&1 || \\
    useradd --system --no-create-home --shell /usr/sbin/nologin boundswarm
python3 -m venv {prefix}/venv
{prefix}/venv/bin/pip install --quiet "$HERE"/wheels/*.whl
install -d -m 0750 -o root -g boundswarm {etc} {etc}/certs
install -m 0640 -o root -g boundswarm "$HERE"/agent.toml "$HERE"/zenoh.json5 {etc}/
install -m 0644 "$HERE"/certs/ca.pem "$HERE"/certs/robot-{id}.pem {etc}/certs/
install -m 0640 -o root -g boundswarm "$HERE"/certs/robot-{id}.key {etc}/certs/
install -m 0640 -o root -g boundswarm "$HERE"/mavlink.key {etc}/
install -m 0644 "$HERE"/README.md {prefix}/
install -m 0644 "$HERE"/boundswarm-agent.service /etc/systemd/system/
systemctl daemon-reload
systemctl enable boundswarm-agent.service
echo "installed; start with: systemctl start boundswarm-agent"
"""


def build_wheel(out: Path) -> Path:
    """The project's wheel (pip wheel, no dependencies) into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps",
                           "--wheel-dir", str(out), str(ROOT)], capture_output=True, text=True)
    wheels = sorted(out.glob("boundswarm-*.whl"))
    if proc.returncode != 0 or not wheels:       # the project's, not the manifest's, fault
        raise RuntimeError(f"could not build the boundswarm wheel: {proc.stderr[-500:]}")
    return wheels[-1]


def deploy(manifest: SwarmManifest, out: Path, wheel: Path | None = None,
           prefix: str = PREFIX, etc: str = ETC) -> dict[str, Path]:
    """Write every bundle; returns {name: folder}."""
    try:
        sc = load_scenario(manifest.scenario)
    except ValueError as exc:
        raise DeployError(f"{manifest.path}: scenario: {exc}") from None
    index = {int(i): k for k, i in enumerate(sc.ids)}
    missing = [r.id for r in manifest.robots if r.id not in index]
    if missing:
        raise DeployError(f"{manifest.path}: robots {missing} are not in {manifest.scenario}")
    ca = SwarmCA(manifest.swarm)
    wheel = wheel or build_wheel(out / "wheels")
    bundles: dict[str, Path] = {}

    ground = out / "ground"
    (ground / "certs").mkdir(parents=True, exist_ok=True)
    (ground / "certs" / "ca.pem").write_bytes(ca.cert_pem)
    for cn, hosts in (("router", [manifest.router_address]), ("ground", ["ground"])):
        issued = ca.issue(cn, hosts)
        (ground / "certs" / f"{cn}.pem").write_bytes(issued.cert_pem)
        write_private(ground / "certs" / f"{cn}.key", issued.key_pem)
    (ground / "router.json5").write_text(json.dumps(router_config(manifest, "."), indent=2))
    (ground / "ground-client.json5").write_text(
        json.dumps(client_config(manifest, "ground", "."), indent=2))
    shutil.copy(manifest.scenario, ground / "scenario.toml")
    keys = {}
    for r in manifest.robots:
        keys[r.id] = secrets.token_bytes(32)
        write_private(ground / f"mavlink-robot-{r.id}.key", keys[r.id])
    if manifest.mocap is not None:
        (ground / "mocap.toml").write_text(to_toml(manifest.mocap))
    (ground / "README.md").write_text(_ground_notes(manifest, wheel.name))
    bundles["ground"] = ground

    for r in manifest.robots:
        b = out / f"robot-{r.id}"
        (b / "certs").mkdir(parents=True, exist_ok=True)
        (b / "wheels").mkdir(exist_ok=True)
        shutil.copy(wheel, b / "wheels" / wheel.name)
        (b / "certs" / "ca.pem").write_bytes(ca.cert_pem)
        issued = ca.issue(f"robot-{r.id}", [r.host])
        (b / "certs" / f"robot-{r.id}.pem").write_bytes(issued.cert_pem)
        write_private(b / "certs" / f"robot-{r.id}.key", issued.key_pem)
        write_private(b / "mavlink.key", keys[r.id])
        # certificate paths relative to the working directory (the unit's is ETC)
        (b / "zenoh.json5").write_text(json.dumps(client_config(manifest, f"robot-{r.id}", "."),
                                                  indent=2))
        x, y, theta = map(float, sc.poses[index[r.id]])
        settings = AgentSettings(
            robot_id=r.id, swarm=manifest.swarm, initial_pose=(x, y, theta),
            control=sc.control, robot=sc.robot,
            can=CanSettings(interface="socketcan", channel=r.can_interface, bitrate=r.bitrate),
            zenoh=ZenohSettings(mode="client", connect=(), config="zenoh.json5"),
            autostart=True, sensing=SensingSettings(sc.sensing_range),
            realtime_priority=REALTIME_PRIORITY,
            mavlink=MavlinkSettings(url=manifest.mavlink, signing_key_file="mavlink.key"),
            pose=manifest.pose)
        (b / "agent.toml").write_text(to_toml(settings))
        (b / "boundswarm-agent.service").write_text(UNIT.format(
            id=r.id, etc=etc, prefix=prefix, can=r.can_interface, bitrate=r.bitrate,
            rtprio=REALTIME_PRIORITY))
        (b / "README.md").write_text(_robot_notes(manifest, r, etc, prefix))
        install = b / "install.sh"
        install.write_text(INSTALL.format(id=r.id, etc=etc, prefix=prefix))
        install.chmod(0o755)
        bundles[f"robot-{r.id}"] = b
    return bundles


def _robot_notes(m: SwarmManifest, r: RobotEntry, etc: str, prefix: str) -> str:
    return f"""# Agent of robot {r.id} in swarm "{m.swarm}"

Installed by install.sh: the agent in {prefix}/venv, its configuration in {etc}
(agent.toml, zenoh.json5, certs/, mavlink.key) and the systemd unit
boundswarm-agent.service, which brings {r.can_interface} up at {r.bitrate} bit/s and runs

    {prefix}/venv/bin/boundswarm agent --config {etc}/agent.toml

    systemctl start boundswarm-agent      # ready once both drivers are armed
    systemctl status boundswarm-agent
    journalctl -u boundswarm-agent -f

The agent connects to the swarm's router at tls/{m.router_address}:{m.router_port} and
sends MAVLink to {m.mavlink} (signed with mavlink.key). On SIGTERM it commands zero
velocity, sets the drivers IDLE and leaves the swarm. `boundswarm agent --help` and the
project's README describe the rest.
"""


def _mocap_notes(m: SwarmManifest, wheel: str) -> str:
    """The ground notes' motion-capture step ('' without a motion-capture system)."""
    if m.mocap is None or m.pose is None:
        return ""
    where = f" at {m.mocap.hostname}" if m.mocap.hostname else ""
    bodies = ", ".join(f"{b.name} -> robot {b.robot}" for b in m.mocap.bodies)
    text = textwrap.fill(f"Motion capture: each robot's pose comes from the {m.mocap.system} "
                         f"system{where} (rigid bodies {bodies}). Install boundswarm with its "
                         f"mocap extra on this computer, e.g. pip install "
                         f"\"../wheels/{wheel}[mocap]\", then, with the router up:",
                         width=88, initial_indent="   ", subsequent_indent="   ")
    after = textwrap.fill(f"The robots refuse to arm without a fix and hold when their fix is "
                          f"older than {m.pose.fix_timeout:g} s: start the bridge before the "
                          f"robots, keep this computer's and the robots' clocks in sync "
                          f"(chrony or PTP: a fix is stamped with its capture time), and "
                          f"watch its warnings about rigid bodies it does not see.",
                          width=88, initial_indent="   ", subsequent_indent="   ")
    return f"""
{text}

       boundswarm mocap --config mocap.toml

{after}
"""


def _ground_notes(m: SwarmManifest, wheel: str) -> str:
    return f"""# Ground station of swarm "{m.swarm}"

1. Router (Zenoh, mutual TLS, access control; robots connect to
   tls/{m.router_address}:{m.router_port}):

       boundswarm router --config router.json5
{_mocap_notes(m, wheel)}
2. Start the mission when every robot is alive (the epoch is shared by all agents; keep
   the clocks of all computers in sync, e.g. with chrony):

       boundswarm mission --config ground-client.json5 --swarm {m.swarm} \\
           --scenario scenario.toml --start-in 5

3. Ground-control station: every agent is a MAVLink 2 system (system id = robot id) sending
   to {m.mavlink}; the MAVLink signing keys are mavlink-robot-<id>.key (32 bytes each).

Each robot bundle holds only its own private key. Re-run `boundswarm deploy` to rotate all
certificates.
"""

