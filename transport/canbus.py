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
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

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
    """A python-can ``udp_multicast`` bus that drops the echoes of its own frames.

    Such a bus hears every datagram it sends. Echoes arrive in the order the frames were
    sent; a received datagram equal to the oldest unechoed sent one is taken as its echo and
    dropped before it is unpacked (the datagrams are compared, so an echo costs no decoding).
    Entries older than ``horizon`` seconds are forgotten (an echo that never came). Datagrams
    that are not classic CAN frames are counted in ``malformed`` and skipped.
    """

    def __init__(self, inner: can.BusABC, horizon: float = 0.5):
        self.inner = inner
        self._socket = inner._multicast     # python-can's datagram socket of this bus
        self.horizon = horizon
        self._sent: deque = deque()
        self.echoes_dropped = 0
        self.malformed = 0
        super().__init__(channel=inner.channel_info)
        self.channel_info = inner.channel_info

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if msg.is_fd:
            raise can.CanOperationError("cannot send an FD frame on a classic CAN bus")
        data = pack_message(msg)
        self._socket.send(data, timeout)
        self._sent.append((time.monotonic(), data))

    def _recv_internal(self, timeout: float | None):
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            got = self._socket.recv(remaining)      # raises CanOperationError if the socket fails
            if not got:
                return None, False
            data, _, timestamp = got
            now = time.monotonic()
            while self._sent and now - self._sent[0][0] > self.horizon:
                self._sent.popleft()
            if self._sent and self._sent[0][1] == data:
                self._sent.popleft()
                self.echoes_dropped += 1
                continue
            try:
                msg = unpack_message(data, replace={"timestamp": timestamp}, check=True)
            except Exception:                  # msgpack or python-can: not a frame of ours
                msg = None
            if msg is None or msg.is_fd:
                self.malformed += 1
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
