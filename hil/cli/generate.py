"""``boundswarm generate``: write one seeded family scenario or micro case as a TOML file."""
from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path
from typing import Any

from rich.console import Console

from hil.cli.exit_codes import EXIT_OK, BadInput
from hil.cli.options import Subparsers, positive


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("generate", help="write a seeded scenario of a family, or a micro "
                                        "case (docs/families.md)")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--family", metavar="KEY=VALUE,...",
                      help="family keys kind, robots, spacing, slots, field, speed, e.g. "
                           "kind=grid,robots=20,field=cluttered ('' for the defaults)")
    what.add_argument("--micro", metavar="NAME", help="a micro case: head_on_swap, "
                      "offset_head_on, obstacle_ahead, crowd_onto_obstacle, narrow_gap, "
                      "through_own_reference, late_arrival")
    p.add_argument("--seed", type=int, required=True, help="seed (integer >= 0)")
    p.add_argument("--out", required=True, metavar="FILE.toml", help="scenario file to write")
    p.add_argument("--robot", metavar="FILE",
                   help="robot profile (robots/*.toml): written as the scenario's [robot] "
                        "(wheels plant), and a family's slots move at most half its top "
                        "speed")
    p.add_argument("--duration", type=positive,
                   help="simulated time [s] (default: 40 for a family, the case's for a micro "
                        "case)")
    p.set_defaults(func=run)


def parse_pairs(text: str, flag: str = "--family") -> dict[str, Any]:
    """``kind=grid,robots=20,spacing=5.5`` as a dict: integers, numbers, else strings."""
    out: dict[str, Any] = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        key, eq, value = (s.strip() for s in item.partition("="))
        if not eq or not key or not value:
            raise BadInput(f"{flag}: expected KEY=VALUE, got {item!r}")
        if key in out:
            raise BadInput(f"{flag}: {key} given twice")
        out[key] = _typed(value)
    return out


def _typed(text: str) -> Any:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def run(args: argparse.Namespace, console: Console) -> int:
    """Generate, write, read the file back as a scenario, print what it holds."""
    from hil.campaign.families import family_doc, micro_doc
    from hil.files import toml_text
    from hil.files.scenario import load_scenario
    if args.seed < 0:
        raise BadInput(f"--seed: expected an integer >= 0, got {args.seed}")
    robot = None
    if args.robot:
        from hil.files.robot_profile import load_robot_profile
        robot = load_robot_profile(args.robot)
    if args.family is not None:
        top = robot.v_wheel_max if robot is not None else math.inf
        doc = family_doc(parse_pairs(args.family), args.seed, duration=args.duration or 40.0,
                         where="--family", top_speed=top)
        how = f"--family {args.family!r}"
    else:
        doc = micro_doc(args.micro, args.seed, duration=args.duration, where="--micro")
        how = f"--micro {args.micro}"
    if robot is not None:
        doc["robot"] = dataclasses.asdict(robot)
        doc["sim"] = {**doc.get("sim", {}), "plant": "wheels"}
        how += f" --robot {args.robot}"
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(f"# boundswarm generate {how} --seed {args.seed}\n" + toml_text.dumps(doc),
                   encoding="utf-8")
    sc = load_scenario(out)
    console.print(f"wrote {out}: {sc.name}, {len(sc.ids)} robots, {len(sc.obstacles)} "
                  f"obstacles, {sc.duration:g} s")
    return EXIT_OK
