"""The ``boundswarm`` command line: one module per subcommand, dispatched from here.

Each ``hil/cli/<subcommand>.py`` defines its subcommand's options (``add_parser``) and what
it runs; options that several share are in :mod:`hil.cli.options`, terminal output in
:mod:`hil.cli.console`. Exit codes are in :mod:`hil.cli.exit_codes`: 2 only for bad input
(the message names the option, file or field), and a one-line message with exit 1 for any
other error. ``python -m hil.cli`` runs the command too (``hil/cli/__main__.py``).
"""
from __future__ import annotations

import argparse
import logging
import signal
import sys
import traceback

from rich.console import Console

from hil.cli import (
    agent,
    campaign,
    can,
    deploy,
    generate,
    mission,
    mocap,
    plant,
    record,
    report,
    router,
    sim,
    sitl,
)
from hil.cli.exit_codes import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, BadInput

SUBCOMMANDS = (sim, sitl, agent, plant, can, deploy, router, mission, mocap, record, report,
               generate, campaign)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="boundswarm", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="store_true",
                        help="debug logging, and the traceback of an error")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in SUBCOMMANDS:
        module.add_parser(sub)
    return parser


def stop_on_signals() -> None:
    """SIGINT and SIGTERM end a command as Ctrl-C does (KeyboardInterrupt: a launcher ends
    its children first). Also when the command was started in the background of a script,
    whose shell sets SIGINT to be ignored, and when a service manager sends SIGTERM: either
    would otherwise leave a launcher's agents and plant running. Commands with a stop of
    their own (router, recorder, mocap bridge, plant, agent) replace these handlers."""
    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt(signal.Signals(signum).name)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, interrupt)


def main(argv: list[str] | None = None) -> int:
    argv = plant.as_subcommand(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    where = f"boundswarm {args.command}"
    stop_on_signals()
    try:
        code: int = args.func(args, Console())
        return code
    except KeyboardInterrupt:
        print(f"{where}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:
        if isinstance(exc, bad_input()):
            print(f"{where}: error: {_one_line(exc)}", file=sys.stderr)
            return EXIT_BAD_INPUT
        if args.verbose:
            traceback.print_exc()
        print(f"{where}: failed: {type(exc).__name__}: {_one_line(exc)}"
              + ("" if args.verbose else " (-v shows the traceback)"), file=sys.stderr)
        return EXIT_FAILED


def bad_input() -> tuple[type[Exception], ...]:
    """The errors that mean bad input. Imported only when an error is reported: the
    modules that define them are slow to import for a command that does not need them."""
    from common.schema import ConfigError
    from hil.files.run_folder import RunFolderError
    from hil.files.scenario import ScenarioError
    from hil.ground.deploy import DeployError
    return BadInput, ConfigError, ScenarioError, RunFolderError, DeployError


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())

