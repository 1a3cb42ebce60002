"""Opening a robot's CAN bus from python-can's own terms: interface, channel, options.

* ``socketcan`` on ``vcanN``/``canN``, where the kernel has SocketCAN;
* ``udp_multicast`` where it has none: python-can's ``UdpMulticastBus`` with ``channel`` = an
  **interface-local IPv6 group** (``ff11::/16``, scope 1) and ``hop_limit=0``, one UDP port per
  robot bus (buses on different groups but one port hear each other). Nothing else is accepted,
  and the hop limit is read back from the socket after opening, so no frame leaves the host.
  That bus also receives the frames it sent itself: :class:`EchoFilteredBus` drops them, so it
  behaves like a CAN controller;
* ``virtual`` (python-can's in-process bus) for tests;
* ``auto``: socketcan if ``AF_CAN`` sockets work and the channel exists, else udp_multicast on
  :data:`DEFAULT_GROUP`, port :data:`DEFAULT_PORT` + N for channel ``vcanN``/``canN``.

A bus that cannot be opened raises :class:`BusOpenError`, whose message names the interface,
channel and port.
"""
from __future__ import annotations

import enum
import ipaddress
import logging
import re
import socket
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import can

log = logging.getLogger(__name__)

DEFAULT_GROUP = "ff11::b5:1"       # interface-local scope: never routed off the host
DEFAULT_PORT = 43100               # udp_multicast port of robot bus 0 (vcan0); vcanN -> +N
HOP_LIMIT = 0
_NUMBERED_CHANNEL = re.compile(r"^v?can(\d+)$")


class CanLinkError(Exception):
    """Base of the CAN link's errors."""


class BusOpenError(CanLinkError):
    """A bus could not be opened; the message names interface, channel and port."""


class Interface(enum.Enum):
    """python-can interface names this project uses (plus ``auto``)."""

    SOCKETCAN = "socketcan"
    UDP_MULTICAST = "udp_multicast"
    VIRTUAL = "virtual"
    AUTO = "auto"


@dataclass(frozen=True)
class BusConfig:
    """Which bus to open, in python-can terms.

    ``channel``: ``vcan0``/``can0`` (socketcan), an ``ff11::`` group (udp_multicast), any name
    (virtual). ``port``: UDP port, udp_multicast only (None: :data:`DEFAULT_PORT`).
    """

    interface: Interface = Interface.AUTO
    channel: str = "vcan0"
    port: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.interface, Interface):
            raise ValueError(f"interface: expected one of {[i.value for i in Interface]}, "
                             f"got {self.interface!r}")
        if not self.channel:
            raise ValueError("channel: must not be empty")
        if self.port is not None and not 1 <= self.port <= 65535:
            raise ValueError(f"port: must be 1..65535, got {self.port}")
        if self.port is not None and self.interface in (Interface.SOCKETCAN, Interface.VIRTUAL):
            raise ValueError(f"port: only for udp_multicast (or auto), not {self.interface.value}")
        if self.interface is Interface.UDP_MULTICAST:
            check_local_group(self.channel)

    @classmethod
    def from_options(cls, interface: str, channel: str,
                     port: int | None = None) -> BusConfig:
        """From CLI/TOML strings (``--can-interface``, ``--can-channel``, ``--can-port``)."""
        try:
            kind = Interface(interface)
        except ValueError:
            raise ValueError(f"interface: expected one of {[i.value for i in Interface]}, "
                             f"got {interface!r}") from None
        return cls(kind, channel, port)

    def describe(self) -> str:
        """``interface 'x' channel 'y' [port n]`` for messages."""
        port = f" port {self.port}" if self.port is not None else ""
        return f"interface {self.interface.value!r} channel {self.channel!r}{port}"


def check_local_group(channel: str) -> None:
    """ValueError unless ``channel`` is an interface-local IPv6 multicast group (ff11::/16)."""
    try:
        group = ipaddress.IPv6Address(channel)
    except ValueError:
        raise ValueError(f"channel: udp_multicast needs an IPv6 group such as {DEFAULT_GROUP}, "
                         f"got {channel!r}") from None
    if group.packed[:2] != b"\xff\x11":
        raise ValueError(f"channel: only interface-local groups ff11::/16 are allowed (no frame "
                         f"may leave the host), got {channel!r}")


def socketcan_available(channel: str) -> bool:
    """True if this kernel opens ``AF_CAN`` raw sockets and network interface ``channel`` exists."""
    if not hasattr(socket, "AF_CAN"):
        return False
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError:
        return False
    return Path("/sys/class/net", channel).exists()


