"""The one-command SITL swarm: router, plant, the agents' processes, recording.

Sequence: start the Zenoh router in a process of its own (loopback endpoint, scouting off;
hil.sitl.launch), connect to it and start recording; write each robot's agent config and the
run manifest; start the plant process(es) (emulated drivers on one CAN bus per robot, robot
motion, truth and obstacle detections) and wait for truth from every robot; start the agents
(a process per robot, or per ``agents_per_process`` robots: ``agent_hosts``) and wait for
every liveliness token; publish the mission with an epoch a little in the
future; watch the run (progress, live status table, lost processes); then end every child
(agents first: zero velocity, IDLE; the router once the recording has settled) and turn the
recording into the same run folder as ``sim``, plus loop timing, neighbour-state age
and watchdog trips.

A plant that dies ends the run at once; an agent that dies is reported and the run goes on
(its robot stands still, its drivers' watchdog stopped it), so what the others do is
measured. Any failure or Ctrl-C tears down every process.

The scenario's ``[world]`` (docs/world.md "In the SITL"): the plant slips the wheels and
spoils the encoders and detections; the agents' configs get an ``[impairment]`` section
(simulation only) for the link's delay, jitter and loss; and each ``[[world.kill]]`` is done
here: at mission epoch + ``at`` (this process's clock) the robot's agent is sent SIGKILL by
PID, a planned death that is recorded in ``SitlRun.killed``, not reported as a lost process.
The scenario's ``[mocap]`` (firmware_sim.mocap_sim): the plant publishes pose fixes and the
agents' configs get a ``[pose]`` table; they arm once their first fix is in.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import os
import signal
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Protocol

import numpy as np
from rich.console import Console
from rich.live import Live
from rich.table import Table

from agent.impairment import ImpairmentSettings
from agent.pose import PoseSettings
from agent.settings import AgentSettings, SensingSettings, TimeoutSettings
from common.payloads import MissionMsg, Received, StateMsg, TruthMsg
from common.schema import to_toml
from common.vocabulary import StateFlags
from hil.files.scenario import Scenario
from hil.ground.recorder import Recorder
from hil.sitl.host_cpu import busy_share, cpu_times, machine_cores, steal_share
from hil.sitl.launch import (
    LaunchSettings,
    agent_layout,
    open_launcher_session,
    start_router,
    zenoh_runtime,
)
from hil.sitl.mavlink_router import MavlinkRouter
from hil.sitl.processes import Child, Children, wait_until
from transport.canbus import DEFAULT_GROUP
from transport.settings import CanSettings, MavlinkSettings, ZenohSettings
from transport.zenoh_link import Keys, Latest, Presence

log = logging.getLogger(__name__)

MODE_NAMES = {0: "TRACK", 1: "AVOID", 2: "ROTATE"}

# Zenoh's runtime for the agents, plants and launcher of a SITL swarm: one thread instead of
# five or six. Dozens of processes on a few cores then spend less CPU handing each message
# between threads (30 robots: neighbour-state age p99 25 ms instead of 44 in an A/B pair of
# runs). A ZENOH_RUNTIME in the launcher's environment wins (not for the router: its own).
ZENOH_RUNTIME = zenoh_runtime(1)


class SitlError(RuntimeError):
    """The swarm could not be started or lost its plant."""


@dataclass(frozen=True)
class SitlOptions:
    can_interface: str = "udp_multicast"
    can_channel: str | None = None      # udp_multicast group, or socketcan template "vcan{i}"
    can_base_port: int = 43200          # udp_multicast: robot ID's bus on port base + ID
    robots_per_plant: int = 0           # 0: one plant process hosts every robot
    zenoh_port: int | None = None       # router port on 127.0.0.1 (default: a free one)
    gcs_port: int = 14550               # ground station's UDP port on 127.0.0.1 (0: no MAVLink)
    near_radius: float = 0.0            # m, agents' [zenoh] near_radius (0: every robot)
    mavlink_key: str | None = None      # absolute path of a MAVLink signing key file (all agents)
    realtime_priority: int = 10         # agents' SCHED_FIFO loop priority, plant's + 1 (0: normal)
    startup_timeout: float = 40.0       # s
    lead_time: float = 1.5              # s between the mission message and its epoch
    live: bool = True                   # live status table on a terminal
    robot_profile: str | None = None    # absolute path of the robot profile the plants use
    record_periods: bool = False        # each agent records its periods in periods/
    launch: LaunchSettings = field(default_factory=LaunchSettings)   # router, age bound


@dataclass
class SitlRun:
    """What the launcher saw, for the report and the exit code."""

    epoch: float = 0.0
    lost: dict = field(default_factory=dict)      # child name -> exit code
    killed: dict = field(default_factory=dict)    # robot id -> mission time [s] of its kill
    agent_stats: dict = field(default_factory=dict)
    plant_stats: list = field(default_factory=list)
    recorded: dict = field(default_factory=dict)  # robot id -> states in the recording
    clock_step: float = 0.0     # s, the wall clock's largest step against the monotonic one
    cpu_steal: float | None = None   # share of the CPU the host stole in the mission
    cpu_busy: float | None = None    # share of the CPU the host gave that was used then
    tick_groups: int = 1
    agents_per_process: int = 1
    agent_processes: int = 0


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def agent_hosts(settings: list[AgentSettings], per_process: int,
                killed: set[int]) -> list[list[AgentSettings]]:
    """The agents' processes: up to ``per_process`` robots of one tick phase each, in the
    scenario's order; a robot in ``killed`` alone (a planned death ends its process)."""
    hosts: list[list[AgentSettings]] = []
    by_phase: dict[float, list[AgentSettings]] = {}
    for s in settings:
        if s.robot_id in killed or per_process == 1:
            hosts.append([s])
        else:
            by_phase.setdefault(s.tick_phase, []).append(s)
    for group in by_phase.values():
        hosts += [group[k:k + per_process] for k in range(0, len(group), per_process)]
    return hosts


