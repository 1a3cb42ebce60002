"""``boundswarm record``: record a swarm's Zenoh traffic into an MCAP file."""
from __future__ import annotations

import argparse
import signal
import threading
from pathlib import Path

from rich.console import Console

from hil.cli.exit_codes import EXIT_OK
from hil.cli.options import Subparsers, add_zenoh_client_options, swarm_name, zenoh_client


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("record", help="record a swarm's Zenoh traffic (MCAP)")
    p.add_argument("--swarm", required=True, type=swarm_name)
    p.add_argument("--out", required=True, help="MCAP file to write")
    add_zenoh_client_options(p, required=True)
    p.add_argument("--duration", type=float, help="s (default: until Ctrl-C)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace, console: Console) -> int:
    """Record until SIGINT/SIGTERM or ``--duration``."""
    from hil.ground.recorder import Recorder
    from transport.zenoh_link import Keys, open_session
    session = open_session(zenoh_client(args.config, args.connect), "the recorder")
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
