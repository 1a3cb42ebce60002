"""Opening a robot's CAN bus from python-can's own terms (interface, channel, options).

* ``socketcan`` on ``vcanN``/``canN`` where the kernel has SocketCAN;
* ``udp_multicast`` where it has none: an interface-local IPv6 group (``ff11::...``, scope 1)
  with ``hop_limit=0``, one UDP port per robot bus (different groups on one port would cross
  talk). Such traffic never leaves the machine. That bus hears its own frames: they are
  filtered out here, so it behaves like a CAN controller;
* ``virtual`` for in-process tests;
* ``auto``: socketcan when the kernel has it and the channel exists, else udp_multicast.
"""
from __future__ import annotations

import ipaddress
import os
import socket
import time
from collections import deque

import can

DEFAULT_GROUP = "ff11::b5:1"     # interface-local scope: never routed off the host
DEFAULT_PORT = 43100


class BusOpenError(RuntimeError):
    """The bus could not be opened; the message names interface and channel."""


def has_socketcan(channel: str | None = None) -> bool:
    """True if the kernel has SocketCAN (and ``channel``, if given, exists)."""
    if not hasattr(socket, "AF_CAN"):
        return False
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError:
        return False
    return channel is None or os.path.exists(f"/sys/class/net/{channel}")


class EchoFilteredBus(can.BusABC):
    """Wraps a bus that hears its own frames and drops those echoes.

    Echoes arrive in the order the frames were sent; each received frame equal to the
    oldest unechoed sent frame (id, RTR, DLC, data) is taken as its echo. Entries older than
    ``horizon`` seconds are forgotten (an echo that never came).
    """

    def __init__(self, inner: can.BusABC, horizon: float = 0.5):
        self.inner = inner
        self.horizon = horizon
        self._sent: deque = deque()
        self.echoes_dropped = 0
        self.malformed = 0
        super().__init__(channel=inner.channel_info)
        self.channel_info = inner.channel_info

    @staticmethod
    def _key(msg: can.Message) -> tuple:
        return (msg.arbitration_id, msg.is_remote_frame, msg.dlc,
                bytes(msg.data) if not msg.is_remote_frame else b"")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.inner.send(msg, timeout)
        self._sent.append((time.monotonic(), self._key(msg)))

    def _recv_internal(self, timeout: float | None):
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:   # the inner bus has no filters: its own receive, without recv()'s loop
                msg, _ = self.inner._recv_internal(remaining)
            except can.CanOperationError as exc:
                if isinstance(exc.__cause__, OSError):
                    raise
                self.malformed += 1            # a datagram that is not a CAN frame
                continue
            if msg is None:
                return None, False
            now = time.monotonic()
            while self._sent and now - self._sent[0][0] > self.horizon:
                self._sent.popleft()
            if self._sent and self._sent[0][1] == self._key(msg):
                self._sent.popleft()
                self.echoes_dropped += 1
                continue
            return msg, False

    def shutdown(self) -> None:
        super().shutdown()
        self.inner.shutdown()


def open_bus(interface: str, channel: str | None = None, port: int | None = None,
             bitrate: int | None = None) -> can.BusABC:
    """Open a bus in python-can terms; raises :class:`BusOpenError` naming what failed."""
    if interface == "auto":
        if channel and has_socketcan(channel):
            interface = "socketcan"
        else:
            interface, channel = "udp_multicast", (
                channel if channel and channel.startswith("ff") else DEFAULT_GROUP)
    what = f"interface {interface!r} channel {channel!r}" + (f" port {port}" if port else "")
    kwargs: dict = {}
    if interface == "udp_multicast":
        channel = channel or DEFAULT_GROUP
        try:
            group = ipaddress.IPv6Address(channel)
        except ValueError:
            raise BusOpenError(f"cannot open CAN bus ({what}): udp_multicast needs an IPv6 "
                               f"multicast group such as {DEFAULT_GROUP}") from None
        if not group.is_multicast or (group.packed[1] & 0x0F) != 1:
            raise BusOpenError(f"cannot open CAN bus ({what}): only interface-local groups "
                               f"(ff11::/16, scope 1) are allowed, so no frame leaves the host")
        kwargs.update(port=port or DEFAULT_PORT, hop_limit=0)
    elif interface == "socketcan" and not has_socketcan(channel):
        raise BusOpenError(f"cannot open CAN bus ({what}): this kernel has no SocketCAN or no "
                           f"such interface (try udp_multicast, or a vcan inside UML)")
    elif bitrate and interface not in ("virtual", "socketcan"):
        kwargs["bitrate"] = bitrate
    try:
        bus = can.Bus(interface=interface, channel=channel, **kwargs)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise BusOpenError(f"cannot open CAN bus ({what}): {exc}") from None
    return EchoFilteredBus(bus) if interface == "udp_multicast" else bus