def _swarm_name(sc: Scenario) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in sc.name) or "swarm"


def agent_settings(sc: Scenario, index: int, swarm: str, endpoint: str,
                   opts: SitlOptions, mavlink_port: int) -> AgentSettings:
    rid = int(sc.ids[index])
    if opts.can_interface == "udp_multicast":
        can = CanSettings(interface="udp_multicast", channel=opts.can_channel or DEFAULT_GROUP,
                          port=opts.can_base_port + rid)
    else:
        can = CanSettings(interface=opts.can_interface,
                          channel=(opts.can_channel or "vcan{i}").format(i=index, id=rid))
    x, y, theta = map(float, sc.poses[index])
    w = sc.world
    impairment = (ImpairmentSettings(seed=w.seed, link_delay=w.link_delay,
                                     link_jitter=w.link_jitter, link_loss=w.link_loss,
                                     loss_burst=w.loss_burst) if w.link else None)
    # agents on a slow link are configured not to take live neighbours for silent ones
    timeouts = TimeoutSettings()
    timeouts = dataclasses.replace(timeouts, staleness=w.staleness(timeouts.staleness))
    groups, _ = agent_layout(len(sc.ids), machine_cores(), opts.launch)
    return AgentSettings(robot_id=rid, swarm=swarm, initial_pose=(x, y, theta),
                         tick_phase=(index % groups) * sc.control.period / groups,
                         control=sc.control, robot=sc.robot, can=can, timeouts=timeouts,
                         zenoh=ZenohSettings(mode="client", connect=(endpoint,),
                                             near_radius=opts.near_radius),
                         autostart=True, sensing=SensingSettings(sc.sensing_range),
                         realtime_priority=opts.realtime_priority,
                         mavlink=MavlinkSettings(url=f"udpout:127.0.0.1:{mavlink_port}",
                                                 signing_key_file=opts.mavlink_key),
                         impairment=impairment,
                         pose=(PoseSettings(fix_timeout=sc.mocap.fix_timeout)
                               if sc.mocap is not None else None))


def _status_table(sc: Scenario, states: Mapping[int, Received[StateMsg]],
                  truth: Mapping[int, Received[TruthMsg]], presence: frozenset,
                  t: float) -> Table:
    table = Table(title=f"{sc.name}: t = {t:5.1f} s of {sc.duration:g} s", header_style="bold")
    for col in ("robot", "alive", "mode", "flags", "x [m]", "y [m]", "error [m]", "v [m/s]"):
        table.add_column(col, justify="right")
    for rid in sc.ids:
        st, tr = states.get(int(rid)), truth.get(int(rid))
        if st is None or tr is None:
            table.add_row(str(rid), "yes" if rid in presence else "no", "-", "-", "-", "-",
                          "-", "-")
            continue
        s, p = st.msg, tr.msg
        flags = ",".join(f.name for f in StateFlags if f.name and s.flags & f) or "-"
        err = float(np.hypot(p.x - s.x_d, p.y - s.y_d))
        table.add_row(str(rid), "yes" if rid in presence else "[red]LOST[/red]",
                      MODE_NAMES.get(s.mode, str(s.mode)), flags, f"{p.x:7.2f}", f"{p.y:7.2f}",
                      f"{err:6.2f}", f"{p.v:6.2f}")
    return table


