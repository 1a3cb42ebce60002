"""Opening a robot's CAN bus from python-can's own terms (interface, channel, options).

* ``socketcan`` on ``vcanN``/``canN`` where the kernel has SocketCAN;
* ``udp_multicast`` where it has none: an interface-local IPv6 group (``ff11::...``, scope 1)
  with ``hop_limit=0``, one UDP port per robot bus (different groups on one port would cross
  talk). Such traffic never leaves the machine. python-can's bus hears its own frames: here
  the kernel drops them (a socket filter), so it behaves like a CAN controller;
* ``virtual`` for in-process tests;
* ``auto``: socketcan when the kernel has it and the channel exists, else udp_multicast.
"""
from __future__ import annotations

import ctypes
import ipaddress
import os
import select
import socket
import struct
import time

import can
from can.interfaces.udp_multicast import UdpMulticastBus
from can.interfaces.udp_multicast.bus import SO_TIMESTAMPNS
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


# classic BPF (linux/filter.h): on a UDP socket the program sees the UDP header at offset 0
_BPF_LDH_ABS, _BPF_JEQ_K, _BPF_RET_K = 0x28, 0x15, 0x06
SO_ATTACH_FILTER = getattr(socket, "SO_ATTACH_FILTER", 26)


_DROP_ALL = [(_BPF_RET_K, 0, 0, 0)]


def _attach(sock: socket.socket, program: list[tuple[int, int, int, int]]) -> None:
    """Attach a classic BPF socket filter (Linux; OSError elsewhere)."""
    insns = ctypes.create_string_buffer(b"".join(struct.pack("HBBI", *i) for i in program))
    sock.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER,
                    struct.pack("HL", len(program), ctypes.addressof(insns)))   # sock_fprog


def drop_from_port(sock: socket.socket, port: int) -> None:
    """Drop, in the kernel, every datagram to ``sock`` whose UDP source port is ``port``."""
    _attach(sock, [(_BPF_LDH_ABS, 0, 0, 0),           # A = source port
                   (_BPF_JEQ_K, 0, 1, port),          # A == port ? next : skip one
                   (_BPF_RET_K, 0, 0, 0),             # drop
                   (_BPF_RET_K, 0, 0, 0xFFFFFFFF)])   # keep the whole datagram


_TIMESPEC = struct.Struct("@ll")


def _stamp(ancillary: list) -> float:
    """The kernel's receive time (SO_TIMESTAMPNS) of a datagram [s, UNIX time], or now."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(data) >= _TIMESPEC.size:
            seconds, nanoseconds = _TIMESPEC.unpack_from(data)
            return seconds + nanoseconds * 1e-9
    return time.time()


class EchoFilteredBus(can.BusABC):
    """A python-can ``udp_multicast`` bus that never hears its own frames, like a CAN
    controller.

    python-can's bus receives on a socket bound to the group's port and would hear every
    datagram it sent. This one sends python-can's datagrams from a socket of its own (an
    ephemeral port, hop limit 0, same group and port), and a socket filter on python-can's
    receiving socket drops the datagrams from that port in the kernel: an echo never wakes
    the reader or costs a system call. Every other sender (python-can tools included) is
    heard. Datagrams that are not classic CAN frames are counted in ``malformed`` and
    skipped.
    """

    def __init__(self, inner: UdpMulticastBus):
        self.inner = inner
        rx = inner._multicast                    # python-can's receiving side of this bus
        self._dest = (rx.group, rx.port)
        self._tx = tx = socket.socket(socket.AF_INET6, socket.SOCK_DGRAM)
        try:
            tx.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS, rx.hop_limit)
            # python-can binds its buses' ports with these: an ephemeral port that happens to
            # be another bus's (ports are picked from the same range) must not keep that bus
            # from opening. What such a shared port would queue here is dropped: it only sends
            for option in (socket.SO_REUSEADDR, getattr(socket, "SO_REUSEPORT", None)):
                if option is not None:
                    tx.setsockopt(socket.SOL_SOCKET, option, 1)
            _attach(tx, _DROP_ALL)
            tx.bind(("::", 0))
            tx.setblocking(False)               # a full send buffer fails the send, never waits
            drop_from_port(rx._socket, tx.getsockname()[1])
        except OSError:
            self._tx.close()
            raise
        self._sock = rx._socket
        self._size = rx.max_buffer
        self._ancillary_size = rx.received_ancillary_buffer_size   # 0: no SO_TIMESTAMPNS
        self.malformed = 0
        super().__init__(channel=inner.channel_info)
        self.channel_info = inner.channel_info

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if msg.is_fd:
            raise can.CanOperationError("cannot send an FD frame on a classic CAN bus")
        try:
            self._tx.sendto(pack_message(msg), self._dest)
        except OSError as exc:
            raise can.CanOperationError(f"failed to send via socket: {exc}") from exc

    def _recv_internal(self, timeout: float | None):
        # python-can's recv selects before every read: two system calls a frame, and one to
        # find the socket empty. Here a datagram waiting is read at once (MSG_DONTWAIT), and
        # only an empty socket is waited on, for what is left of ``timeout``.
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            try:
                data, ancillary, _, _ = self._sock.recvmsg(self._size, self._ancillary_size,
                                                           socket.MSG_DONTWAIT)
            except BlockingIOError:
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0.0:
                    return None, False
                try:
                    ready, _, _ = select.select([self._sock], [], [], remaining)
                except OSError as exc:
                    raise can.CanOperationError(f"failed to wait on the socket: {exc}") from exc
                if not ready:
                    return None, False
                continue
            except OSError as exc:
                raise can.CanOperationError(f"failed to receive via socket: {exc}") from exc
            try:
                msg = unpack_message(data, replace={"timestamp": _stamp(ancillary)},
                                     check=True)
            except Exception:                  # msgpack or python-can: not a frame of ours
                msg = None
            if msg is None or msg.is_fd:
                self.malformed += 1
                continue
            return msg, False

    def fileno(self) -> int:
        """The receiving socket's descriptor (readable when a frame waits)."""
        return self.inner.fileno()

    def shutdown(self) -> None:
        super().shutdown()
        self._tx.close()
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
    if interface != "udp_multicast":
        return bus
    assert isinstance(bus, UdpMulticastBus)     # what can.Bus makes for this interface
    try:
        return EchoFilteredBus(bus)
    except OSError as exc:
        bus.shutdown()
        raise BusOpenError(f"cannot open CAN bus ({what}): own-frame filter: {exc}") from None
