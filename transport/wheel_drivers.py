"""The host side of a robot's two ODrive wheel drivers (common.ports.MotorPort).

Arming: clear errors, velocity control with VEL_RAMP, limits, CLOSED_LOOP_CONTROL. Every
period the agent sends both wheel velocities [rev/s] (which also feeds the drivers'
watchdogs). Feedback is drained without blocking: heartbeats (state, errors) and encoder
estimates per axis, each with its age on the injected monotonic clock. Shutdown: zero
velocity, then IDLE. Frames go out with the lengths of ODrive's official DBC; frames that
do not decode are ignored and counted.
"""
from __future__ import annotations

import logging
import math
import time
from collections import Counter
from dataclasses import dataclass
from typing import Callable

import can

from common import drivers
from common.vocabulary import WheelFeedback
from transport.odrive_frames import (
    AxisState,
    Cmd,
    ControlMode,
    InputMode,
    encode,
    error_names,
    receive,
)

log = logging.getLogger(__name__)


@dataclass
class AxisStatus:
    """What one driver last reported, with the monotonic times [s] it arrived."""

    state: int = AxisState.UNDEFINED
    error: int = 0
    pos: float = 0.0            # rev
    vel: float = 0.0            # rev/s
    heartbeat_at: float = -float("inf")
    encoder_at: float = -float("inf")

    @property
    def error_names(self) -> tuple[str, ...]:
        return error_names(self.error)


class WheelDrivers:
    """Left and right ODrive axes on one bus; + wheel velocity drives the robot forward."""

    def __init__(self, bus: can.BusABC, left_node: int = drivers.LEFT_NODE,
                 right_node: int = drivers.RIGHT_NODE, vel_limit: float = drivers.SPEED_LIMIT,
                 current_limit: float = drivers.CURRENT_LIMIT,
                 clock: Callable[[], float] = time.monotonic):
        self.bus, self.clock = bus, clock
        self.left_node, self.right_node = left_node, right_node
        self.vel_limit, self.current_limit = vel_limit, current_limit
        self.status = {left_node: AxisStatus(), right_node: AxisStatus()}
        self.ignored: Counter = Counter()
        self.sent = 0

    def _send(self, msg: can.Message) -> None:
        try:
            self.bus.send(msg)
            self.sent += 1
        except can.CanError as exc:
            self.ignored["send_failed"] += 1
            log.warning("CAN send failed: %s", exc)

    def _both(self, cmd: Cmd, **signals: float) -> None:
        for node in (self.left_node, self.right_node):
            self._send(encode(node, cmd, **signals))

    def arm(self) -> None:
        """Velocity mode with ramp, limits, zero set-point, closed loop. Errors are not
        cleared here: a latched error (Estop, watchdog) needs :meth:`clear_errors`."""
        self._both(Cmd.SET_CONTROLLER_MODE, Control_Mode=ControlMode.VELOCITY_CONTROL,
                   Input_Mode=InputMode.VEL_RAMP)
        self._both(Cmd.SET_LIMITS, Velocity_Limit=self.vel_limit,
                   Current_Limit=self.current_limit)
        self._both(Cmd.SET_INPUT_VEL, Input_Vel=0.0, Input_Torque_FF=0.0)
        self._both(Cmd.SET_AXIS_STATE, Axis_Requested_State=AxisState.CLOSED_LOOP_CONTROL)

    def disarm(self) -> None:
        self._both(Cmd.SET_INPUT_VEL, Input_Vel=0.0, Input_Torque_FF=0.0)
        self._both(Cmd.SET_AXIS_STATE, Axis_Requested_State=AxisState.IDLE)

    def command(self, right_rev_s: float, left_rev_s: float) -> None:
        """Wheel velocity set-points [rev/s]; a non-finite one is sent as zero and counted."""
        if not (math.isfinite(right_rev_s) and math.isfinite(left_rev_s)):
            self.ignored["nonfinite_command"] += 1
            right_rev_s = left_rev_s = 0.0
        self._send(encode(self.right_node, Cmd.SET_INPUT_VEL, Input_Vel=right_rev_s,
                          Input_Torque_FF=0.0))
        self._send(encode(self.left_node, Cmd.SET_INPUT_VEL, Input_Vel=left_rev_s,
                          Input_Torque_FF=0.0))

    def clear_errors(self) -> None:
        """Clear_Errors as the official DBC lays it out: its one byte, Identify = 0."""
        self._both(Cmd.CLEAR_ERRORS, Identify=0)

    def estop(self) -> None:
        self._both(Cmd.ESTOP)

    def poll(self) -> int:
        """Drain every waiting frame (never blocks); returns how many were used."""
        used = 0
        for frame in receive(self.bus, self.ignored):
            st = self.status.get(frame.node)
            if st is None or frame.rtr:
                continue
            now = self.clock()
            if frame.cmd == Cmd.HEARTBEAT:
                st.state, st.error = int(frame.signals["Axis_State"]), int(
                    frame.signals["Axis_Error"])
                st.heartbeat_at = now
                used += 1
            elif frame.cmd == Cmd.GET_ENCODER_ESTIMATES:
                st.pos, st.vel = frame.signals["Pos_Estimate"], frame.signals["Vel_Estimate"]
                st.encoder_at = now
                used += 1
        return used

    def feedback(self) -> WheelFeedback | None:
        self.poll()
        r, l_ = self.status[self.right_node], self.status[self.left_node]
        if r.encoder_at == -float("inf") or l_.encoder_at == -float("inf"):
            return None
        now = self.clock()
        errors = tuple(f"{side}: {name}" for side, st in (("right", r), ("left", l_))
                       for name in st.error_names)
        # the two axes report apart: both positions at the newer report's arrival, the older
        # carried forward at its velocity (paired as they come, a wheel 10 ms behind the
        # other at 10 rev/s reads as a 0.16 rad heading error, and odometry drifts sideways)
        at = max(r.encoder_at, l_.encoder_at)
        return WheelFeedback(pos_rev=(r.pos + r.vel * (at - r.encoder_at),
                                      l_.pos + l_.vel * (at - l_.encoder_at)),
                             vel_rev_s=(r.vel, l_.vel),
                             age=now - min(r.encoder_at, l_.encoder_at),
                             closed_loop=(r.state == AxisState.CLOSED_LOOP_CONTROL
                                          and l_.state == AxisState.CLOSED_LOOP_CONTROL),
                             errors=errors)
