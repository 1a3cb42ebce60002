"""``boundswarm router``: a Zenoh router (the ground station's) until Ctrl-C."""
from __future__ import annotations

import argparse
import signal
import threading

from rich.console import Console

from hil.cli_options import Subparsers, zenoh_file
from hil.exit_codes import EXIT_OK


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("router", help="run a Zenoh router from a config file")
    p.add_argument("--config", required=True, help="zenoh config (JSON5)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace, console: Console) -> int:
    """Open the router's session and keep it until SIGINT/SIGTERM."""
    from transport.zenoh_link import open_session
    session = open_session(zenoh_file(args.config), "the router")
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    console.print(f"router running ({args.config}); Ctrl-C stops")
    try:
        stop.wait()
    finally:
        session.close()
    return EXIT_OK
