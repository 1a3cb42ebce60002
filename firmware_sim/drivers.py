"""Emulated ODrive drivers on a CAN bus: the I/O shell around :mod:`firmware_sim.odrive_axis`.

:class:`EmulatedDrivers` serves N axes (node ids) on one python-can bus. Each
:meth:`~EmulatedDrivers.tick` at time ``now_s`` (monotonic seconds, passed in, so tests run on
simulated time over the ``virtual`` bus):

1. advances every axis by the time since the previous tick;
2. drains the bus without blocking and applies the commands addressed to its nodes (any of
   them feeds that axis's watchdog); remote (RTR) requests for Heartbeat, Get_Error,
   Get_Encoder_Estimates and Get_Bus_Voltage_Current are answered; frames that do not decode
   (wrong DLC, unknown id, NaN payload, value outside its table) are ignored and counted;
3. sends what is due: Heartbeat every ``heartbeat_period_s`` and Get_Encoder_Estimates every
   ``encoder_period_s`` per node (missed periods are skipped, never caught up), and frames whose
   injected delay has passed.

Fault injection per node (:class:`Faults`): silence it, drop a fraction of its frames (with the
injected, seeded RNG) or delay them; :meth:`~EmulatedDrivers.raise_error` sets an error bit.
Every frame goes through :mod:`transport.can_codec`; no byte is packed here.

:func:`serve` runs the drivers on a real bus in real time (a process entry point).
"""
from __future__ import annotations

import heapq
import logging
import math
import random
import signal
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Callable

import can

from firmware_sim.odrive_axis import AxisConfig, AxisStatus, OdriveAxis
from transport.can_bus import BusConfig, open_bus
from transport.can_codec import (MAX_NODE, AxisError, BusVoltageCurrent, ClearErrors, Command,
                                 EncoderEstimates, ErrorStatus, Estop, Heartbeat, Rejected,
                                 Request, SetAxisState, SetControllerMode,
                                 SetInputVel, SetLimits, decode, encode)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DriversConfig:
    """The drivers on one bus: their node ids, feedback periods [s], axis emulation."""

    nodes: tuple[int, ...] = (0, 1)
    heartbeat_period_s: float = 0.1
    encoder_period_s: float = 0.01
    axis: AxisConfig = field(default_factory=AxisConfig)

    def __post_init__(self) -> None:
        if not self.nodes or len(set(self.nodes)) != len(self.nodes):
            raise ValueError(f"nodes: need distinct node ids, got {self.nodes!r}")
        if any(not 0 <= n <= MAX_NODE for n in self.nodes):
            raise ValueError(f"nodes: node ids are 0..{MAX_NODE}, got {self.nodes!r}")
        for name in ("heartbeat_period_s", "encoder_period_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: must be > 0, got {value!r}")


@dataclass(frozen=True)
class Faults:
    """Injected faults of one node's transmissions."""

    silent: bool = False             # sends nothing, answers nothing
    drop_fraction: float = 0.0       # 0..1, fraction of its frames dropped at random
    delay_s: float = 0.0             # its frames go out this late

    def __post_init__(self) -> None:
        if not 0.0 <= self.drop_fraction <= 1.0:
            raise ValueError(f"drop_fraction: must be in [0, 1], got {self.drop_fraction!r}")
        if not (math.isfinite(self.delay_s) and self.delay_s >= 0):
            raise ValueError(f"delay_s: must be >= 0, got {self.delay_s!r}")


@dataclass
class DriverCounters:
    """What the drivers did with frames, for tests and run metrics."""

    sent: int = 0
    dropped: int = 0                 # by fault injection (silent or drop_fraction)
    send_failures: int = 0
    unanswered_requests: int = 0     # RTR for a command that has no data to send
    rejected: Counter = field(default_factory=Counter)   # Rejection -> count