def resolve(config: BusConfig) -> BusConfig:
    """``auto`` made concrete: socketcan if usable for the channel, else udp_multicast."""
    if config.interface is not Interface.AUTO:
        return config
    if socketcan_available(config.channel):
        if config.port is not None:
            raise ValueError("port: only for udp_multicast, but auto chose socketcan")
        return BusConfig(Interface.SOCKETCAN, config.channel)
    numbered = _NUMBERED_CHANNEL.match(config.channel)
    if numbered:
        port = config.port if config.port is not None else DEFAULT_PORT + int(numbered[1])
        return BusConfig(Interface.UDP_MULTICAST, DEFAULT_GROUP, port)
    return BusConfig(Interface.UDP_MULTICAST, config.channel, config.port)


def open_bus(config: BusConfig) -> can.BusABC:
    """Open the bus ``config`` describes (``auto`` resolved); :class:`BusOpenError` if not."""
    try:
        concrete = resolve(config)
    except ValueError as exc:
        raise BusOpenError(f"cannot open CAN bus ({config.describe()}): {exc}") from None
    what = concrete.describe()
    if concrete.interface is Interface.SOCKETCAN and not socketcan_available(concrete.channel):
        raise BusOpenError(f"cannot open CAN bus ({what}): this kernel has no SocketCAN or no "
                           f"interface {concrete.channel!r} (use udp_multicast, or a vcan "
                           f"inside User-Mode Linux)")
    options: dict = {}
    if concrete.interface is Interface.UDP_MULTICAST:
        options = {"port": concrete.port or DEFAULT_PORT, "hop_limit": HOP_LIMIT}
    try:
        bus = can.Bus(interface=concrete.interface.value, channel=concrete.channel, **options)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise BusOpenError(f"cannot open CAN bus ({what}): {exc}") from exc
    log.info("CAN bus open: %s", what)
    if concrete.interface is not Interface.UDP_MULTICAST:
        return bus
    hops = multicast_hop_limit(bus)
    if hops != HOP_LIMIT:
        bus.shutdown()
        raise BusOpenError(f"cannot open CAN bus ({what}): socket hop limit is {hops}, "
                           f"expected {HOP_LIMIT}")
    return EchoFilteredBus(bus, channel_info=f"udp_multicast {concrete.channel} port "
                                             f"{concrete.port or DEFAULT_PORT}")


def multicast_hop_limit(bus: can.BusABC) -> int:
    """IPV6_MULTICAST_HOPS of a udp_multicast bus's socket, read back from the kernel."""
    with socket.socket(fileno=socket.dup(bus.fileno())) as sock:
        return sock.getsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS)


class EchoFilteredBus(can.BusABC):
    """A bus that hears its own frames (udp_multicast), with those echoes dropped.

    Every sent frame is remembered (id, RTR, data) for ``horizon_s``; a received frame equal to
    a remembered one is taken as its echo and dropped (the oldest match first). Datagrams that
    python-can cannot unpack as CAN frames are dropped and counted too. ``clock``: monotonic
    seconds, injected for tests.
    """

    def __init__(self, inner: can.BusABC, channel_info: str, horizon_s: float = 1.0,
                 clock: Callable[[], float] = time.monotonic):
        self.inner, self.horizon_s, self.clock = inner, horizon_s, clock
        self._sent: deque[tuple[float, tuple]] = deque()
        self.echoes_dropped = 0
        self.malformed_dropped = 0
        self.channel_info = channel_info
        super().__init__(channel=channel_info)

    @staticmethod
    def _key(msg: can.Message) -> tuple:
        return (msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame,
                msg.dlc if msg.is_remote_frame else bytes(msg.data))

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.inner.send(msg, timeout)
        self._sent.append((self.clock(), self._key(msg)))

    def _is_echo(self, msg: can.Message) -> bool:
        now = self.clock()
        while self._sent and now - self._sent[0][0] > self.horizon_s:
            self._sent.popleft()
        key = self._key(msg)
        for i, (_, sent) in enumerate(self._sent):
            if sent == key:
                del self._sent[i]
                return True
        return False

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                msg = self.inner.recv(remaining)
            except can.CanOperationError as exc:
                if isinstance(exc.__cause__, OSError):
                    raise
                self.malformed_dropped += 1
                log.warning("dropped a datagram that is not a CAN frame: %s", exc)
                continue
            if msg is None:
                return None, False
            if self._is_echo(msg):
                self.echoes_dropped += 1
                continue
            return msg, False

    def fileno(self) -> int:
        return self.inner.fileno()

    def shutdown(self) -> None:
        super().shutdown()
        self.inner.shutdown()
