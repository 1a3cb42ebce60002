"""``boundswarm agent``: one agent process (what runs on a robot computer)."""
from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from hil.cli_options import Subparsers
from hil.exit_codes import EXIT_OK


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("agent", help="one agent process (what runs on a robot computer)")
    p.add_argument("--config", required=True, help="agent config file (TOML)")
    p.add_argument("--stats", help="write loop and link statistics (JSON) at exit")
    p.set_defaults(func=run)


def run(args: argparse.Namespace, console: Console) -> int:
    """Run the agent of the config until SIGINT/SIGTERM."""
    from agent.process import run_agent
    from agent.settings import load_settings
    settings = load_settings(args.config)
    run_agent(settings, Path(args.stats) if args.stats else None)
    return EXIT_OK
