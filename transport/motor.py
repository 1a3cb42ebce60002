"""The host side of one robot's two ODrive wheel axes over CAN Simple (agent.ports.MotorPort).

* :meth:`MotorLink.arm`: per axis, zero velocity (the firmware keeps ``input_vel`` across
  IDLE), VELOCITY_CONTROL with VEL_RAMP, the limits, then CLOSED_LOOP_CONTROL. Arming does
  not clear errors: :meth:`MotorLink.clear_errors` does, explicitly (an Estop stays latched).
* :meth:`MotorLink.command`: both wheel velocities [rev/s], every control period; this also
  feeds the drivers' watchdogs. A non-finite velocity is never sent: both wheels get zero.
* :meth:`MotorLink.poll` drains the bus without blocking: Heartbeat (state, errors,
  procedure result), encoder estimates and RTR answers per axis, each stamped with the
  injected monotonic clock, so :meth:`MotorLink.axis` reports their ages.
* :meth:`MotorLink.disarm` is the shutdown: zero velocity, then IDLE. :meth:`MotorLink.estop`.

Frames that do not decode are ignored and counted by :class:`~transport.can_codec.Rejection`;
command frames to our axes from another sender (a second writer) are counted and logged.
Every frame comes from :mod:`transport.can_codec`. Positive wheel velocity drives forward.
"""
from __future__ import annotations

import enum
import logging
import math
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Callable

import can

from agent.ports import WheelFeedback
from transport.can_codec import (MAX_NODE, AxisError, AxisState, BusVoltageCurrent, Command,
                                 ControlMode, EncoderEstimates, ErrorStatus, Heartbeat,
                                 InputMode, ProcedureResult, Rejected, Request, decode,
                                 error_names, make_clear_errors, make_estop, make_request,
                                 make_set_axis_state, make_set_controller_mode,
                                 make_set_input_vel, make_set_limits)

log = logging.getLogger(__name__)


class Wheel(enum.Enum):
    LEFT = "left"
    RIGHT = "right"


