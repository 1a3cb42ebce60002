"""``boundswarm sim``: batch simulation of a scenario into a run folder."""
from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console

from firmware_sim.plant import PlantKind
from hil.cli.console import LazyProgress, summary_table
from hil.cli.exit_codes import EXIT_OK, EXIT_UNSAFE, BadInput
from hil.cli.options import Subparsers

if TYPE_CHECKING:
    from hil.files.scenario import Scenario


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("sim", help="batch simulation of a scenario (in-process, compiled)")
    p.add_argument("scenario", help="scenario file (TOML)")
    p.add_argument("--out", required=True, help="run folder to write")
    p.add_argument("--duration", type=float, help="override the scenario's duration [s]")
    p.add_argument("--plant", choices=[k.value for k in PlantKind],
                   help="ideal unicycle, or wheels with the drivers' speed limit and ramp "
                        "(default: the scenario's; wheels with --robot or a [world] with "
                        "wheel slip or encoder noise)")
    p.add_argument("--robot", metavar="FILE",
                   help="robot profile (robots/*.toml) instead of the scenario's [robot]")
    p.add_argument("--substeps", type=int, help="physics steps per control period")
    p.add_argument("--record-every", type=int, default=1, metavar="K",
                   help="record one control period in K (0: metrics only, no figures)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace, console: Console) -> int:
    """Simulate, write the run folder (metrics, data, figures), print the summary."""
    from firmware_sim.batch import SimOptions, simulate
    from hil.files import run_folder
    from hil.files.figures import draw_figures
    from hil.files.robot_profile import load_robot_profile
    from hil.files.scenario import load_scenario
    sc = load_scenario(args.scenario)
    plant = PlantKind(args.plant) if args.plant else sc.plant
    if args.robot:                  # a real robot's limits apply unless --plant says not
        sc = dataclasses.replace(sc, robot=load_robot_profile(args.robot))
        plant = PlantKind(args.plant) if args.plant else PlantKind.WHEELS
    if sc.world.odometry and plant is PlantKind.IDEAL:
        if args.plant:
            raise BadInput("--plant ideal: the scenario's [world] has wheel slip or encoder "
                           "noise, which need the wheels plant")
        plant = PlantKind.WHEELS
    options = SimOptions(duration=args.duration or sc.duration,
                         sensing_range=sc.sensing_range,
                         substeps=args.substeps or sc.substeps, plant=plant,
                         record_every=args.record_every)
    if sc.mocap is not None and not sc.world.odometry:
        console.print("[yellow]note: the scenario's \\[mocap] changes nothing here: without "
                      "wheel slip or encoder noise in \\[world] every robot knows its pose"
                      "[/yellow]")
    if options.plant is PlantKind.WHEELS:
        state_envelope(console, sc)
    started = time.perf_counter()
    with LazyProgress(console, f"sim {sc.name}") as progress:
        result = simulate(sc.ids, sc.poses, sc.formation, sc.obstacles, sc.control, sc.robot,
                          options, world=sc.world, mocap=sc.mocap, progress=progress)
    elapsed = time.perf_counter() - started
    metrics = result.metrics.summary(sc.name, options.duration)
    metrics["plant"] = options.plant.value
    metrics["robot"] = dataclasses.asdict(sc.robot)
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


def state_envelope(console: Console, sc: Scenario) -> None:
    """Print what the safety governor allows the scenario's robot (agent.config.
    speed_envelope) with neighbour data a link delay and a period old, and warn when the
    formation's places are too close for a robot to pass between two robots in them, or
    one behind another too close for the governor to let a robot keep the pace."""
    envelope = sc.envelope()
    console.print(envelope.describe())
    spacing = sc.formation.min_spacing()
    if spacing <= envelope.passable:
        console.print(f"[yellow]warning: the formation's places are as close as "
                      f"{spacing:.2f} m: with data this old no robot passes between two "
                      f"robots in their places, and one whose place is across the formation "
                      f"waits behind it; give the places more room, or let the mission "
                      f"assign them (\\[formation] assign = \"shortest\")[/yellow]")
    if not sc.pace_held(envelope):
        console.print(f"[yellow]warning: a place lies {sc.formation.min_ahead():.2f} m "
                      f"behind another along the formation's motion: with data this old the "
                      f"governor holds a robot that close behind another below the pace, so "
                      f"it trails its place; give the places more room along the motion or "
                      f"move the formation more slowly[/yellow]")