class _Closable(Protocol):
    """What run_sitl opens on its Zenoh session and closes at the end, in reverse order."""

    def close(self) -> None: ...


def run_sitl(sc: Scenario, out: Path, opts: SitlOptions, console: Console) -> SitlRun:
    """Run the SITL swarm of ``sc``, recording into ``out``; returns what was seen. The
    router runs in a process of its own (hil.sitl.launch), ended last; the launcher is a
    client of it. Its processes inherit ZENOH_RUNTIME (the router: its own); the launcher's
    Zenoh takes it too if it has not started yet (the variable is read once per process)."""
    os.environ.setdefault("ZENOH_RUNTIME", ZENOH_RUNTIME)
    out.mkdir(parents=True, exist_ok=True)
    groups, per = agent_layout(len(sc.ids), machine_cores(), opts.launch)
    opts = dataclasses.replace(opts, launch=dataclasses.replace(
        opts.launch, tick_groups=groups, agents_per_process=per))
    run = SitlRun(tick_groups=groups, agents_per_process=per)
    swarm = _swarm_name(sc)
    keys = Keys(swarm)
    port = opts.zenoh_port or free_tcp_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    config_dir = out / "config"
    config_dir.mkdir(exist_ok=True)
    router_child = Children(out / "logs")
    try:
        router_pid = start_router(router_child, endpoint, config_dir, opts.launch).pid
        router = open_launcher_session(endpoint, opts.launch)
    except BaseException:
        router_child.terminate_all()
        raise
    opened: list[_Closable] = []
    try:
        # a minute of a 50-robot swarm's samples: the recorder thread (normal scheduling) may
        # fall far behind while the agents run, the launcher's Zenoh threads never do
        recorder = Recorder(router, keys, out / "run.mcap", capacity=1 << 17)
        opened.append(recorder)
        presence = Presence(router, keys)
        opened.append(presence)
        truth = Latest(router, keys.truth("*"), TruthMsg.decode, time.time)
        states = Latest(router, keys.state("*"), StateMsg.decode, time.time)
        opened += [truth, states]
        if opts.gcs_port:
            router_mav = MavlinkRouter(free_udp_port(), opts.gcs_port).start()
            opened.append(router_mav)
            mav_port = router_mav.agents_port
            console.print(f"MAVLink: every agent (system id = robot id) on udp 127.0.0.1:"
                          f"{opts.gcs_port}; e.g. mavproxy.py --master=udpin:127.0.0.1:"
                          f"{opts.gcs_port}, or QGroundControl's default UDP link")
        else:
            mav_port = free_udp_port()               # nobody listens: telemetry is dropped
        settings = [agent_settings(sc, i, swarm, endpoint, opts, mav_port)
                    for i in range(len(sc.ids))]
        if opts.record_periods:               # agent.period_log, one file per robot
            (out / "periods").mkdir(exist_ok=True)
            settings = [dataclasses.replace(s, record_periods=str(
                (out / "periods" / f"robot_{s.robot_id}.periods").resolve()))
                for s in settings]
        for s in settings:
            (config_dir / f"robot_{s.robot_id}.toml").write_text(to_toml(s))
        _write_manifest(out, sc, settings, endpoint, swarm, {"router": router_pid})

        with Children(out / "logs") as children:
            _start_plants(children, sc, opts, swarm, endpoint, out)
            ids = {int(i) for i in sc.ids}
            console.print(f"plant starting ({len(ids)} robots) ...")
            if not wait_until(lambda: set(truth.snapshot()) >= ids or children.failed(),
                              opts.startup_timeout) or children.failed():
                raise SitlError(_failure(
                    f"the plant did not come up within {opts.startup_timeout:g} s "
                    f"(--startup-timeout): no truth from robot(s) "
                    f"{_ids(ids - set(truth.snapshot()))}", children))
            agents: dict[int, Child] = {}
            hosts = agent_hosts(settings, opts.launch.agents_per_process,
                                {k.robot for k in sc.world.kill})
            for host in hosts:
                args = ["agent"]
                for s in host:
                    args += ["--config", str(config_dir / f"robot_{s.robot_id}.toml"),
                             "--stats", str(out / "logs" / f"agent_{s.robot_id}.json")]
                name = ("agent_" if len(host) == 1 else "agents_") + "-".join(
                    str(s.robot_id) for s in host)
                child = children.start(name, args)
                agents.update({s.robot_id: child for s in host})
            run.agent_processes = len(hosts)
            _write_manifest(out, sc, settings, endpoint, swarm,
                            {"router": router_pid,
                             **{c.name: c.pid for c in children.children
                                if c.name.startswith("plant")},
                             **{f"agent_{rid}": c.pid for rid, c in agents.items()}})
            console.print(f"{len(agents)} agents starting" + (
                f" in {len(hosts)} processes (up to {per} a process, {groups} tick groups: "
                f"--agents-per-process, --tick-groups)" if per > 1 else "") + " ...")
            if not wait_until(lambda: presence.alive() >= ids or children.failed(),
                              opts.startup_timeout) or children.failed():
                missing = ids - presence.alive()
                raise SitlError(_failure(
                    f"not every agent came up within {opts.startup_timeout:g} s "
                    f"(--startup-timeout; {len(ids) - len(missing)} of {len(ids)} did): "
                    f"not up: robot(s) {_ids(missing)}", children))

            run.epoch = time.time() + opts.lead_time
            mission = MissionMsg(1, time.time(), run.epoch, sc.formation.center0,
                                 sc.formation.velocity, sc.formation.omega, sc.ids,
                                 sc.formation.offsets)
            router.put(keys.mission, mission.encode())
            console.print(f"mission published; t = 0 at epoch {run.epoch:.3f}")
            _watch(sc, run, children, agents, router, keys, mission, truth, states, presence,
                   opts, console)
            # clean stop: agents first, all at once (zero velocity, IDLE), then the plants
            children.terminate_together(list({c.pid: c for c in agents.values()}.values()))
            children.terminate_all()
        recorder.settle()             # what they published before they ended has arrived
        recorder.close()
        for key, n in recorder.recorded_per_key.items():
            if key.endswith("/state") and (rid := Keys.robot_id_of(key)) is not None:
                run.recorded[rid] = n
        for s in settings:
            path = out / "logs" / f"agent_{s.robot_id}.json"
            if path.exists():
                run.agent_stats[s.robot_id] = json.loads(path.read_text())
        for path in sorted((out / "logs").glob("plant_*.json")):
            run.plant_stats.append(json.loads(path.read_text()))
        return run
    finally:
        try:              # a session that fails to close must not leave the router running
            for thing in reversed(opened):
                thing.close()
            router.close()
        finally:
            router_child.terminate_all()


