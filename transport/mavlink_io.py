"""Byte transports for MAVLink that never block, opened from pymavlink-style URLs.

::

    udpout:HOST:PORT    send to a ground station listening there (QGroundControl and MAVProxy
                        listen on 14550); its replies come back to our own (ephemeral) port
    udpin:HOST:PORT     listen there; send to the peers heard from (the MAX_PEERS latest)
    tcp:HOST:PORT       connect to a TCP server; while down, retry every RECONNECT_S
    DEVICE[,BAUD]       a serial port (POSIX), e.g. /dev/ttyUSB0,57600 (default 57600 baud)

Every transport has ``recv() -> bytes`` (``b""`` when nothing is waiting), ``write(frame)``,
``flush()`` and ``close()``; none of them waits. Written frames wait in a bounded output
buffer until ``flush`` (UDP: sent then, as few datagrams of at most ``MAX_DATAGRAM`` bytes as
hold them, as autopilots pack their streams; TCP and serial: sent as far as the stream takes
them, at each write and flush). A frame that cannot be sent is dropped and counted
(``dropped``), whole: no frame is ever cut. The MAVLink codec (pymavlink) writes through
``write``, so these objects serve as its ``file``.
"""
from __future__ import annotations

import errno
import logging
import math
import os
import select
import socket
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Protocol

log = logging.getLogger(__name__)

MAX_PEERS = 4                  # udpin: peers answered
RECONNECT_S = 1.0              # tcp: s between connection attempts while down
OUT_BUFFER = 16 * 1024         # bytes waiting in a transport before frames are dropped
MAX_DATAGRAM = 1472            # bytes of frames in one UDP datagram: an Ethernet MTU's payload
READ_SIZE = 4096               # bytes read at most per recv() from a stream
DEFAULT_BAUD = 57600


class Transport(Protocol):
    # Read-only members: the stream transports compute ``dropped`` from their out buffer.
    @property
    def dropped(self) -> int: ...          # frames not sent
    @property
    def datagrams(self) -> bool: ...       # True: each recv() is whole frames; False: a stream

    def recv(self) -> bytes: ...
    def write(self, frame: bytes) -> None: ...
    def flush(self) -> None: ...          # send what was written (see the module doc)
    def close(self) -> None: ...


def _host_port(url: str, rest: str) -> tuple[str, int]:
    host, sep, port = rest.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"MAVLink URL {url!r}: expected HOST:PORT after the scheme")
    return host, int(port)


def parse_url(url: str) -> tuple[str, str, int]:
    """(scheme, host or device, port or baud) of ``url``; ``ValueError`` naming it if bad.

    The scheme is ``udpout``, ``udpin``, ``tcp`` or ``serial``."""
    scheme, _, rest = url.partition(":")
    if scheme in ("udpout", "udpin", "tcp"):
        return (scheme, *_host_port(url, rest))
    if url.startswith("/dev/"):
        device, _, baud = url.partition(",")
        if baud and not baud.isdigit():
            raise ValueError(f"MAVLink URL {url!r}: the baud rate after ',' must be a number")
        return "serial", device, int(baud) if baud else DEFAULT_BAUD
    raise ValueError(f"MAVLink URL {url!r}: expected udpout:HOST:PORT, udpin:HOST:PORT, "
                     f"tcp:HOST:PORT or a serial device /dev/...[,BAUD]")


def open_transport(url: str, clock: Callable[[], float] = time.monotonic) -> Transport:
    """The transport for ``url`` (see the module doc); ``clock`` [s] paces TCP reconnects."""
    scheme, where, number = parse_url(url)
    if scheme == "tcp":
        return TcpTransport(where, number, clock=clock)
    if scheme == "serial":
        return SerialTransport(where, number)
    return UdpTransport(where, number, listen=scheme == "udpin")


class UdpTransport:
    """One non-blocking UDP socket: ``listen`` binds to (host, port), else sends there.
    Frames written wait for :meth:`flush`, which packs them into datagrams."""

    datagrams = True

    def __init__(self, host: str, port: int, listen: bool):
        family, _, _, _, addr = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        self._sock.setblocking(False)
        self._listen = listen
        self._peers: OrderedDict[tuple, None] = OrderedDict()
        if listen:
            self._sock.bind(addr)
        else:
            self._peers[addr] = None
        self._out: list[bytes] = []
        self._queued = 0               # bytes in _out
        self.dropped = 0

    @property
    def local_address(self) -> tuple:
        return self._sock.getsockname()

    def recv(self) -> bytes:
        try:
            data, addr = self._sock.recvfrom(65535)
        except (BlockingIOError, ConnectionRefusedError):   # refused: ICMP after a send
            return b""
        if self._listen:
            self._peers[addr] = None
            self._peers.move_to_end(addr)
            while len(self._peers) > MAX_PEERS:
                self._peers.popitem(last=False)
        return data

    def write(self, frame: bytes) -> None:
        if self._queued + len(frame) > OUT_BUFFER:
            self.dropped += 1
            return
        self._out.append(frame)
        self._queued += len(frame)

    def flush(self) -> None:
        if not self._out:                  # most polls: nothing written
            return
        out, self._out, self._queued = self._out, [], 0
        for frames in _packed(out):
            datagram = b"".join(frames)
            for addr in self._peers:
                try:
                    self._sock.sendto(datagram, addr)
                except OSError:
                    self.dropped += len(frames)

    def close(self) -> None:
        self.flush()
        self._sock.close()