@dataclass(frozen=True)
class MotorConfig:
    """Node ids of the two axes and the limits sent when arming."""

    left_node: int = 0
    right_node: int = 1
    vel_limit_rev_s: float = 10.0
    current_limit_a: float = 20.0

    def __post_init__(self) -> None:
        for name in ("left_node", "right_node"):
            node = getattr(self, name)
            if not isinstance(node, int) or not 0 <= node <= MAX_NODE:
                raise ValueError(f"{name}: CAN Simple node ids are 0..{MAX_NODE}, got {node!r}")
        if self.left_node == self.right_node:
            raise ValueError(f"right_node: must differ from left_node ({self.left_node})")
        for name in ("vel_limit_rev_s", "current_limit_a"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {value!r}")

    def node(self, wheel: Wheel) -> int:
        return self.left_node if wheel is Wheel.LEFT else self.right_node


@dataclass(frozen=True)
class AxisFeedback:
    """What one axis last reported; ages [s] on the link's clock, inf if never heard."""

    node: int
    state: AxisState
    axis_error: AxisError
    procedure_result: ProcedureResult
    pos_rev: float
    vel_rev_s: float
    heartbeat_age_s: float
    encoder_age_s: float
    bus_voltage_v: float | None      # from the last Get_Bus_Voltage_Current answer
    bus_current_a: float | None

    @property
    def error_names(self) -> tuple[str, ...]:
        return error_names(self.axis_error)

    @property
    def closed_loop(self) -> bool:
        return self.state is AxisState.CLOSED_LOOP_CONTROL


@dataclass
class _Track:
    """Latest values of one axis and the clock time [s] they arrived."""

    state: AxisState = AxisState.UNDEFINED
    axis_error: AxisError = AxisError.NONE
    procedure_result: ProcedureResult = ProcedureResult.SUCCESS
    pos_rev: float = 0.0
    vel_rev_s: float = 0.0
    bus_voltage_v: float | None = None
    bus_current_a: float | None = None
    heartbeat_at: float = -math.inf
    encoder_at: float = -math.inf


@dataclass
class LinkCounters:
    sent: int = 0
    send_failures: int = 0
    nonfinite_commands: int = 0      # command() calls with NaN/inf, replaced by zero
    other_writers: int = 0           # command frames to our axes not sent by us
    rejected: Counter = field(default_factory=Counter)   # Rejection -> count


class MotorLink:
    """Left and right wheel axes of one robot on ``bus`` (opened and closed by the caller).

    ``clock``: monotonic seconds (never wall-clock), injected so tests run on simulated time.
    """

    def __init__(self, bus: can.BusABC, config: MotorConfig | None = None,
                 clock: Callable[[], float] = time.monotonic):
        self.bus, self.clock = bus, clock
        self.config = config or MotorConfig()
        self.counters = LinkCounters()
        self._tracks = {self.config.left_node: _Track(), self.config.right_node: _Track()}

    # --- commands -----------------------------------------------------------------------------
    def arm(self) -> None:
        """Velocity control with VEL_RAMP, limits, zero set-point, then CLOSED_LOOP_CONTROL."""
        cfg = self.config
        for node in self._tracks:
            self._send(make_set_input_vel(node, 0.0))
            self._send(make_set_controller_mode(node, ControlMode.VELOCITY_CONTROL,
                                                InputMode.VEL_RAMP))
            self._send(make_set_limits(node, cfg.vel_limit_rev_s, cfg.current_limit_a))
            self._send(make_set_axis_state(node, AxisState.CLOSED_LOOP_CONTROL))

    def command(self, right_rev_s: float, left_rev_s: float) -> None:
        """Wheel velocity set-points [rev/s]; NaN/inf anywhere sends zero to both."""
        if not (math.isfinite(right_rev_s) and math.isfinite(left_rev_s)):
            self.counters.nonfinite_commands += 1
            log.warning("non-finite wheel command (%r, %r): sending zero",
                        right_rev_s, left_rev_s)
            right_rev_s = left_rev_s = 0.0
        self._send(make_set_input_vel(self.config.right_node, right_rev_s))
        self._send(make_set_input_vel(self.config.left_node, left_rev_s))

    def disarm(self) -> None:
        """The shutdown sequence: zero velocity, then IDLE, on both axes."""
        for node in self._tracks:
            self._send(make_set_input_vel(node, 0.0))
        for node in self._tracks:
            self._send(make_set_axis_state(node, AxisState.IDLE))

    def clear_errors(self) -> None:
        """Clear_Errors on both axes."""
        for node in self._tracks:
            self._send(make_clear_errors(node))

    def estop(self) -> None:
        """Estop on both axes (latched until :meth:`clear_errors`)."""
        for node in self._tracks:
            self._send(make_estop(node))

    def request(self, command: Command) -> None:
        """RTR request of ``command`` (a Get_* message or Heartbeat) to both axes."""
        for node in self._tracks:
            self._send(make_request(node, command))

    def _send(self, msg: can.Message) -> None:
        try:
            self.bus.send(msg)
            self.counters.sent += 1
        except can.CanError as exc:
            self.counters.send_failures += 1
            log.warning("CAN send of 0x%03X failed: %s", msg.arbitration_id, exc)

    # --- feedback -----------------------------------------------------------------------------
    def poll(self) -> int:
        """Drain every received frame without blocking; returns how many were used."""
        used = 0
        while (msg := self.bus.recv(0.0)) is not None:
            used += self._use(msg)
        return used

    def _use(self, msg: can.Message) -> bool:
        record = decode(msg)
        if isinstance(record, Rejected):
            self.counters.rejected[record.reason] += 1
            log.debug("ignored frame: %s", record.detail)
            return False
        track = self._tracks.get(record.node)
        if track is None or isinstance(record, Request):
            return False
        now = self.clock()
        if isinstance(record, Heartbeat):
            track.state, track.axis_error = record.axis_state, record.axis_error
            track.procedure_result, track.heartbeat_at = record.procedure_result, now
        elif isinstance(record, EncoderEstimates):
            track.pos_rev, track.vel_rev_s, track.encoder_at = (record.pos_rev, record.vel_rev_s,
                                                                now)
        elif isinstance(record, BusVoltageCurrent):
            track.bus_voltage_v, track.bus_current_a = record.voltage_v, record.current_a
        elif isinstance(record, ErrorStatus):
            track.axis_error = record.active_errors | record.disarm_reason
        else:
            self.counters.other_writers += 1
            log.warning("another sender commands node %d: %s", record.node, record)
            return False
        return True

    def axis(self, wheel: Wheel) -> AxisFeedback:
        """What ``wheel``'s axis last reported, with ages now (does not poll)."""
        node = self.config.node(wheel)
        t, now = self._tracks[node], self.clock()
        return AxisFeedback(node=node, state=t.state, axis_error=t.axis_error,
                            procedure_result=t.procedure_result, pos_rev=t.pos_rev,
                            vel_rev_s=t.vel_rev_s, heartbeat_age_s=now - t.heartbeat_at,
                            encoder_age_s=now - t.encoder_at, bus_voltage_v=t.bus_voltage_v,
                            bus_current_a=t.bus_current_a)

    def feedback(self) -> WheelFeedback | None:
        """Poll, then both wheels as the agent uses them; None before both sent estimates."""
        self.poll()
        right, left = self.axis(Wheel.RIGHT), self.axis(Wheel.LEFT)
        if math.isinf(right.encoder_age_s) or math.isinf(left.encoder_age_s):
            return None
        errors = tuple(f"{wheel.value}: {name}" for wheel, fb in
                       ((Wheel.RIGHT, right), (Wheel.LEFT, left)) for name in fb.error_names)
        return WheelFeedback(pos_rev=(right.pos_rev, left.pos_rev),
                             vel_rev_s=(right.vel_rev_s, left.vel_rev_s),
                             age=max(right.encoder_age_s, left.encoder_age_s),
                             closed_loop=right.closed_loop and left.closed_loop, errors=errors)
