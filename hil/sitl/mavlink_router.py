"""A small MAVLink router: many agents behind one ground-station port.

A ground station listening with ``udpin`` answers only the last address it heard from, so
with several agents sending to one port its commands would reach the wrong agent. The SITL
launcher therefore points every agent at this router (``udpout`` to one local port); the
router forwards their frames to the ground station from a single socket, learns each
system id's address from what it sends, and routes the ground station's frames by their
``target_system``: to that agent only, or to every agent for a broadcast (0) or a message
without a target (the ground station's HEARTBEAT). Frames are forwarded unchanged (signed
frames stay signed). It runs in a thread of the launcher, on 127.0.0.1 only, and empties
both sockets every ``interval`` seconds rather than waking for each datagram: thirty agents
send hundreds of datagrams a second, and on a machine that runs them all a wake-up costs
more than the datagrams it reads. A frame waits at most ``interval`` (10 ms) on its way.
"""
from __future__ import annotations

import logging
import socket
import threading
from collections import Counter

from pymavlink.dialects.v20 import common as mav2

log = logging.getLogger(__name__)

MAGIC_V2, MAGIC_V1 = 0xFD, 0xFE


def _frames(data: bytes):
    """Split a datagram into MAVLink frames (v1 or v2, signed or not)."""
    i = 0
    while i < len(data):
        magic = data[i]
        if magic == MAGIC_V2 and i + 10 <= len(data):
            n = 12 + data[i + 1] + (13 if data[i + 2] & 0x01 else 0)
        elif magic == MAGIC_V1 and i + 6 <= len(data):
            n = 8 + data[i + 1]
        else:
            return
        yield data[i:i + n]
        i += n


def system_id(frame: bytes) -> int | None:
    if frame and frame[0] == MAGIC_V2 and len(frame) > 5:
        return frame[5]
    if frame and frame[0] == MAGIC_V1 and len(frame) > 3:
        return frame[3]
    return None


def _waiting(sock: socket.socket, most: int = 4096):
    """The datagrams waiting on ``sock`` (at most ``most``), without waiting for more."""
    for _ in range(most):
        try:
            yield sock.recvfrom(65536, socket.MSG_DONTWAIT)
        except OSError:             # BlockingIOError: empty; or an ICMP error of a send
            return


class MavlinkRouter:
    """Agents send to ``agents_port``; the ground station is at ``gcs_port`` (127.0.0.1)."""

    def __init__(self, agents_port: int, gcs_port: int = 14550, host: str = "127.0.0.1",
                 interval: float = 0.01):
        self.gcs, self.interval = (host, gcs_port), interval
        self._agents = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._agents.bind((host, agents_port))
        self._gcs_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._gcs_sock.bind((host, 0))
        self.addresses: dict[int, tuple] = {}     # sysid -> agent address
        self.counts: Counter = Counter()
        self._parser = mav2.MAVLink(None)
        self._parser.robust_parsing = True
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="mavlink-router", daemon=True)

    @property
    def agents_port(self) -> int:
        return self._agents.getsockname()[1]

    def start(self) -> "MavlinkRouter":
        self._thread.start()
        return self

    def _targets(self, frame: bytes) -> list[tuple]:
        try:
            msgs = self._parser.parse_buffer(frame) or []
        except Exception:           # pymavlink raises its own base exception on bad frames
            self.counts["bad_from_gcs"] += 1
            return []
        if not msgs:
            return []
        target = getattr(msgs[0], "target_system", 0)     # none (HEARTBEAT): everyone
        if target == 0:
            return list(self.addresses.values())
        addr = self.addresses.get(target)
        if addr is None:
            self.counts["unknown_target"] += 1
            return []
        return [addr]

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            for data, addr in _waiting(self._agents):
                for frame in _frames(data):
                    sid = system_id(frame)
                    if sid:
                        self.addresses[sid] = addr
                self._send(self._gcs_sock, data, self.gcs)
                self.counts["to_gcs"] += 1
            for data, _ in _waiting(self._gcs_sock):
                for frame in _frames(data):
                    for target in self._targets(frame):
                        self._send(self._agents, frame, target)
                        self.counts["to_agents"] += 1

    def _send(self, sock: socket.socket, data: bytes, to: tuple) -> None:
        try:
            sock.sendto(data, to)
        except OSError:             # e.g. refused: the ground station is not up yet
            self.counts["send_failed"] += 1

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2)
        self._agents.close()
        self._gcs_sock.close()
