"""The ``boundswarm`` command line: parse, build the config, call the library, print.

Exit codes: 0 success; 1 the run finished but was not safe (a collision); 2 bad input
(scenario, config or run folder), with a message naming what is wrong.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

from rich.console import Console

from agent.config import ConfigError, check_braking_margin
from firmware_sim.batch import SimOptions, simulate
from firmware_sim.plant import PlantKind
from hil import run_folder
from hil.console import LazyProgress, summary_table
from hil.figures import draw_figures
from hil.scenario import ScenarioError, load_scenario

EXIT_OK, EXIT_UNSAFE, EXIT_BAD_INPUT = 0, 1, 2


def cmd_sim(args: argparse.Namespace, console: Console) -> int:
    """Batch simulation of a scenario into a run folder."""
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


def cmd_report(args: argparse.Namespace, console: Console) -> int:
    """Redraw the figures of a saved run and show its metrics."""
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
    except (ScenarioError, ConfigError, run_folder.RunFolderError, ValueError) as exc:
        print(f"boundswarm {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"boundswarm {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
