"""``boundswarm campaign``: a spec's runs on Dask into a campaign folder, its report, and
the replay of one run into a run folder."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from rich.console import Console

from hil.cli.exit_codes import EXIT_FAILED, EXIT_OK, BadInput
from hil.cli.options import Subparsers

COMPARED = ("min_pair_distance", "min_obstacle_clearance", "converged", "convergence_time",
            "collisions")


def _workers(text: str) -> int:
    if not (text.isdigit() and int(text) >= 1):
        raise argparse.ArgumentTypeError(f"expected a number of workers >= 1, got {text!r}")
    return int(text)


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("campaign", help="many batch runs on Dask: families x seeds x "
                                        "profiles x world x gains, with a report")
    p.add_argument("spec", help="campaign spec (TOML), or a campaign folder (resumes it, "
                                "or with --replay replays one of its runs)")
    p.add_argument("--out", help="campaign folder to write (default: the folder given as "
                                 "spec); with --replay, the run folder to write")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_workers,
                       help="local worker processes, one thread each (default: the cores this "
                            "process may run on)")
    where.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                       help="run on this existing Dask cluster instead of a local one")
    p.add_argument("--robot", metavar="FILE", action="append",
                   help="robot profile (robots/*.toml) to run instead of the spec's profiles "
                        "(repeat for several); not when resuming a campaign folder")
    p.add_argument("--retry-failed", action="store_true",
                   help="run again the runs that failed (raised an error) before")
    p.add_argument("--replay", metavar="RUNKEY",
                   help="simulate this run of the campaign again into a run folder with "
                        "figures (as sim writes), instead of running the campaign")
    p.set_defaults(func=run)


def run(args: argparse.Namespace, console: Console) -> int:
    if args.replay:
        return replay(args, console)
    from hil.campaign import driver
    from hil.campaign.report import write_report
    from hil.campaign.spec import load_spec
    source = Path(args.spec)
    if args.out:
        out = Path(args.out)
    elif source.is_dir():
        out = source
    else:
        raise BadInput("--out: required with a spec file (the campaign folder to write)")
    if args.robot and source.is_dir():
        raise BadInput("--robot: a campaign folder runs the profiles it was started with")
    if args.scheduler:
        driver.check_scheduler(args.scheduler)
    if not driver.dask_available():
        raise RuntimeError("Dask is not installed: pip install 'boundswarm[campaign]'")
    spec = load_spec(source, profiles=args.robot)
    outcome = driver.run_campaign(spec, out, console, workers=args.workers,
                                  scheduler=args.scheduler, retry_failed=args.retry_failed)
    report = write_report(spec.name, outcome.rows, out, outcome.total)
    ok = [r for r in outcome.rows if r.get("status") == "ok"]
    safe = 100 * sum(bool(r.get("safe")) for r in ok) / len(ok) if ok else 0.0
    conv = 100 * sum(bool(r.get("converged")) for r in ok) / len(ok) if ok else 0.0
    speed = (f"; {outcome.runs_per_minute:.1f} runs/min on {outcome.workers} workers"
             if outcome.executed else "")
    console.print(f"{spec.name}: {len(outcome.rows)} of {outcome.total} runs "
                  f"({outcome.executed} run now, {outcome.failed} failed): safe {safe:.1f} %, "
                  f"converged {conv:.1f} %{speed}")
    if outcome.complete:
        console.print(f"results: {out / driver.PARQUET}\nreport:  {report}")
    else:
        console.print(f"[red]{len(outcome.lost)} runs were lost with their workers (first: "
                      f"{outcome.lost[0] if outcome.lost else '-'}); run the command again "
                      f"to finish them[/red]\nreport (partial): {report}")
    if outcome.failed:
        console.print(f"[red]{outcome.failed} runs failed: see {report}[/red]")
    return EXIT_OK if outcome.complete and not outcome.failed else EXIT_FAILED


def replay(args: argparse.Namespace, console: Console) -> int:
    """Write the run's scenario into the run folder and simulate it as ``sim`` does."""
    from hil.campaign import driver
    from hil.campaign.run import scenario_doc
    from hil.campaign.spec import load_spec
    from hil.cli import sim
    from hil.files import toml_text
    if not args.out:
        raise BadInput("--out: required with --replay (the run folder to write)")
    spec = load_spec(args.spec, check_families=False)
    found = [r for r in spec.runs if r.key.startswith(args.replay)]
    if len(found) != 1:
        raise BadInput(f"--replay: {'no' if not found else 'more than one'} run "
                       f"{args.replay!r} in campaign {spec.name} ({spec.source})")
    run_ = found[0]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scenario = out / "scenario.toml"
    scenario.write_text(f"# run {run_.key} of campaign {spec.name!r} ({spec.source})\n"
                        + toml_text.dumps(scenario_doc(run_.description)))
    code = sim.run(argparse.Namespace(
        scenario=str(scenario), out=str(out), duration=None, plant=None, robot=None,
        substeps=None, record_every=1), console)
    folder = Path(args.spec) if Path(args.spec).is_dir() else None
    row = driver.read_rows(folder).get(run_.key) if folder else None
    if row and row.get("status") == "ok":
        metrics = json.loads((out / "metrics.json").read_text())
        differ = [k for k in COMPARED if metrics.get(k) != row.get(k)]
        if differ:
            console.print(f"[yellow]the replay differs from the campaign's row in "
                          f"{', '.join(differ)} (other code since?)[/yellow]")
        else:
            console.print(f"the replay reproduces the campaign's row ({', '.join(COMPARED)})")
    return code