def _ids(robots: set[int]) -> str:
    return ", ".join(map(str, sorted(robots)))


def _failure(what: str, children: Children) -> str:
    lines = [what + "."]
    for c in children.failed():
        lines.append(f"{c.name} (pid {c.pid}) exited with {c.proc.returncode}; "
                     f"last lines of {c.log_path}:\n{c.tail()}")
    return "\n".join(lines)


def _start_plants(children: Children, sc: Scenario, opts: SitlOptions, swarm: str,
                  endpoint: str, out: Path) -> None:
    ids = [int(i) for i in sc.ids]
    size = opts.robots_per_plant or len(ids)
    for k in range(0, len(ids), size):
        group = ids[k:k + size]
        args = ["plant", "sitl", "--scenario", str(sc.source),
                "--robots", ",".join(map(str, group)),
                "--swarm", swarm, "--zenoh-connect", endpoint,
                "--can-interface", opts.can_interface,
                "--stats", str(out / "logs" / f"plant_{k // size}.json")]
        if opts.robot_profile:
            args += ["--robot", opts.robot_profile]
        if opts.realtime_priority:      # the emulated hardware ahead of the agents
            args += ["--realtime-priority", str(min(opts.realtime_priority + 1, 99))]
        if opts.can_interface == "udp_multicast":
            args += ["--can-channel", opts.can_channel or DEFAULT_GROUP,
                     "--can-base-port", str(opts.can_base_port)]
        elif opts.can_channel:
            args += ["--can-channel", opts.can_channel]
        children.start(f"plant_{k // size}", args)


