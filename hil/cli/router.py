"""``boundswarm router``: a Zenoh router (the ground station's) until Ctrl-C."""
from __future__ import annotations

import argparse
import signal
import threading

from rich.console import Console

from hil.cli.exit_codes import EXIT_OK
from hil.cli.options import Subparsers, priority, zenoh_file


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("router", help="run a Zenoh router from a config file")
    p.add_argument("--config", required=True, help="zenoh config (JSON5)")
    p.add_argument("--realtime-priority", type=priority, default=0, metavar="P",
                   help="the router's threads run SCHED_FIFO at priority P (1..99; needs "
                        "root or RLIMIT_RTPRIO, else a warning; 0: normal scheduling)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace, console: Console) -> int:
    """Open the router's session and keep it until SIGINT/SIGTERM."""
    from agent.loop import use_realtime
    from transport.zenoh_link import open_session
    conf = zenoh_file(args.config)
    # Zenoh's threads, started by and after the session, inherit this thread's scheduling
    # (which itself only waits for a signal)
    if args.realtime_priority > 0:
        use_realtime(args.realtime_priority)
    session = open_session(conf, "the router")
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    console.print(f"router running ({args.config}); Ctrl-C stops")
    try:
        stop.wait()
    finally:
        session.close()
    return EXIT_OK
