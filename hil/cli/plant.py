"""``boundswarm plant ...``: the emulated hardware, as three programs.

    plant sitl      robots of a scenario: each robot's drivers on its own bus, their motion
                    from the drivers' wheel speeds, truth and obstacles on Zenoh (what
                    ``boundswarm sitl`` starts)
    plant drivers   one robot's two emulated drivers on a bus (HIL bench); with Zenoh
                    options, also their wheel positions and speeds for a remote world
    plant world     multi-host SITL: the robots moved by the wheel speeds their remote
                    drivers publish

``plant --drivers-only`` and ``plant --world-only`` are accepted for ``plant drivers`` and
``plant world``.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

from rich.console import Console

from agent.config import RobotParams
from common.schema import add_argument_for
from hil.cli.exit_codes import EXIT_OK, BadInput
from hil.cli.options import (
    Subparsers,
    add_can_options,
    add_zenoh_client_options,
    priority,
    swarm_name,
    zenoh_client,
)
from transport.settings import CanSettings

FLAG_FORMS = {"--drivers-only": "drivers", "--world-only": "world"}


def as_subcommand(argv: list[str]) -> list[str]:
    """``argv`` with ``plant --drivers-only ...`` spelled ``plant drivers ...`` (and
    ``--world-only`` as ``world``); any other command line unchanged."""
    command = next((k for k, a in enumerate(argv) if not a.startswith("-")), None)
    if command is None or argv[command] != "plant":
        return argv
    rest = argv[command + 1:]
    for flag, mode in FLAG_FORMS.items():
        if flag in rest:
            return [*argv[:command + 1], mode, *(a for a in rest if a != flag)]
    return argv


def add_parser(sub: Subparsers) -> None:
    plant = sub.add_parser("plant", help="emulated hardware: sitl, drivers or world",
                           description="The emulated hardware, as three programs. "
                                       + __doc__.split("\n\n")[-1].replace("``", ""))
    modes = plant.add_subparsers(dest="plant_command", required=True)

    p = modes.add_parser("sitl", help="robots of a scenario, each with its drivers on its bus")
    p.add_argument("--scenario", required=True, help="scenario file (TOML)")
    p.add_argument("--robot", metavar="FILE",
                   help="robot profile (robots/*.toml) instead of the scenario's [robot]")
    p.add_argument("--swarm", required=True, type=swarm_name, help="Zenoh key prefix")
    p.add_argument("--zenoh-connect", required=True, action="append", help="router endpoint")
    p.add_argument("--robots", help="comma-separated robot ids to host (default all)")
    add_can_options(p)
    p.add_argument("--can-base-port", type=int,
                   help="robot ID's udp_multicast bus is on port BASE + ID")
    p.add_argument("--no-watchdog", action="store_true",
                   help="the emulated drivers run with their watchdog disabled (default: "
                        "enabled, with the robot's watchdog_timeout)")
    p.add_argument("--realtime-priority", type=priority, default=0, metavar="P",
                   help="the plant's loop runs SCHED_FIFO at P (0: normal scheduling)")
    p.add_argument("--stats", help="write loop statistics (JSON) at exit")
    p.set_defaults(func=run_sitl)

    p = modes.add_parser("drivers", help="one robot's emulated drivers on a bus (HIL bench)")
    add_can_options(p)
    p.add_argument("--can-port", type=int, help="udp_multicast port of the bus")
    add_argument_for(p, "--left-node", CanSettings, "left_node")
    add_argument_for(p, "--right-node", CanSettings, "right_node")
    add_argument_for(p, "--vel-limit", RobotParams, "wheel_speed_limit")
    add_argument_for(p, "--ramp", RobotParams, "wheel_ramp")
    add_argument_for(p, "--watchdog", RobotParams, "watchdog_timeout")
    p.add_argument("--no-watchdog", action="store_true",
                   help="the watchdog disabled (ODrive axis.config.enable_watchdog = False)")
    p.add_argument("--rate", type=_drivers_rate, default=200.0, metavar="HZ",
                   help="loop rate (encoder estimates go out at 100 Hz)")
    p.add_argument("--realtime-priority", type=priority, default=0, metavar="P",
                   help="the drivers' loop runs SCHED_FIFO at P (0: normal scheduling)")
    p.add_argument("--robot", type=int, help="with zenoh: the robot id of the wheels")
    p.add_argument("--swarm", type=swarm_name, help="with zenoh: Zenoh key prefix")
    add_zenoh_client_options(p, required=False, config="--zenoh-config",
                             connect="--zenoh-connect")
    p.set_defaults(func=run_drivers)

    p = modes.add_parser("world", help="robots moved by their remote drivers' wheel speeds")
    p.add_argument("--scenario", required=True, help="scenario file (TOML)")
    p.add_argument("--swarm", required=True, type=swarm_name, help="Zenoh key prefix")
    add_zenoh_client_options(p, required=True, config="--zenoh-config",
                             connect="--zenoh-connect")
    p.add_argument("--realtime-priority", type=priority, default=0, metavar="P",
                   help="the world's loop runs SCHED_FIFO at P (0: normal scheduling)")
    p.add_argument("--stats", help="write loop statistics (JSON) at exit")
    p.set_defaults(func=run_world)


def _drivers_rate(text: str) -> float:
    from firmware_sim.plant_process import check_drivers_rate
    try:
        return check_drivers_rate(float(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _write_stats(path: str | None, stats: dict[str, Any]) -> None:
    if path:
        Path(path).write_text(json.dumps(stats, indent=2) + "\n")


def run_sitl(args: argparse.Namespace, console: Console) -> int:
    """Host the robots of the scenario until SIGINT/SIGTERM."""
    from firmware_sim.plant_process import run_sitl_plant
    from hil.files.robot_profile import load_robot_profile
    from hil.files.scenario import load_scenario
    sc = load_scenario(args.scenario)
    if args.robot:
        sc = dataclasses.replace(sc, robot=load_robot_profile(args.robot))
    known = [int(i) for i in sc.ids]
    try:
        ids = [int(x) for x in args.robots.split(",")] if args.robots else known
    except ValueError:
        raise BadInput(f"--robots: expected comma-separated ids, got {args.robots!r}") from None
    unknown = sorted(set(ids) - set(known))
    if unknown:
        raise BadInput(f"--robots: {unknown} are not in {args.scenario}")
    ports = {rid: args.can_base_port + rid for rid in ids} if args.can_base_port else {}
    stats = run_sitl_plant(sc, ids, args.swarm, args.zenoh_connect, args.can_interface,
                           args.can_channel, ports, enable_watchdog=not args.no_watchdog,
                           realtime_priority=args.realtime_priority)
    _write_stats(args.stats, stats)
    return EXIT_OK


def run_drivers(args: argparse.Namespace, console: Console) -> int:
    """Serve the two drivers until SIGINT/SIGTERM; publish their wheels if Zenoh is given."""
    from firmware_sim.odrive_sim import DriverPair
    from firmware_sim.plant_process import run_drivers_only
    from transport.canbus import open_bus
    conf = (zenoh_client(args.zenoh_config, args.zenoh_connect)
            if args.zenoh_config or args.zenoh_connect else None)
    if conf is not None and (args.robot is None or args.swarm is None):
        raise BadInput("with --zenoh-config or --zenoh-connect, give --robot and --swarm")
    # the flags' values checked as the settings they are (bad values: exit 2, field named)
    limits = RobotParams(wheel_speed_limit=args.vel_limit, wheel_ramp=args.ramp,
                         watchdog_timeout=args.watchdog)
    nodes = CanSettings(left_node=args.left_node, right_node=args.right_node)
    bus = open_bus(args.can_interface, args.can_channel, port=args.can_port)
    pair = DriverPair(bus, left_node=nodes.left_node, right_node=nodes.right_node)
    pair.configure(vel_limit=limits.wheel_speed_limit, ramp=limits.wheel_ramp,
                   enable_watchdog=not args.no_watchdog,
                   watchdog_timeout=limits.watchdog_timeout)
    console.print(f"emulated drivers (nodes {args.left_node} left, {args.right_node} "
                  f"right) on {args.can_interface} {args.can_channel or ''}; Ctrl-C stops")
    if conf is None:
        run_drivers_only(pair, rate=args.rate, realtime_priority=args.realtime_priority)
        return EXIT_OK
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
        run_drivers_only(pair, rate=args.rate, publish_wheels=publish,
                         realtime_priority=args.realtime_priority)
    finally:
        session.close()
    return EXIT_OK


def run_world(args: argparse.Namespace, console: Console) -> int:
    """Move the scenario's robots from their remote drivers until SIGINT/SIGTERM."""
    from firmware_sim.plant_process import run_world as run_remote_world
    from hil.files.scenario import load_scenario
    sc = load_scenario(args.scenario)
    conf = zenoh_client(args.zenoh_config, args.zenoh_connect)
    stats = run_remote_world(sc, args.swarm, conf, realtime_priority=args.realtime_priority)
    _write_stats(args.stats, stats)
    return EXIT_OK
