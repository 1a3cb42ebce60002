"""``boundswarm report``: redraw the figures of a saved run and show its metrics."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from rich.console import Console

from hil.cli.console import summary_table
from hil.cli.exit_codes import EXIT_OK
from hil.cli.options import Subparsers


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("report", help="figures and metrics from a recorded run")
    p.add_argument("run", help="run folder written by sim or sitl")
    p.set_defaults(func=run)


def run(args: argparse.Namespace, console: Console) -> int:
    """Redraw the run's figures from its data; print its metrics if they are readable."""
    from hil.files import run_folder
    from hil.files.figures import draw_figures
    from hil.files.scenario import load_scenario
    folder = Path(args.run)
    sc = load_scenario(folder / run_folder.SCENARIO)
    data = run_folder.read_run(folder)
    paths = draw_figures(data, sc.obstacles, sc.control.a, sc.control.b,
                         folder / run_folder.FIGURES)
    try:
        metrics = json.loads((folder / run_folder.METRICS).read_text())
        console.print(summary_table(metrics, f"{folder}"))
    except (OSError, ValueError) as exc:
        console.print(f"[yellow]no readable {run_folder.METRICS}: {exc}[/yellow]")
    console.print(f"{len(paths)} figures in {folder / run_folder.FIGURES}/")
    return EXIT_OK
