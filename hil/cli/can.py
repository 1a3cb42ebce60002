"""``boundswarm can ...``: inspect a robot's CAN traffic, live or from a log.

    can monitor   live decoded view of one bus: per message and node, rates against the DBC
                  cycle times, ages, signals with units and names, bus load, alarms
    can stats     the same as JSON after --duration seconds (for scripts)
    can log FILE  record to a python-can file format (.log candump, .asc, .blf)
    can decode    decode a log file, or candump -L lines on standard input (a filter)
    can replay    send a log onto a bus with its timing; refuses command frames on a bus
                  where an armed agent is writing, unless --force

A bus is named in python-can terms (--can-interface, --can-channel, --can-port) or by a
SITL run and robot (--run DIR --robot ID, read from the run manifest).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import can
from rich.console import Console, Group
from rich.live import Live
from rich.table import Table

from agent.config import RobotParams
from common.schema import add_argument_for
from hil.cli.exit_codes import EXIT_BAD_INPUT, EXIT_OK, BadInput
from hil.cli.options import Subparsers, add_can_options, positive
from hil.ground.can_inspect import BusStats
from transport.canbus import open_bus
from transport.odrive_frames import AxisState, Cmd, FrameError, decode, message_name

COMMAND_CMDS = {Cmd.SET_AXIS_STATE, Cmd.SET_CONTROLLER_MODE, Cmd.SET_INPUT_VEL, Cmd.SET_LIMITS,
                Cmd.ESTOP, Cmd.CLEAR_ERRORS}


def bus_from_args(args: argparse.Namespace) -> tuple[can.BusABC, str]:
    """Open the bus the arguments name; returns it and a description."""
    if args.run:
        try:
            manifest = json.loads((Path(args.run) / "manifest.json").read_text())
        except (OSError, ValueError) as exc:
            raise BadInput(f"{args.run}: no readable manifest.json ({exc})") from None
        robot = manifest.get("robots", {}).get(str(args.robot))
        if robot is None:
            raise BadInput(f"{args.run}: no robot {args.robot} in the manifest "
                             f"(robots: {', '.join(manifest.get('robots', {}))})")
        c = robot["can"]
        return (open_bus(c["interface"], c["channel"], port=c.get("port")),
                f"robot {args.robot} of {args.run}: {c['interface']} {c['channel']}"
                + (f" port {c['port']}" if c.get("port") else ""))
    if not args.can_channel and args.can_interface != "auto":
        raise BadInput("name a bus: --can-interface/--can-channel (--can-port), or "
                         "--run DIR --robot ID")
    return (open_bus(args.can_interface, args.can_channel, port=args.can_port),
            f"{args.can_interface} {args.can_channel or ''}")


def _stats(args: argparse.Namespace) -> BusStats:
    return BusStats(bitrate=args.bitrate, vel_limit=args.vel_limit,
                    nodes=set(args.node) if args.node else None,
                    messages=set(args.message) if args.message else None)


def _drain(bus: can.BusABC, stats: BusStats, until: float) -> None:
    while time.time() < until:
        msg = bus.recv(max(0.0, min(0.05, until - time.time())))
        if msg is not None:
            stats.feed(msg)


def _view(stats: BusStats, now: float, title: str) -> Group:
    table = Table(title=title, header_style="bold")
    for col in ("node", "side", "message", "rate [Hz]", "DBC [Hz]", "age [s]", "count",
                "signals"):
        table.add_column(col, justify="right" if col not in ("message", "signals") else "left")
    doc = stats.summary(now)
    for m in doc["messages"]:
        table.add_row(str(m["node"]), m["side"] or "-", m["name"], f"{m['rate_hz']:.1f}",
                      "-" if m["expected_hz"] is None else f"{m['expected_hz']:.0f}",
                      f"{m['age_s']:.2f}", str(m["count"]), stats.describe(m["name"],
                                                                           m["signals"]))
    alarms = Table(show_header=False, box=None)
    for a in doc["alarms"]:
        alarms.add_row(f"[red]{a['kind']}[/red]", f"node {a['node']}" if a["node"] is not None
                       else "", a["detail"])
    load = f"bus load {doc['bus_load']:.1%} of {stats.bitrate / 1000:g} kbit/s"
    return Group(table, load, alarms if doc["alarms"] else "no alarms")


def cmd_monitor(args: argparse.Namespace, console: Console) -> int:
    bus, what = bus_from_args(args)
    stats = _stats(args)
    try:
        with Live(console=console, auto_refresh=False) as live:
            while True:
                _drain(bus, stats, time.time() + 0.25)
                live.update(_view(stats, time.time(), what), refresh=True)
    except KeyboardInterrupt:
        return EXIT_OK
    finally:
        bus.shutdown()


def cmd_stats(args: argparse.Namespace, console: Console) -> int:
    bus, what = bus_from_args(args)
    stats = _stats(args)
    try:
        _drain(bus, stats, time.time() + args.duration)
    finally:
        bus.shutdown()
    doc = stats.summary(time.time())
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        console.print(_view(stats, time.time(), what))
    return EXIT_OK


def cmd_log(args: argparse.Namespace, console: Console) -> int:
    bus, what = bus_from_args(args)
    n = 0
    end = time.time() + args.duration if args.duration else None
    try:
        with can.Logger(args.file) as logger:
            console.print(f"logging {what} to {args.file}; Ctrl-C stops")
            while end is None or time.time() < end:
                msg = bus.recv(0.1)
                if msg is not None:
                    logger.on_message_received(msg)
                    n += 1
    except KeyboardInterrupt:
        pass
    finally:
        bus.shutdown()
    console.print(f"{n} frames written to {args.file}")
    return EXIT_OK


def _read_log(source: str) -> Iterable[can.Message]:
    if source == "-":
        return can.CanutilsLogReader(sys.stdin)
    if not Path(source).exists():
        raise BadInput(f"{source}: no such log file")
    return can.LogReader(source)


def cmd_decode(args: argparse.Namespace, console: Console) -> int:
    stats = BusStats()
    for msg in _read_log(args.file):
        try:
            frame = decode(msg)
            name = message_name(frame.cmd)
            text = (f"{name}{' (RTR)' if frame.rtr else ''} node {frame.node}: "
                    + stats.describe(name, frame.signals))
        except FrameError as exc:
            text = f"not decoded: {exc}"
        data = msg.data.hex().upper() if not msg.is_remote_frame else "R"
        print(f"({msg.timestamp:.6f}) {msg.channel or '-'} {msg.arbitration_id:03X}#{data}"
              f"  {text}", flush=True)
    return EXIT_OK


def armed_writer(bus: can.BusABC, listen: float = 0.5) -> bool:
    """True if, within ``listen`` seconds, an axis reports closed loop and velocity
    commands are being written (an armed agent is driving the wheels)."""
    closed = commands = False
    end = time.monotonic() + listen
    while time.monotonic() < end:
        msg = bus.recv(0.05)
        if msg is None:
            continue
        try:
            f = decode(msg)
        except FrameError:
            continue
        if f.cmd == Cmd.HEARTBEAT and not f.rtr and \
                f.signals.get("Axis_State") == AxisState["CLOSED_LOOP_CONTROL"]:
            closed = True
        if f.cmd == Cmd.SET_INPUT_VEL:
            commands = True
    return closed and commands


def cmd_replay(args: argparse.Namespace, console: Console) -> int:
    frames = list(_read_log(args.file))
    commands = [m for m in frames if _is_command(m)]
    bus, what = bus_from_args(args)
    try:
        if commands and not args.force and armed_writer(bus):
            print(f"boundswarm can replay: refused: {args.file} holds {len(commands)} command "
                  f"frame(s) and an armed agent is writing on {what}; use --force to replay "
                  f"anyway", file=sys.stderr)
            return EXIT_BAD_INPUT
        sent = replay(bus, frames, args.speed)
        console.print(f"replayed {sent} frames onto {what}")
        return EXIT_OK
    finally:
        bus.shutdown()


def replay(bus: can.BusABC, frames: list[can.Message], speed: float = 1.0,
           clock: Callable[[], float] | None = None,
           sleep: Callable[[float], None] | None = None) -> int:
    """Send ``frames`` keeping their relative timing (sleep, then spin the last ms) on
    ``clock`` [s] (default: time.perf_counter and time.sleep, looked up at the call)."""
    if not frames:
        return 0
    if speed <= 0:
        raise ValueError(f"replay speed must be > 0, got {speed}")
    clock = clock or time.perf_counter
    sleep = sleep or time.sleep
    start, first = clock(), frames[0].timestamp
    for msg in frames:
        target = start + (msg.timestamp - first) / speed
        while (left := target - clock()) > 0:
            if left > 0.002:
                sleep(left - 0.001)
        bus.send(can.Message(arbitration_id=msg.arbitration_id, data=msg.data,
                             is_extended_id=msg.is_extended_id,
                             is_remote_frame=msg.is_remote_frame, dlc=msg.dlc))
    return len(frames)


def _is_command(msg: can.Message) -> bool:
    try:
        f = decode(msg)
    except FrameError:
        return False
    return f.cmd in COMMAND_CMDS and not f.rtr


def add_parser(sub: Subparsers) -> None:
    """Register ``can`` and its subcommands on the main parser."""
    can_p = sub.add_parser("can", help="CAN inspection: monitor, stats, log, decode, replay")
    can_sub = can_p.add_subparsers(dest="can_command", required=True)

    def bus_options(p: argparse.ArgumentParser) -> None:
        add_can_options(p, default_interface="auto")
        p.add_argument("--can-port", type=int, help="udp_multicast port of the bus")
        p.add_argument("--run", help="SITL run folder (with --robot)")
        p.add_argument("--robot", type=int, help="robot id in the run manifest")
        p.add_argument("--bitrate", type=int, default=500_000, help="bit/s, for the bus load")
        add_argument_for(p, "--vel-limit", RobotParams, "wheel_speed_limit")
        p.add_argument("--node", type=int, action="append", help="only this node (repeatable)")
        p.add_argument("--message", action="append",
                       help="only this message, e.g. HEARTBEAT (repeatable)")

    p = can_sub.add_parser("monitor", help="live decoded view of one bus")
    bus_options(p)
    p.set_defaults(func=cmd_monitor)
    p = can_sub.add_parser("stats", help="rates, load and alarms after --duration, as JSON")
    bus_options(p)
    p.add_argument("--duration", type=float, default=2.0, help="s")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_stats)
    p = can_sub.add_parser("log", help="record to a file (.log candump, .asc, .blf)")
    bus_options(p)
    p.add_argument("file")
    p.add_argument("--duration", type=float, help="s (default: until Ctrl-C)")
    p.set_defaults(func=cmd_log)
    p = can_sub.add_parser("decode", help="decode a log file, or candump -L lines from -")
    p.add_argument("file", help="log file, or - for standard input")
    p.set_defaults(func=cmd_decode)
    p = can_sub.add_parser("replay", help="send a log onto a bus with its timing")
    bus_options(p)
    p.add_argument("file")
    p.add_argument("--force", action="store_true",
                   help="replay command frames even while an armed agent writes")
    p.add_argument("--speed", type=positive, default=1.0, help="time scale (2: twice as fast)")
    p.set_defaults(func=cmd_replay)