class EmulatedDrivers:
    """Emulated ODrive axes ``config.nodes`` on ``bus`` (which the caller opens and closes)."""

    def __init__(self, bus: can.BusABC, config: DriversConfig | None = None,
                 rng: random.Random | None = None):
        self.bus = bus
        self.config = config or DriversConfig()
        self.rng = rng or random.Random(0)
        self.counters = DriverCounters()
        self._axes = {node: OdriveAxis(self.config.axis) for node in self.config.nodes}
        self._faults = {node: Faults() for node in self.config.nodes}
        self._due: dict[tuple[int, Command], float] = {}
        self._delayed: list[tuple[float, int, can.Message]] = []
        self._seq = 0
        self._now: float | None = None

    def axis(self, node: int) -> OdriveAxis:
        """The emulated axis of ``node``."""
        return self._axes[node]

    def set_faults(self, node: int, faults: Faults) -> None:
        """Inject (or with ``Faults()`` remove) faults of ``node``'s transmissions."""
        if node not in self._axes:
            raise ValueError(f"node: {node} is not one of {self.config.nodes}")
        self._faults[node] = faults

    def raise_error(self, node: int, error: AxisError) -> None:
        """Fault injection: raise ``error`` on ``node`` (disarms it if in closed loop)."""
        self._axes[node].raise_error(error)

    def tick(self, now_s: float) -> None:
        """Advance the axes to ``now_s``, handle received frames, send what is due."""
        if self._now is not None:
            if now_s < self._now:
                raise ValueError(f"now_s: time went back from {self._now} to {now_s}")
            for axis in self._axes.values():
                axis.step(now_s - self._now)
        self._now = now_s
        while (msg := self.bus.recv(0.0)) is not None:
            self._handle(msg)
        for node, axis in self._axes.items():
            status = axis.status()
            if self._is_due(node, Command.HEARTBEAT, self.config.heartbeat_period_s):
                self._emit(node, _heartbeat(node, status))
            if self._is_due(node, Command.GET_ENCODER_ESTIMATES, self.config.encoder_period_s):
                self._emit(node, encode(EncoderEstimates(node, status.pos_rev, status.vel_rev_s)))
        while self._delayed and self._delayed[0][0] <= now_s:
            self._send(heapq.heappop(self._delayed)[2])

    def _is_due(self, node: int, command: Command, period_s: float) -> bool:
        due = self._due.get((node, command), self._now)
        if self._now < due:
            return False
        skipped = math.floor((self._now - due) / period_s)
        self._due[(node, command)] = due + (skipped + 1) * period_s
        return True

    def _handle(self, msg: can.Message) -> None:
        record = decode(msg)
        if isinstance(record, Rejected):
            self.counters.rejected[record.reason] += 1
            log.debug("ignored frame: %s", record.detail)
            return
        axis = self._axes.get(record.node)
        if axis is None:
            return                                   # another node on this bus
        if isinstance(record, Request):
            axis.feed_watchdog()
            self._answer(record, axis.status())
            return
        match record:
            case SetInputVel(vel_rev_s=vel):
                axis.set_input_vel(vel)
            case SetAxisState(requested_state=state):
                axis.request_state(state)
            case SetControllerMode(control_mode=control, input_mode=mode):
                axis.set_controller_mode(control, mode)
            case SetLimits(vel_limit_rev_s=vel_limit, current_limit_a=current_limit):
                axis.set_limits(vel_limit, current_limit)
            case Estop():
                axis.estop()
            case ClearErrors():
                axis.clear_errors()
            case _:
                return                               # what axes send (another driver's frame)
        axis.feed_watchdog()

    def _answer(self, request: Request, status: AxisStatus) -> None:
        node = request.node
        if request.command is Command.HEARTBEAT:
            reply = _heartbeat(node, status)
        elif request.command is Command.GET_ENCODER_ESTIMATES:
            reply = encode(EncoderEstimates(node, status.pos_rev, status.vel_rev_s))
        elif request.command is Command.GET_ERROR:
            reply = encode(ErrorStatus(node, status.active_errors, status.disarm_reason))
        elif request.command is Command.GET_BUS_VOLTAGE_CURRENT:
            reply = encode(BusVoltageCurrent(node, status.bus_voltage_v, status.bus_current_a))
        else:
            self.counters.unanswered_requests += 1
            return
        self._emit(node, reply)

    def _emit(self, node: int, msg: can.Message) -> None:
        faults = self._faults[node]
        if faults.silent or (faults.drop_fraction and self.rng.random() < faults.drop_fraction):
            self.counters.dropped += 1
        elif faults.delay_s > 0:
            self._seq += 1
            heapq.heappush(self._delayed, (self._now + faults.delay_s, self._seq, msg))
        else:
            self._send(msg)

    def _send(self, msg: can.Message) -> None:
        try:
            self.bus.send(msg)
            self.counters.sent += 1
        except can.CanError as exc:
            self.counters.send_failures += 1
            log.warning("emulated driver could not send 0x%03X: %s", msg.arbitration_id, exc)


def _heartbeat(node: int, status: AxisStatus) -> can.Message:
    return encode(Heartbeat(node, status.axis_error, status.state, status.procedure_result,
                            trajectory_done=True))


def run_realtime(drivers: EmulatedDrivers, step_s: float, should_stop: Callable[[], bool],
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> int:
    """Tick ``drivers`` every ``step_s`` on absolute deadlines until ``should_stop()``.

    Missed deadlines are skipped, not caught up; returns how many were skipped.
    """
    skipped_total = 0
    deadline = clock()
    while not should_stop():
        drivers.tick(clock())
        deadline += step_s
        now = clock()
        if now < deadline:
            sleep(deadline - now)
        else:
            skipped = math.floor((now - deadline) / step_s)
            skipped_total += skipped
            deadline += skipped * step_s
    return skipped_total


def serve(bus_config: BusConfig, config: DriversConfig | None = None,
          step_s: float = 0.001) -> None:
    """Process entry point: emulated drivers on ``bus_config`` until SIGTERM or SIGINT."""
    stop = []
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.append(True))
    bus = open_bus(bus_config)
    try:
        drivers = EmulatedDrivers(bus, config)
        log.info("emulated drivers %s on %s", drivers.config.nodes, bus.channel_info)
        skipped = run_realtime(drivers, step_s, lambda: bool(stop))
        log.info("emulated drivers stopped: %s, %d skipped steps", drivers.counters, skipped)
    finally:
        bus.shutdown()
