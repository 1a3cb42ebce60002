"""What a robot's CAN bus carries, decoded with the project's DBC: rates, ages, load, alarms.

:class:`BusStats` is fed received frames (python-can messages with timestamps, live or from
a log) and keeps, per message and node, the count, the rate over a sliding window, the age
of the last frame and its decoded signals (units and value-table names from the DBC). It
computes the bus load from exact frame bit lengths against a declared bit rate and raises
alarms: a node whose heartbeat is missing, an axis error (watchdog and the others, by
name), a velocity set-point at the velocity limit, unknown ids, wrong DLC, non-finite
payloads. It does no I/O; the ``boundswarm can`` commands feed it.
"""
from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, field

import can

from transport.busload import frame_bits
from transport.odrive_frames import (
    AxisState,
    Cmd,
    FrameError,
    cycle_time,
    decode,
    error_names,
    message_name,
)

WINDOW = 2.0           # s, for rates and load
STALE_AFTER = 3.0      # heartbeat periods without one: the node is stale


@dataclass
class Stream:
    """One message of one node."""

    name: str
    node: int
    count: int = 0
    last_t: float = -math.inf
    signals: dict = field(default_factory=dict)
    times: deque = field(default_factory=deque)

    def rate(self, now: float) -> float:
        while self.times and now - self.times[0] > WINDOW:
            self.times.popleft()
        span = min(WINDOW, now - self.times[0]) if self.times else 0.0
        return (len(self.times) - 1) / span if len(self.times) > 1 and span > 0 else 0.0


@dataclass(frozen=True)
class Alarm:
    kind: str           # stale_node, axis_error, at_velocity_limit, unknown_id, dlc, nonfinite
    node: int | None
    detail: str


class BusStats:
    """Accumulates frames of one bus; ``sides`` names nodes (e.g. {0: "left", 1: "right"})."""

    def __init__(self, bitrate: int = 500_000, sides: dict[int, str] | None = None,
                 vel_limit: float | None = None, nodes: set[int] | None = None,
                 messages: set[str] | None = None):
        self.bitrate = bitrate
        self.sides = sides or {0: "left", 1: "right"}
        self.vel_limit = vel_limit
        self.node_filter = nodes
        self.message_filter = {m.lower() for m in messages} if messages else None
        self.streams: dict[tuple[str, int], Stream] = {}
        self.rejected: Counter = Counter()
        self.rejected_last: dict[str, str] = {}
        self._bits: deque = deque()           # (t, bits) within the window
        self.total_frames = 0
        self.first_t: float | None = None
        self.last_t: float | None = None

    def feed(self, msg: can.Message) -> None:
        t = msg.timestamp
        self.first_t = t if self.first_t is None else self.first_t
        self.last_t = t
        self.total_frames += 1
        self._bits.append((t, frame_bits(msg)))
        try:
            frame = decode(msg)
        except FrameError as exc:
            self.rejected[exc.reason] += 1
            self.rejected_last[exc.reason] = f"id 0x{msg.arbitration_id:03x}, {len(msg.data)} B"
            return
        base = message_name(frame.cmd)
        name = base if not frame.rtr else f"{base} (RTR)"
        if self.node_filter is not None and frame.node not in self.node_filter:
            return
        if self.message_filter is not None and base.lower() not in self.message_filter:
            return
        key = (name, frame.node)
        stream = self.streams.get(key)
        if stream is None:
            stream = self.streams[key] = Stream(name, frame.node)
        stream.count += 1
        stream.last_t = t
        stream.times.append(t)
        if frame.signals:
            stream.signals = frame.signals

    def load(self, now: float) -> float:
        """Bus load over the last window (or since the first frame, if shorter)."""
        while self._bits and now - self._bits[0][0] > WINDOW:
            self._bits.popleft()
        if not self._bits or self.first_t is None:
            return 0.0
        span = max(min(WINDOW, now - self.first_t), 1e-3)
        return sum(b for _, b in self._bits) / (span * self.bitrate)

    def alarms(self, now: float) -> list[Alarm]:
        out: list[Alarm] = []
        hb_period = cycle_time(Cmd.HEARTBEAT) or 0.1
        nodes = {node for (_, node) in self.streams}
        for node in sorted(nodes):
            hb = self.streams.get(("Heartbeat", node))
            if hb is None or now - hb.last_t > STALE_AFTER * hb_period:
                age = "never" if hb is None else f"{now - hb.last_t:.2f} s ago"
                out.append(Alarm("stale_node", node, f"last heartbeat {age}"))
            elif hb.signals.get("Axis_Error"):
                names = error_names(int(hb.signals["Axis_Error"]))
                kind = "watchdog" if "WATCHDOG_TIMER_EXPIRED" in names else "axis_error"
                out.append(Alarm(kind, node, ", ".join(names)))
            cmd = self.streams.get(("Set_Input_Vel", node))
            if cmd is not None and self.vel_limit and \
                    abs(cmd.signals.get("Input_Vel", 0.0)) >= self.vel_limit - 1e-6:
                out.append(Alarm("at_velocity_limit", node,
                                 f"set-point {cmd.signals['Input_Vel']:.3f} rev/s"))
        for reason, n in sorted(self.rejected.items()):
            out.append(Alarm(reason, None, f"{n} frame(s), last {self.rejected_last[reason]}"))
        return out

    def describe(self, name: str, signals: dict) -> str:
        """Signals with units and value-table names, e.g. 'Axis_State: CLOSED_LOOP_CONTROL'."""
        parts = []
        for sig, value in signals.items():
            if sig == "Axis_State" or sig == "Axis_Requested_State":
                try:
                    value = AxisState(int(value)).name
                except ValueError:
                    pass
            elif sig in ("Axis_Error", "Active_Errors", "Disarm_Reason"):
                value = ", ".join(error_names(int(value))) or "none"
            elif isinstance(value, float):
                unit = _UNITS.get(sig, "")
                value = f"{value:.3f}{(' ' + unit) if unit else ''}"
            parts.append(f"{sig}={value}")
        return " ".join(parts)

    def summary(self, now: float) -> dict:
        """The ``can stats --json`` document."""
        return {"bus_load": round(self.load(now), 4), "bitrate": self.bitrate,
                "frames": self.total_frames,
                "messages": [{"name": s.name, "node": s.node,
                              "side": self.sides.get(s.node), "rate_hz": round(s.rate(now), 1),
                              "expected_hz": _expected(s.name), "count": s.count,
                              "age_s": round(now - s.last_t, 3), "signals": s.signals}
                             for s in sorted(self.streams.values(),
                                             key=lambda s: (s.node, s.name))],
                "rejected": dict(self.rejected),
                "alarms": [{"kind": a.kind, "node": a.node, "detail": a.detail}
                           for a in self.alarms(now)]}


def _expected(name: str) -> float | None:
    period = next((cycle_time(c) for c in Cmd if message_name(c) == name), None)
    return round(1.0 / period, 1) if period else None


def _units() -> dict[str, str]:
    from transport.odrive_frames import database
    return {sig.name: sig.unit for m in database().messages for sig in m.signals if sig.unit}


_UNITS = _units()