def _write_manifest(out: Path, sc: Scenario, settings: list[AgentSettings], endpoint: str,
                    swarm: str, pids: dict[str, int] | None = None) -> None:
    """The run manifest: how to attach to each robot (CAN bus, Zenoh, MAVLink, process)."""
    pids = pids or {}
    robots = {str(s.robot_id): {"can": {"interface": s.can.interface, "channel": s.can.channel,
                                        "port": s.can.port, "left_node": s.can.left_node,
                                        "right_node": s.can.right_node},
                                "zenoh": endpoint,
                                "mavlink": {"sysid": s.robot_id, "url": s.mavlink.url},
                                "config": f"config/robot_{s.robot_id}.toml",
                                "pid": pids.get(f"agent_{s.robot_id}")}
              for s in settings}
    tmp = out / "manifest.json.tmp"
    tmp.write_text(json.dumps(
        {"version": 1, "scenario": sc.name, "swarm": swarm, "zenoh_router": endpoint,
         "router_pid": pids.get("router"),
         "plants": {k: v for k, v in pids.items() if k.startswith("plant")},
         "robots": robots}, indent=2) + "\n")
    tmp.replace(out / "manifest.json")


def kill_agent(child: Child, console: Console) -> bool:
    """End a planned death: SIGKILL to the agent's PID (no clean shutdown: it stops
    commanding and publishing at once), its exit collected. False if it had already ended
    (then it is a lost process, not a planned death)."""
    if child.proc.poll() is not None:
        return False
    child.expected_exit = True
    os.kill(child.pid, signal.SIGKILL)       # our child, not yet reaped: the PID is its own
    try:
        child.proc.wait(timeout=5.0)
    except subprocess.TimeoutExpired:
        log.warning("%s (pid %d) still there after SIGKILL", child.name, child.pid)
    console.print(f"{child.name} (pid {child.pid}) killed as the world plans")
    return True


def _watch(sc: Scenario, run: SitlRun, children: Children, agents: Mapping[int, Child],
           router, keys: Keys, mission: MissionMsg, truth: Latest, states: Latest,
           presence: Presence, opts: SitlOptions, console: Console) -> None:
    end = run.epoch + sc.duration
    live = Live(console=console, auto_refresh=False, transient=True) \
        if opts.live and console.is_terminal else None
    last_mission = time.monotonic()
    last_note = 0.0
    kills = sorted((k.at, k.robot) for k in sc.world.kill if k.at <= sc.duration)
    offset = time.time() - time.monotonic()      # s; moves only if the wall clock steps
    cpu_at_epoch = None
    if live:
        live.start()
    try:
        while time.time() < end:
            run.clock_step = max(run.clock_step,
                                 abs(time.time() - time.monotonic() - offset))
            if cpu_at_epoch is None and time.time() >= run.epoch:
                cpu_at_epoch = cpu_times()
            due = run.epoch + kills[0][0] if kills else end
            time.sleep(min(0.1, max(due - time.time(), 0.0)))
            while kills and time.time() >= run.epoch + kills[0][0]:
                _, rid = kills.pop(0)
                now = time.time()
                if kill_agent(agents[rid], console):
                    run.killed[rid] = now - run.epoch
            for child in children.failed():
                if child.name in run.lost:
                    continue
                run.lost[child.name] = child.proc.returncode
                child.expected_exit = True
                console.print(f"[red]{child.name} (pid {child.pid}) exited with "
                              f"{child.proc.returncode}[/red]")
                if child.name.startswith("plant"):
                    raise SitlError(_failure("the plant died", children)
                                    + f"\n{child.tail()}")
            if time.monotonic() - last_mission > 1.0:        # for late or lossy joiners
                router.put(keys.mission, mission.encode())
                last_mission = time.monotonic()
            t = time.time() - run.epoch
            if live:
                live.update(_status_table(sc, states.snapshot(), truth.snapshot(),
                                          presence.alive(), t), refresh=True)
            elif time.monotonic() - last_note > 5.0:
                last_note = time.monotonic()
                console.print(f"t = {t:5.1f} s of {sc.duration:g} s, "
                              f"{len(presence.alive())}/{len(sc.ids)} agents alive")
        cpu_at_end = cpu_times()
        run.cpu_steal = steal_share(cpu_at_epoch, cpu_at_end)
        run.cpu_busy = busy_share(cpu_at_epoch, cpu_at_end)
    finally:
        if live:
            live.stop()