def _packed(frames: list[bytes]) -> list[list[bytes]]:
    """``frames`` in order, in groups of at most MAX_DATAGRAM bytes (a larger frame alone)."""
    groups: list[list[bytes]] = []
    size = 0                       # bytes in the last group
    for frame in frames:
        if not groups or size + len(frame) > MAX_DATAGRAM:
            groups.append([])
            size = 0
        groups[-1].append(frame)
        size += len(frame)
    return groups


class _OutBuffer:
    """Bytes waiting for a stream; whole frames are refused when it is full."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.dropped = 0

    def push(self, frame: bytes) -> None:
        if len(self.data) + len(frame) > OUT_BUFFER:
            self.dropped += 1
        else:
            self.data += frame

    def flush(self, send: Callable[[bytes], int]) -> None:
        """Send what the stream takes now; ``send`` raises BlockingIOError when full."""
        if self.data:
            try:
                del self.data[:send(bytes(self.data))]
            except BlockingIOError:
                pass


class TcpTransport:
    """A non-blocking TCP client that reconnects while the server is away."""

    datagrams = False

    def __init__(self, host: str, port: int, clock: Callable[[], float] = time.monotonic):
        self._addr, self._clock = (host, port), clock
        self._sock: socket.socket | None = None
        self._connected = False
        self._next_attempt = -math.inf
        self._out = _OutBuffer()
        self._connect()

    @property
    def dropped(self) -> int:
        return self._out.dropped

    def _connect(self) -> None:
        now = self._clock()
        if now < self._next_attempt:
            return
        self._next_attempt = now + RECONNECT_S
        family, _, _, _, addr = socket.getaddrinfo(*self._addr, type=socket.SOCK_STREAM)[0]
        sock = socket.socket(family, socket.SOCK_STREAM)
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        err = sock.connect_ex(addr)
        if err not in (0, errno.EINPROGRESS, errno.EWOULDBLOCK):
            sock.close()
            log.debug("tcp %s:%d: %s", *self._addr, os.strerror(err))
            return
        self._sock, self._connected = sock, err == 0

    def _ready(self) -> socket.socket | None:
        """The socket if the connection is up (else None), finishing a pending connect
        without waiting."""
        if self._sock is None:
            self._connect()
            return None
        if not self._connected:
            _, writable, _ = select.select([], [self._sock], [], 0)
            if not writable:
                return None
            err = self._sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
            if err:
                self._drop(os.strerror(err))
                return None
            self._connected = True
            log.info("tcp %s:%d connected", *self._addr)
        return self._sock

    def _drop(self, why: str) -> None:
        if self._connected:
            log.warning("tcp %s:%d: %s; reconnecting", *self._addr, why)
        if self._sock is not None:
            self._sock.close()
        self._sock, self._connected = None, False
        self._out.data.clear()           # a new connection starts on a frame boundary

    def recv(self) -> bytes:
        sock = self._ready()
        if sock is None:
            return b""
        try:
            data = sock.recv(READ_SIZE)
        except BlockingIOError:
            return b""
        except OSError as exc:
            self._drop(exc.strerror or str(exc))
            return b""
        if not data:
            self._drop("closed by the peer")
        return data

    def write(self, frame: bytes) -> None:
        sock = self._ready()
        if sock is None:
            self._out.dropped += 1
            return
        self._out.push(frame)
        self._send(sock)

    def flush(self) -> None:
        sock = self._ready()
        if sock is not None:
            self._send(sock)

    def _send(self, sock: socket.socket) -> None:
        try:
            self._out.flush(sock.send)
        except OSError as exc:
            self._drop(exc.strerror or str(exc))

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None


class SerialTransport:
    """A serial port set up by pyserial (raw, ``baud``), read and written without waiting."""

    datagrams = False

    def __init__(self, device: str, baud: int):
        try:
            import serial
        except ImportError:
            raise ValueError(f"MAVLink on {device} needs pyserial (pip install pyserial)") \
                from None
        try:
            self._port = serial.Serial(device, baud, timeout=0, write_timeout=0)
        except (serial.SerialException, ValueError) as exc:
            raise ValueError(f"MAVLink serial port {device} at {baud} baud: {exc}") from None
        self._fd = self._port.fileno()       # opened O_NONBLOCK by pyserial
        self._out = _OutBuffer()

    @property
    def dropped(self) -> int:
        return self._out.dropped

    def recv(self) -> bytes:
        try:
            return os.read(self._fd, READ_SIZE)
        except BlockingIOError:
            return b""

    def write(self, frame: bytes) -> None:
        self._out.push(frame)
        self.flush()

    def flush(self) -> None:
        self._out.flush(lambda data: os.write(self._fd, data))

    def close(self) -> None:
        self._port.close()
