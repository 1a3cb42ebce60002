"""Options that several ``boundswarm`` subcommands share, and their argument types."""
from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, TypeAlias

from hil.cli.exit_codes import BadInput

if TYPE_CHECKING:
    import zenoh

Subparsers: TypeAlias = "argparse._SubParsersAction[argparse.ArgumentParser]"


def add_can_options(p: argparse.ArgumentParser, default_interface: str = "udp_multicast"
                    ) -> None:
    """CAN options in python-can's own names."""
    p.add_argument("--can-interface", default=default_interface,
                   help="python-can interface: socketcan, udp_multicast, virtual or auto")
    p.add_argument("--can-channel", help="socketcan: vcan0/can0; udp_multicast: an "
                                         "interface-local group ff11::...")


def priority(text: str) -> int:
    """A SCHED_FIFO priority option: 0 (normal scheduling) or 1..99."""
    if not (text.isdigit() and int(text) <= 99):
        raise argparse.ArgumentTypeError(f"expected 0..99, got {text!r}")
    return int(text)


def positive(text: str) -> float:
    """A finite number above zero."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a number above 0, got {text!r}")
    return value


def swarm_name(text: str) -> str:
    """A swarm name usable as a Zenoh key prefix."""
    from transport.zenoh_link import Keys
    try:
        Keys(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def add_zenoh_client_options(p: argparse.ArgumentParser, required: bool,
                             config: str = "--config", connect: str = "--connect") -> None:
    """A Zenoh client: a config file (e.g. with TLS), or router endpoints without one."""
    group = p.add_mutually_exclusive_group(required=required)
    group.add_argument(config, metavar="FILE", help="zenoh client config (JSON5), e.g. with TLS")
    group.add_argument(connect, action="append", metavar="ENDPOINT",
                       help="router endpoint, e.g. tcp/127.0.0.1:7447 (repeatable; no config)")


def zenoh_file(path: str) -> zenoh.Config:
    """The Zenoh config in ``path``; BadInput naming the file if it is not one."""
    from transport.zenoh_link import config_from_file
    try:
        return config_from_file(path)
    except ValueError as exc:
        raise BadInput(str(exc)) from None


def zenoh_client(config: str | None, connect: list[str] | None) -> zenoh.Config:
    """The client config in file ``config``, else one that connects to ``connect``."""
    from transport.zenoh_link import session_config
    return zenoh_file(config) if config else session_config("client", connect=connect or [])
