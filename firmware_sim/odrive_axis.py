"""Emulated ODrive v0.6 firmware of one axis: the state machine and the wheel, no I/O.

Theory of operation. The axis is IDLE or in CLOSED_LOOP_CONTROL; it moves its wheel only in
closed loop. Time is passed in: :meth:`OdriveAxis.step` advances it by ``dt`` seconds.

* **Arming.** A request for CLOSED_LOOP_CONTROL is refused while an error is set
  (``active_errors | disarm_reason``): the axis stays IDLE and ``procedure_result`` becomes
  DISARMED, as the firmware does. Otherwise it enters closed loop (procedure BUSY) with the
  velocity set-point taken from the current wheel speed (bumpless; the inner current loop is
  not modelled). Requesting IDLE ends closed loop (procedure SUCCESS); UNDEFINED is a no-op;
  calibration and other procedures are not emulated (procedure INVALID_STATE, state unchanged).
* **Velocity control.** ``input_vel`` is kept across IDLE, as in the firmware (so a host sends
  zero before arming). In closed loop with VELOCITY_CONTROL the set-point follows
  ``clamp(input_vel, ±vel_limit)``: at ``vel_ramp_rate`` rev/s² with input mode VEL_RAMP,
  at once with PASSTHROUGH; other modes are not emulated and brake to zero at the ramp rate.
  The wheel speed equals the set-point (ideal inner loop).
* **Watchdog.** Any command addressed to the axis feeds it (CAN Simple does this for every
  message to the node). In closed loop, ``watchdog_timeout_s`` without a feed disarms the axis
  with WATCHDOG_TIMER_EXPIRED in ``disarm_reason`` and drops it to IDLE.
* **Errors.** Estop disarms with ESTOP_REQUESTED; an injected error bit is active and, in
  closed loop, disarms. Clear_Errors clears both ``active_errors`` and ``disarm_reason``.
* **Wheel.** In IDLE the wheel coasts down, first order with ``coast_time_constant_s``. The
  encoder position is the exact integral of the wheel speed over each step.
* **Bus.** Current drawn = idle + acceleration + speed terms (closed loop only), capped at the
  current limit; voltage sags with the supply resistance.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, fields

from transport.can_codec import AxisError, AxisState, ControlMode, InputMode, ProcedureResult

log = logging.getLogger(__name__)

_STOPPED_REV_S = 1e-6                # a coasting wheel slower than this has stopped
_TIME_EPS_S = 1e-9                   # summed float steps of exactly the timeout do not trip


@dataclass(frozen=True)
class AxisConfig:
    """Emulation parameters of one axis; units in the names."""

    vel_limit_rev_s: float = 10.0
    current_limit_a: float = 20.0
    vel_ramp_rate_rev_s2: float = 1000.0
    watchdog_timeout_s: float = 0.1          # 0 disables the watchdog
    coast_time_constant_s: float = 0.3
    bus_voltage_v: float = 24.0              # supply voltage at no load
    supply_resistance_ohm: float = 0.05
    idle_current_a: float = 0.05             # drawn in closed loop at standstill
    current_per_accel_a_s2_per_rev: float = 0.01
    current_per_speed_a_s_per_rev: float = 0.05

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"{f.name}: must be a finite number >= 0, got {value!r}")
        for name in ("vel_limit_rev_s", "current_limit_a", "vel_ramp_rate_rev_s2",
                     "coast_time_constant_s", "bus_voltage_v"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class AxisStatus:
    """A snapshot of one axis, what its CAN frames report."""

    state: AxisState
    procedure_result: ProcedureResult
    active_errors: AxisError
    disarm_reason: AxisError
    control_mode: ControlMode
    input_mode: InputMode
    vel_limit_rev_s: float
    current_limit_a: float
    input_vel_rev_s: float
    vel_setpoint_rev_s: float
    vel_rev_s: float                 # actual wheel speed
    pos_rev: float                   # encoder position
    bus_voltage_v: float
    bus_current_a: float
    watchdog_trips: int

    @property
    def axis_error(self) -> AxisError:
        """What the Heartbeat reports: active_errors | disarm_reason."""
        return self.active_errors | self.disarm_reason


class OdriveAxis:
    """One emulated axis (see the module docstring for its behaviour)."""

    def __init__(self, config: AxisConfig | None = None):
        self.config = config or AxisConfig()
        self._state = AxisState.IDLE
        self._procedure = ProcedureResult.SUCCESS
        self._active = AxisError.NONE
        self._disarm_reason = AxisError.NONE
        self._control_mode = ControlMode.VELOCITY_CONTROL
        self._input_mode = InputMode.VEL_RAMP
        self._vel_limit = self.config.vel_limit_rev_s
        self._current_limit = self.config.current_limit_a
        self._input_vel = 0.0
        self._setpoint = 0.0
        self._vel = 0.0
        self._pos = 0.0
        self._bus_current = 0.0
        self._since_feed = 0.0
        self._watchdog_trips = 0

    # --- commands -----------------------------------------------------------------------------
    def request_state(self, requested: AxisState) -> None:
        """Set_Axis_State."""
        requested = AxisState(requested)
        if requested is AxisState.UNDEFINED:
            return
        if requested is AxisState.IDLE:
            if self._state is AxisState.CLOSED_LOOP_CONTROL:
                self._procedure = ProcedureResult.SUCCESS
            self._state = AxisState.IDLE
        elif requested is AxisState.CLOSED_LOOP_CONTROL:
            if self._active | self._disarm_reason:
                log.info("closed loop refused: errors %s", self._active | self._disarm_reason)
                self._procedure = ProcedureResult.DISARMED
            elif self._state is not AxisState.CLOSED_LOOP_CONTROL:
                self._state = AxisState.CLOSED_LOOP_CONTROL
                self._procedure = ProcedureResult.BUSY
                self._setpoint = max(-self._vel_limit, min(self._vel_limit, self._vel))
                self._since_feed = 0.0
        else:
            log.warning("requested state %s is not emulated", requested.name)
            self._procedure = ProcedureResult.INVALID_STATE

    def set_controller_mode(self, control_mode: ControlMode, input_mode: InputMode) -> None:
        """Set_Controller_Mode (only VELOCITY_CONTROL with VEL_RAMP/PASSTHROUGH drives)."""
        self._control_mode, self._input_mode = ControlMode(control_mode), InputMode(input_mode)

    def set_input_vel(self, vel_rev_s: float) -> None:
        """Set_Input_Vel [rev/s] (torque feed-forward is not emulated)."""
        if math.isfinite(vel_rev_s):
            self._input_vel = vel_rev_s

    def set_limits(self, vel_limit_rev_s: float, current_limit_a: float) -> None:
        """Set_Limits; a non-finite or non-positive limit is ignored."""
        if math.isfinite(vel_limit_rev_s) and vel_limit_rev_s > 0:
            self._vel_limit = vel_limit_rev_s
            self._setpoint = max(-vel_limit_rev_s, min(vel_limit_rev_s, self._setpoint))
            if self._state is AxisState.CLOSED_LOOP_CONTROL:
                self._vel = self._setpoint
        if math.isfinite(current_limit_a) and current_limit_a > 0:
            self._current_limit = current_limit_a

    def feed_watchdog(self) -> None:
        """Any command to the axis feeds its watchdog."""
        self._since_feed = 0.0

    def estop(self) -> None:
        """Estop: disarm with ESTOP_REQUESTED."""
        self._disarm(AxisError.ESTOP_REQUESTED)

    def clear_errors(self) -> None:
        """Clear_Errors: active errors and disarm reason."""
        self._active = self._disarm_reason = AxisError.NONE
        if self._procedure is not ProcedureResult.BUSY:
            self._procedure = ProcedureResult.SUCCESS

    def raise_error(self, error: AxisError) -> None:
        """Fault injection: ``error`` becomes active and disarms a closed-loop axis."""
        self._active |= error
        if self._state is AxisState.CLOSED_LOOP_CONTROL:
            self._disarm(error)

    def _disarm(self, reason: AxisError) -> None:
        self._disarm_reason |= reason
        self._state = AxisState.IDLE
        self._procedure = ProcedureResult.DISARMED

    # --- time ---------------------------------------------------------------------------------
    def step(self, dt: float) -> None:
        """Advance by ``dt`` seconds: watchdog, set-point ramp or coasting, encoder, bus."""
        if not dt >= 0:
            raise ValueError(f"dt: must be >= 0, got {dt}")
        cfg = self.config
        if self._state is AxisState.CLOSED_LOOP_CONTROL and cfg.watchdog_timeout_s > 0:
            self._since_feed += dt
            if self._since_feed > cfg.watchdog_timeout_s + _TIME_EPS_S:
                self._watchdog_trips += 1
                log.warning("watchdog expired: %.3f s without a command", self._since_feed)
                self._disarm(AxisError.WATCHDOG_TIMER_EXPIRED)
        v0 = self._vel
        if self._state is AxisState.CLOSED_LOOP_CONTROL:
            self._pos += self._ramp(dt)
        else:
            decay = math.exp(-dt / cfg.coast_time_constant_s)
            self._pos += v0 * cfg.coast_time_constant_s * (1.0 - decay)
            self._vel = v0 * decay if abs(v0 * decay) > _STOPPED_REV_S else 0.0
            self._setpoint = self._vel
        self._bus_current = self._current(v0, dt)

    def _ramp(self, dt: float) -> float:
        """Move set-point and wheel toward the target; returns the distance covered [rev]."""
        velocity_mode = (self._control_mode is ControlMode.VELOCITY_CONTROL
                         and self._input_mode in (InputMode.VEL_RAMP, InputMode.PASSTHROUGH))
        target = (max(-self._vel_limit, min(self._vel_limit, self._input_vel))
                  if velocity_mode else 0.0)
        v0 = self._setpoint
        if self._input_mode is InputMode.PASSTHROUGH and velocity_mode:
            self._setpoint = self._vel = target
            return target * dt
        rate = self.config.vel_ramp_rate_rev_s2
        t_ramp = min(dt, abs(target - v0) / rate)
        v1 = v0 + math.copysign(rate * t_ramp, target - v0)
        if t_ramp < dt:
            v1 = target
        self._setpoint = self._vel = v1
        return 0.5 * (v0 + v1) * t_ramp + v1 * (dt - t_ramp)

    def _current(self, v0: float, dt: float) -> float:
        if self._state is not AxisState.CLOSED_LOOP_CONTROL:
            return 0.0
        cfg = self.config
        accel = (self._vel - v0) / dt if dt > 0 else 0.0
        drawn = (cfg.idle_current_a + cfg.current_per_accel_a_s2_per_rev * abs(accel)
                 + cfg.current_per_speed_a_s_per_rev * abs(self._vel))
        return min(drawn, self._current_limit)

    def status(self) -> AxisStatus:
        """The axis as its CAN frames report it."""
        return AxisStatus(
            state=self._state, procedure_result=self._procedure, active_errors=self._active,
            disarm_reason=self._disarm_reason, control_mode=self._control_mode,
            input_mode=self._input_mode, vel_limit_rev_s=self._vel_limit,
            current_limit_a=self._current_limit, input_vel_rev_s=self._input_vel,
            vel_setpoint_rev_s=self._setpoint, vel_rev_s=self._vel, pos_rev=self._pos,
            bus_voltage_v=self.config.bus_voltage_v
            - self.config.supply_resistance_ohm * self._bus_current,
            bus_current_a=self._bus_current, watchdog_trips=self._watchdog_trips)
