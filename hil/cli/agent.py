"""``boundswarm agent``: one agent process (what runs on a robot computer)."""
from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from hil.cli.exit_codes import EXIT_OK, BadInput
from hil.cli.options import Subparsers


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("agent", help="one agent process (what runs on a robot computer)")
    p.add_argument("--config", required=True, action="append",
                   help="agent config file (TOML); given again, the process runs each of "
                        "these agents in turn every period (a simulated swarm on fewer cores "
                        "than robots: the same period, tick grid, realtime_priority and "
                        "[zenoh] settings, distinct robot IDs and CAN buses)")
    p.add_argument("--stats", action="append",
                   help="write loop and link statistics (JSON) at exit; one per --config")
    p.set_defaults(func=run)


def run(args: argparse.Namespace, console: Console) -> int:
    """Run the agent(s) of the config(s) until SIGINT/SIGTERM."""
    from agent.process import check_group, run_agents
    from agent.settings import load_settings
    if args.stats is not None and len(args.stats) != len(args.config):
        raise BadInput(f"{len(args.config)} --config but {len(args.stats)} --stats: give one "
                       f"--stats per --config, or none")
    if args.stats is not None and len(set(args.stats)) != len(args.stats):
        raise BadInput(f"--stats: a file given twice: {args.stats}")
    group = [load_settings(path) for path in args.config]
    try:
        check_group(group)
    except ValueError as exc:
        raise BadInput(f"--config: {exc}") from exc
    stats = [Path(p) for p in args.stats] if args.stats else [None] * len(group)
    run_agents(group, stats)
    return EXIT_OK
