"""systemd's notify protocol (sd_notify) for the agent service, without a dependency.

READY=1 once both drivers are armed (closed loop); WATCHDOG=1 only while the control loop
keeps its deadlines, so a stalled or overrunning loop is restarted by systemd
(``WatchdogSec``); STOPPING=1 on shutdown. Outside systemd (no NOTIFY_SOCKET) it does
nothing.
"""
from __future__ import annotations

import os
import socket


class Notifier:
    def __init__(self, address: str | None = None, min_interval: float = 0.5):
        address = address if address is not None else os.environ.get("NOTIFY_SOCKET")
        if address and address.startswith("@"):
            address = "\0" + address[1:]               # abstract namespace
        self.address = address or None
        self.min_interval = min_interval
        self.ready_sent = False
        self._last_watchdog = -float("inf")

    @property
    def enabled(self) -> bool:
        return self.address is not None

    def send(self, state: str) -> None:
        if self.address is None:                        # not enabled
            return
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as s:
            s.sendto(state.encode(), self.address)

    def ready(self, status: str) -> None:
        if not self.ready_sent:
            self.send(f"READY=1\nSTATUS={status}")
            self.ready_sent = True

    def watchdog(self, now: float, on_time: bool) -> None:
        """Feed the watchdog (at most every ``min_interval`` s) while the loop is on time."""
        if on_time and now - self._last_watchdog >= self.min_interval:
            self.send("WATCHDOG=1")
            self._last_watchdog = now

    def stopping(self) -> None:
        self.send("STOPPING=1")
