"""The ``boundswarm`` command line: parse, build the config, call the library, print.

Exit codes: 0 success; 1 the run finished but was not safe (a collision); 2 bad input
(scenario, config or run folder), with a message naming what is wrong; 3 (sitl) a process
of the swarm was lost during the run; 4 (sitl) the swarm could not be run.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

from rich.console import Console

from firmware_sim.plant import PlantKind
from hil.console import LazyProgress, summary_table
from transport.canbus import BusOpenError

EXIT_OK, EXIT_UNSAFE, EXIT_BAD_INPUT, EXIT_LOST, EXIT_FAILED = 0, 1, 2, 3, 4


def cmd_sim(args: argparse.Namespace, console: Console) -> int:
    """Batch simulation of a scenario into a run folder."""
    from agent.config import check_braking_margin
    from firmware_sim.batch import SimOptions, simulate
    from hil import run_folder
    from hil.figures import draw_figures
    from hil.scenario import load_scenario
    sc = load_scenario(args.scenario)
    options = SimOptions(duration=args.duration or sc.duration,
                         sensing_range=sc.sensing_range,
                         substeps=args.substeps or sc.substeps,
                         plant=PlantKind(args.plant) if args.plant else sc.plant,
                         record_every=args.record_every)
    if options.plant is PlantKind.WHEELS:
        check_braking_margin(sc.control, sc.robot, strict=args.strict)
    started = time.perf_counter()
    with LazyProgress(console, f"sim {sc.name}") as progress:
        result = simulate(sc.ids, sc.poses, sc.formation, sc.obstacles, sc.control, sc.robot,
                          options, progress=progress)
    elapsed = time.perf_counter() - started
    metrics = result.metrics.summary(sc.name, options.duration)
    metrics["plant"] = options.plant.value
    metrics["compute_seconds"] = round(elapsed, 3)
    out = Path(args.out)
    data = run_folder.RunData.from_result(result)
    run_folder.write_run(out, metrics, data, sc.source.read_text() if sc.source else None)
    if options.record_every:
        draw_figures(data, sc.obstacles, sc.control.a, sc.control.b, out / run_folder.FIGURES)
    console.print(summary_table(metrics, f"{sc.name}: {len(sc.ids)} robots, "
                                         f"{options.duration:g} s simulated in {elapsed:.2f} s"))
    console.print(f"metrics: {out / run_folder.METRICS}\nfigures: {out / run_folder.FIGURES}/")
    return EXIT_OK if metrics["collisions"] == 0 else EXIT_UNSAFE


def _percentiles(values: list) -> dict:
    import numpy as np
    a = np.asarray([v for v in values if v is not None], dtype=float)
    if not a.size:
        return {"p50": None, "p99": None, "max": None}
    return {"p50": float(np.percentile(a, 50)), "p99": float(np.percentile(a, 99)),
            "max": float(a.max())}


def cmd_sitl(args: argparse.Namespace, console: Console) -> int:
    """The SITL swarm on a scenario, recorded into a run folder."""
    from agent.settings import near_radius_problem
    from hil import run_folder
    from hil.figures import draw_figures
    from hil.scenario import load_scenario
    from hil.sitl import SitlError, SitlOptions, run_sitl
    from hil.sitl_report import analyse_recording, missed_in
    sc = load_scenario(args.scenario)
    if args.duration:
        import dataclasses
        sc = dataclasses.replace(sc, duration=args.duration)
    out = Path(args.out)
    opts = SitlOptions(can_interface=args.can_interface, can_channel=args.can_channel,
                       can_base_port=args.can_base_port,
                       robots_per_plant=args.robots_per_plant, live=not args.no_live,
                       gcs_port=args.gcs_port, near_radius=args.near_radius,
                       mavlink_key=str(Path(args.mavlink_key).resolve()) if args.mavlink_key
                       else None, realtime_priority=args.realtime_priority)
    if opts.mavlink_key:
        from transport.mavlink_signing import load_signing_key
        try:
            load_signing_key(Path(opts.mavlink_key))
        except (OSError, ValueError) as exc:
            print(f"boundswarm sitl: --mavlink-key: {exc}", file=sys.stderr)
            return 2
    if problem := near_radius_problem(opts.near_radius, sc.sensing_range):
        print(f"boundswarm sitl: --near-radius {problem}", file=sys.stderr)
        return 2
    started = time.perf_counter()
    try:
        run = run_sitl(sc, out, opts, console)
    except SitlError as exc:
        print(f"boundswarm sitl: {exc}", file=sys.stderr)
        return EXIT_FAILED
    data, result, extra = analyse_recording(out / "run.mcap", sc)
    metrics = result.summary(sc.name, sc.duration)
    loops = {rid: st["loop"] for rid, st in run.agent_stats.items()}
    mission_misses = {rid: missed_in(lp, extra["epoch"], extra["epoch"] + sc.duration)
                      for rid, lp in loops.items()}
    metrics["sitl"] = {
        "wall_seconds": round(time.perf_counter() - started, 2),
        "agents_reporting": len(run.agent_stats),
        "lost_processes": run.lost,
        "deadline_misses": sum(lp["overruns"] for lp in loops.values()),
        "deadline_misses_in_mission": sum(mission_misses.values()),
        "missed_in_mission_per_agent": mission_misses,
        "period_jitter_ms": _percentiles([lp["jitter"]["p99_ms"] for lp in loops.values()]),
        "jitter_p50_ms_per_agent": {r: lp["jitter"]["p50_ms"] for r, lp in loops.items()},
        "jitter_p99_ms_per_agent": {r: lp["jitter"]["p99_ms"] for r, lp in loops.items()},
        "jitter_max_ms_per_agent": {r: lp["jitter"]["max_ms"] for r, lp in loops.items()},
        "compute_p99_ms_per_agent": {r: lp["compute"]["p99_ms"] for r, lp in loops.items()},
        "neighbour_age_ms": {r: st["agent"]["neighbour_age_ms"]
                             for r, st in run.agent_stats.items()},
        "failsafes": {r: st["failsafe"] for r, st in run.agent_stats.items() if st["failsafe"]},
        "can": {r: st["can"] for r, st in run.agent_stats.items()},
        "zenoh_dropped": {r: {**st["zenoh"]["states"]["dropped"],
                              **{f"beacon_{k}": v for k, v in
                                 st["zenoh"].get("beacons", {}).get("dropped", {}).items()}}
                          for r, st in run.agent_stats.items()},
        "watchdog_trips": {k: v for p in run.plant_stats
                           for k, v in p.get("watchdog_trips", {}).items()},
        "plant_overruns": sum(p["overruns"] for p in run.plant_stats),
        "cpu_share": {**{f"agent_{r}": round(st["cpu_seconds"] / st["wall_seconds"], 3)
                         for r, st in run.agent_stats.items()},
                      **{f"plant_{k}": round(p["cpu_seconds"] / p["wall_seconds"], 3)
                         for k, p in enumerate(run.plant_stats)}},
    }
    run_folder.write_run(out, metrics, data, sc.source.read_text() if sc.source else None)
    draw_figures(data, sc.obstacles, sc.control.a, sc.control.b, out / run_folder.FIGURES)
    console.print(summary_table(metrics, f"SITL {sc.name}: {len(sc.ids)} agents"))
    s = metrics["sitl"]
    console.print(f"deadline misses: {s['deadline_misses_in_mission']} in the mission, "
                  f"{s['deadline_misses']} in all (start-up included), watchdog trips: "
                  f"{sum(s['watchdog_trips'].values())}, lost: {s['lost_processes'] or 'none'}")
    if s["deadline_misses_in_mission"]:
        console.print(f"[yellow]warning: {s['deadline_misses_in_mission']} control periods "
                      f"missed in the mission: this machine could not run {len(sc.ids)} agents "
                      f"in real time; late periods and stale neighbour data eat the braking "
                      f"margin, so the safety of this run is not representative (fewer "
                      f"robots, or more cores)[/yellow]")
    console.print(f"metrics: {out / run_folder.METRICS}\nfigures: {out / run_folder.FIGURES}/"
                  f"\nrecording: {out / 'run.mcap'} (Foxglove, mcap tools)")
    if metrics["collisions"]:
        return EXIT_UNSAFE
    return EXIT_LOST if run.lost else EXIT_OK


def cmd_deploy(args: argparse.Namespace, console: Console) -> int:
    """Bundles for robot computers and the ground station."""
    from hil.deploy import deploy, load_manifest
    manifest = load_manifest(args.manifest)
    bundles = deploy(manifest, Path(args.out))
    for name, path in bundles.items():
        console.print(f"{name}: {path}")
    console.print("copy each robot-<id> folder to its robot and run its install.sh as root; "
                  "see ground/README.md for the ground station")
    return EXIT_OK


def cmd_router(args: argparse.Namespace, console: Console) -> int:
    """A Zenoh router (the ground station's), until Ctrl-C."""
    import signal
    import threading
    from transport.zenoh_link import config_from_file, open_session
    session = open_session(config_from_file(args.config), "the router")
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    console.print(f"router running ({args.config}); Ctrl-C stops")
    try:
        stop.wait()
    finally:
        session.close()
    return EXIT_OK


def cmd_mission(args: argparse.Namespace, console: Console) -> int:
    """Publish the mission (formation and shared epoch) to a swarm."""
    from common.payloads import MissionMsg
    from transport.zenoh_link import (Keys, Presence, config_from_file, open_session,
                                      session_config)
    from hil.processes import wait_until
    from hil.scenario import load_scenario
    sc = load_scenario(args.scenario)
    conf = (config_from_file(args.config) if args.config
            else session_config("client", connect=args.connect or []))
    session = open_session(conf, "the mission publisher")
    try:
        keys = Keys(args.swarm)
        presence = Presence(session, keys)
        ids = {int(i) for i in sc.ids}
        if not wait_until(lambda: presence.alive() >= ids, args.wait):
            missing = sorted(ids - presence.alive())
            raise ValueError(f"mission: robots {missing} are not alive after {args.wait:g} s")
        epoch = time.time() + args.start_in
        msg = MissionMsg(1, time.time(), epoch, sc.formation.center0, sc.formation.velocity,
                         sc.formation.omega, sc.ids, sc.formation.offsets)
        for _ in range(3):                       # late subscribers get it too
            session.put(keys.mission, msg.encode())
            time.sleep(0.2)
        console.print(f"mission of {sc.name} published to {args.swarm}: t = 0 in "
                      f"{args.start_in:g} s (epoch {epoch:.3f})")
        presence.close()
    finally:
        session.close()
    return EXIT_OK


def cmd_record(args: argparse.Namespace, console: Console) -> int:
    """Record a swarm's Zenoh traffic into an MCAP file."""
    import signal
    import threading
    from hil.recorder import Recorder
    from transport.zenoh_link import Keys, config_from_file, open_session, session_config
    conf = (config_from_file(args.config) if args.config
            else session_config("client", connect=args.connect or []))
    session = open_session(conf, "the recorder")
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    recorder = Recorder(session, Keys(args.swarm), Path(args.out))
    try:
        stop.wait(args.duration)
    finally:
        recorder.close()
        session.close()
    console.print(f"{recorder.recorded} messages recorded into {args.out}")
    return EXIT_OK


def cmd_report(args: argparse.Namespace, console: Console) -> int:
    """Redraw the figures of a saved run and show its metrics."""
    from hil import run_folder
    from hil.figures import draw_figures
    from hil.scenario import load_scenario
    run = Path(args.run)
    sc = load_scenario(run / run_folder.SCENARIO)
    data = run_folder.read_run(run)
    paths = draw_figures(data, sc.obstacles, sc.control.a, sc.control.b,
                         run / run_folder.FIGURES)
    try:
        metrics = json.loads((run / run_folder.METRICS).read_text())
        console.print(summary_table(metrics, f"{run}"))
    except (OSError, ValueError) as exc:
        console.print(f"[yellow]no readable {run_folder.METRICS}: {exc}[/yellow]")
    console.print(f"{len(paths)} figures in {run / run_folder.FIGURES}/")
    return EXIT_OK


def cmd_agent(args: argparse.Namespace, console: Console) -> int:
    """One agent process (what runs on a robot computer)."""
    from agent.process import run_agent
    from agent.settings import load_settings
    settings = load_settings(args.config)
    run_agent(settings, Path(args.stats) if args.stats else None)
    return EXIT_OK


def _can_ports(args: argparse.Namespace, ids: list[int]) -> dict[int, int]:
    return {rid: args.can_base_port + rid for rid in ids} if args.can_base_port else {}


def cmd_plant(args: argparse.Namespace, console: Console) -> int:
    """The SITL plant, or one robot's emulated drivers only (HIL bench)."""
    from firmware_sim.odrive_sim import DriverPair
    from firmware_sim.plant_process import (check_drivers_rate, run_drivers_only,
                                            run_sitl_plant)
    from transport.canbus import open_bus
    from transport.zenoh_link import config_from_file, session_config
    conf = (config_from_file(args.zenoh_config) if args.zenoh_config else
            session_config("client", connect=args.zenoh_connect) if args.zenoh_connect
            else None)
    if args.drivers_only:
        check_drivers_rate(args.rate)                    # before the bus is opened
        bus = open_bus(args.can_interface, args.can_channel, port=args.can_port)
        drivers = DriverPair(bus, right_node=args.right_node, left_node=args.left_node)
        drivers.configure(vel_limit=args.vel_limit, ramp=args.ramp, watchdog=args.watchdog)
        console.print(f"emulated drivers (nodes {args.left_node} left, {args.right_node} "
                      f"right) on {args.can_interface} {args.can_channel or ''}; Ctrl-C stops")
        if conf is None:
            run_drivers_only(drivers, rate=args.rate)
            return EXIT_OK
        if not (args.robot and args.swarm):
            raise ValueError("plant --drivers-only with zenoh needs --robot and --swarm")
        from common.payloads import WheelsMsg
        from transport.zenoh_link import Keys, open_session
        session = open_session(conf, f"drivers of robot {args.robot}")
        pub = session.declare_publisher(Keys(args.swarm).wheels(args.robot))
        seq = [0]

        def publish(right_pos: float, left_pos: float, right_vel: float, left_vel: float,
                    stamp: float) -> None:
            seq[0] += 1
            pub.put(WheelsMsg(args.robot, seq[0], stamp, right_pos, left_pos, right_vel,
                              left_vel).encode())
        try:
            run_drivers_only(drivers, rate=args.rate, publish_wheels=publish)
        finally:
            session.close()
        return EXIT_OK
    from hil.scenario import load_scenario
    if args.world_only:
        from firmware_sim.plant_process import run_world
        if not (args.scenario and args.swarm and conf is not None):
            raise ValueError("plant --world-only needs --scenario, --swarm and a zenoh "
                             "endpoint (--zenoh-connect or --zenoh-config)")
        stats = run_world(load_scenario(args.scenario), args.swarm, conf)
        if args.stats:
            Path(args.stats).write_text(json.dumps(stats, indent=2) + "\n")
        return EXIT_OK
    if not (args.scenario and args.swarm and args.zenoh_connect):
        raise ValueError("plant: give --drivers-only, or --scenario, --swarm and "
                         "--zenoh-connect for a SITL plant")
    sc = load_scenario(args.scenario)
    ids = [int(x) for x in args.robots.split(",")] if args.robots else [int(i) for i in sc.ids]
    unknown = sorted(set(ids) - {int(i) for i in sc.ids})
    if unknown:
        raise ValueError(f"plant: robots {unknown} are not in {args.scenario}")
    stats = run_sitl_plant(sc, ids, args.swarm, args.zenoh_connect, args.can_interface,
                           args.can_channel, _can_ports(args, ids), watchdog=args.watchdog,
                           realtime_priority=args.realtime_priority)
    if args.stats:
        Path(args.stats).write_text(json.dumps(stats, indent=2) + "\n")
    return EXIT_OK


def add_can_options(p: argparse.ArgumentParser, default_interface: str = "udp_multicast"
                    ) -> None:
    """CAN options in python-can's own names."""
    p.add_argument("--can-interface", default=default_interface,
                   help="python-can interface: socketcan, udp_multicast, virtual or auto")
    p.add_argument("--can-channel", help="socketcan: vcan0/can0; udp_multicast: an "
                                         "interface-local group ff11::...")


def _priority(text: str) -> int:
    """A SCHED_FIFO priority option: 0 (normal scheduling) or 1..99."""
    if not (text.isdigit() and int(text) <= 99):
        raise argparse.ArgumentTypeError(f"expected 0..99, got {text!r}")
    return int(text)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="boundswarm", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("sim", help="batch simulation of a scenario (in-process, vectorised)")
    sim.add_argument("scenario", help="scenario file (TOML)")
    sim.add_argument("--out", required=True, help="run folder to write")
    sim.add_argument("--duration", type=float, help="override the scenario's duration [s]")
    sim.add_argument("--plant", choices=[k.value for k in PlantKind],
                     help="ideal unicycle, or wheels with the drivers' speed limit and ramp")
    sim.add_argument("--substeps", type=int, help="physics steps per control period")
    sim.add_argument("--record-every", type=int, default=1, metavar="K",
                     help="record one control period in K (0: metrics only, no figures)")
    sim.add_argument("--strict", action="store_true",
                     help="refuse a configuration that breaks the braking margin")
    sim.set_defaults(func=cmd_sim)

    sitl = sub.add_parser("sitl", help="SITL swarm: router, plant, one agent process per robot")
    sitl.add_argument("scenario", help="scenario file (TOML)")
    sitl.add_argument("--out", required=True, help="run folder to write")
    sitl.add_argument("--duration", type=float, help="override the scenario's duration [s]")
    add_can_options(sitl)
    sitl.add_argument("--can-base-port", type=int, default=43200,
                      help="udp_multicast: robot ID's bus on port BASE + ID")
    sitl.add_argument("--robots-per-plant", type=int, default=0,
                      help="robots hosted by one plant process (0: all in one)")
    sitl.add_argument("--no-live", action="store_true", help="no live status table")
    sitl.add_argument("--gcs-port", type=int, default=14550,
                      help="UDP port of the ground station on 127.0.0.1 (0: no MAVLink)")
    sitl.add_argument("--mavlink-key", metavar="FILE",
                      help="MAVLink 2 signing key of every agent (32 bytes, or a passphrase "
                           "as MAVProxy's 'signing key' hashes it); unsigned commands refused")
    sitl.add_argument("--realtime-priority", type=_priority, default=10, metavar="P",
                      help="agents' control loops run SCHED_FIFO at priority P (1..99; needs "
                           "root or RLIMIT_RTPRIO, else a warning; 0: normal scheduling)")
    sitl.add_argument("--near-radius", type=float, default=0.0, metavar="M",
                      help="agents take full-rate states only from robots within M metres "
                           "and 5 Hz beacons from the rest (0: every robot at full rate)")
    sitl.set_defaults(func=cmd_sitl)

    agent = sub.add_parser("agent", help="one agent process (what runs on a robot computer)")
    agent.add_argument("--config", required=True, help="agent config file (TOML)")
    agent.add_argument("--stats", help="write loop and link statistics (JSON) at exit")
    agent.set_defaults(func=cmd_agent)

    plant = sub.add_parser("plant", help="the SITL plant, or emulated drivers only")
    plant.add_argument("--drivers-only", action="store_true",
                       help="serve one robot's two emulated drivers on the bus (HIL bench); "
                            "with zenoh options, also publish their wheel speeds")
    plant.add_argument("--world-only", action="store_true",
                       help="multi-host SITL: move the robots from the wheel speeds their "
                            "remote drivers publish")
    plant.add_argument("--robot", type=int, help="drivers-only with zenoh: the robot id")
    plant.add_argument("--realtime-priority", type=_priority, default=0, metavar="P",
                       help="SITL plant: its loop runs SCHED_FIFO at P (0: normal)")
    plant.add_argument("--rate", type=float, default=200.0, metavar="HZ",
                       help="drivers-only: loop rate (encoder estimates go out at 100 Hz)")
    plant.add_argument("--zenoh-config", help="zenoh config file (JSON5), e.g. with TLS")
    add_can_options(plant)
    plant.add_argument("--can-port", type=int, help="udp_multicast port of the bus")
    plant.add_argument("--can-base-port", type=int,
                       help="SITL: robot ID's udp_multicast bus is on port BASE + ID")
    plant.add_argument("--left-node", type=int, default=0, help="left wheel node id")
    plant.add_argument("--right-node", type=int, default=1, help="right wheel node id")
    plant.add_argument("--vel-limit", type=float, default=10.0, help="rev/s")
    plant.add_argument("--ramp", type=float, default=1000.0, help="rev/s^2")
    plant.add_argument("--watchdog", type=float, default=0.1, help="s (0 disables)")
    plant.add_argument("--scenario", help="SITL: scenario file")
    plant.add_argument("--robots", help="SITL: comma-separated robot ids to host (default all)")
    plant.add_argument("--swarm", help="SITL: swarm name (Zenoh key prefix)")
    plant.add_argument("--zenoh-connect", action="append", help="SITL: router endpoint")
    plant.add_argument("--stats", help="write loop statistics (JSON) at exit")
    plant.set_defaults(func=cmd_plant)

    from hil import can_cli
    can_cli.add_parser(sub, add_can_options)

    deploy = sub.add_parser("deploy", help="bundles for robot computers and the ground station")
    deploy.add_argument("manifest", help="swarm manifest (TOML)")
    deploy.add_argument("--out", required=True, help="folder for the bundles")
    deploy.set_defaults(func=cmd_deploy)

    router = sub.add_parser("router", help="run a Zenoh router from a config file")
    router.add_argument("--config", required=True, help="zenoh config (JSON5)")
    router.set_defaults(func=cmd_router)

    mission = sub.add_parser("mission", help="publish a scenario's mission to a swarm")
    mission.add_argument("--scenario", required=True)
    mission.add_argument("--swarm", required=True)
    mission.add_argument("--config", help="zenoh client config (JSON5), e.g. with TLS")
    mission.add_argument("--connect", action="append", help="router endpoint (no config)")
    mission.add_argument("--start-in", type=float, default=5.0, help="s until t = 0")
    mission.add_argument("--wait", type=float, default=30.0,
                         help="s to wait for every robot's liveliness token")
    mission.set_defaults(func=cmd_mission)

    record = sub.add_parser("record", help="record a swarm's Zenoh traffic (MCAP)")
    record.add_argument("--swarm", required=True)
    record.add_argument("--out", required=True, help="MCAP file to write")
    record.add_argument("--config", help="zenoh client config (JSON5), e.g. with TLS")
    record.add_argument("--connect", action="append", help="router endpoint (no config)")
    record.add_argument("--duration", type=float, help="s (default: until Ctrl-C)")
    record.set_defaults(func=cmd_record)

    report = sub.add_parser("report", help="figures and metrics from a recorded run")
    report.add_argument("run", help="run folder written by sim or sitl")
    report.set_defaults(func=cmd_report)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    console = Console()
    try:
        return args.func(args, console)
    except (ValueError, BusOpenError, ConnectionError, OSError) as exc:
        # ValueError covers ScenarioError, ConfigError and RunFolderError
        print(f"boundswarm {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"boundswarm {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
