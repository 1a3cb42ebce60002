"""``boundswarm deploy``: bundles for robot computers and the ground station."""
from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from hil.cli.exit_codes import EXIT_OK
from hil.cli.options import Subparsers


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("deploy", help="bundles for robot computers and the ground station")
    p.add_argument("manifest", help="swarm manifest (TOML)")
    p.add_argument("--out", required=True, help="folder for the bundles")
    p.set_defaults(func=run)


def run(args: argparse.Namespace, console: Console) -> int:
    """Write the bundles of the manifest and say where they are."""
    from hil.ground.deploy import deploy, load_manifest
    bundles = deploy(load_manifest(args.manifest), Path(args.out))
    for name, path in bundles.items():
        console.print(f"{name}: {path}")
    console.print("copy each robot-<id> folder to its robot and run its install.sh as root; "
                  "see ground/README.md for the ground station")
    return EXIT_OK
