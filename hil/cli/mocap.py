"""``boundswarm mocap``: pose fixes from a motion-capture system onto the swarm's Zenoh."""
from __future__ import annotations

import argparse
import json
import signal
import threading
from pathlib import Path

from rich.console import Console

from hil.cli.exit_codes import EXIT_OK
from hil.cli.options import Subparsers


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("mocap", help="motion-capture bridge: each robot's pose fix on Zenoh "
                                     "(ground station; the mocap extra)")
    p.add_argument("--config", required=True, help="bridge config (TOML, docs/formats.md)")
    p.add_argument("--stats", metavar="FILE", help="write frame and fix counters as JSON")
    p.add_argument("--frames", type=int, metavar="N",
                   help="stop after N frames (default: until Ctrl-C)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace, console: Console) -> int:
    """Bridge until SIGINT/SIGTERM (or --frames), then print the counters."""
    from hil.ground.mocap import load_mocap_settings, run_bridge
    settings = load_mocap_settings(args.config)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    console.print(f"bridging {settings.system} to boundswarm/{settings.swarm} "
                  f"({len(settings.bodies)} bodies); Ctrl-C stops")
    counters = run_bridge(settings, stop, max_frames=args.frames)
    console.print(f"{counters['frames']} frames; fixes per robot: {counters['published']}; "
                  f"frames without a body: {counters['missing'] or 'none'}")
    if args.stats:
        Path(args.stats).write_text(json.dumps(counters, indent=2) + "\n")
    return EXIT_OK
