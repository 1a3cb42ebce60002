"""Emulated ODrive (v0.6 CAN Simple) wheel drivers: the firmware contract, on a CAN bus.

:class:`EmulatedAxis` is the pure firmware model of one axis (no I/O, time passed in):

* states IDLE and CLOSED_LOOP_CONTROL; a request for closed loop is refused (the axis stays
  IDLE) while an error is active; motion only in CLOSED_LOOP_CONTROL;
* velocity control with VEL_RAMP: the set-point is clamped to vel_limit and the velocity
  follows it at ``ramp`` rev/s^2; other control/input modes are accepted but not emulated
  (the axis holds zero velocity);
* watchdog as the firmware's (``axis.config.enable_watchdog``, ``watchdog_timeout``): fed by
  every frame addressed to the axis' node (CAN Simple feeds it before handling any command,
  requests included) and on entering closed loop; not fed for ``watchdog_timeout`` s in
  closed loop -> WATCHDOG_TIMER_EXPIRED and IDLE (the firmware also latches the error in
  IDLE; here it expires only in closed loop, where it stops a wheel); Estop ->
  ESTOP_REQUESTED and IDLE; in IDLE the wheel coasts down (first order, ``coast_tau``);
  Clear_Errors clears the errors;
* the encoder position counts the wheel's actual turns: the speed reached at each step's
  end, held over the step, the very turns the plant moves the robot by (a step-mean rule
  would differ from them by half of each step's speed change times that step's length, a
  sum that random step lengths turn into a heading drift); bus voltage and a current that
  grows with acceleration and speed.

:class:`DriverPair` serves the axes of one robot on its bus: commands in, Heartbeat (100 ms)
and Get_Encoder_Estimates (10 ms) out, remote requests answered; frames read as firmware reads
them (the bytes their signals need, :func:`transport.odrive_frames.decode`), malformed ones
ignored and counted. Fault injection: silence a node, drop or delay a fraction of the frames it
sends (seeded RNG), raise an error bit. An imperfect world (docs/world.md) adds Gaussian
noise to the positions the encoder estimates report (``encoder_noise``), never to the axis.

Frames in go through :func:`transport.odrive_frames.decode`; frames out through its
:func:`encode`, except the encoder estimates (the steady flow out), packed directly with their
DBC-checked struct.
"""
from __future__ import annotations

import heapq
import logging
import math
import random
from collections import Counter, deque
from dataclasses import dataclass, field
from functools import lru_cache

import can

from common import drivers
from common.draws import ENCODER, normal
from transport.odrive_frames import (
    ENCODER_ESTIMATES,
    AxisError,
    AxisState,
    Cmd,
    ControlMode,
    Frame,
    FrameError,
    InputMode,
    arbitration_id,
    decode,
    encode,
)

log = logging.getLogger(__name__)


@lru_cache(maxsize=256)
def _heartbeat_data(node: int, error: int, state: int) -> bytes:
    """A heartbeat's data bytes (they change only with the axis' error bits and state)."""
    return bytes(encode(node, Cmd.HEARTBEAT, Axis_Error=error, Axis_State=state,
                        Procedure_Result=0, Trajectory_Done_Flag=0).data)


@dataclass
class EmulatedAxis:
    """One axis of emulated firmware; all times in seconds, speeds in rev/s."""

    vel_limit: float = drivers.SPEED_LIMIT   # rev/s
    ramp: float = drivers.RAMP               # rev/s^2
    enable_watchdog: bool = True
    watchdog_timeout: float = drivers.WATCHDOG   # s
    coast_tau: float = 0.3           # s, spin-down time constant when IDLE
    bus_voltage: float = 24.0        # V
    state: int = AxisState.IDLE      # an AxisState member
    error: int = 0                   # AxisError bits
    control_mode: int = ControlMode.VELOCITY_CONTROL
    input_mode: int = InputMode.VEL_RAMP
    setpoint: float = 0.0            # rev/s, after the clamp
    vel: float = 0.0                 # rev/s, actual
    pos: float = 0.0                 # rev
    current: float = 0.0             # A
    watchdog_trips: int = 0
    _since_feed: float = 0.0         # s since the watchdog was last fed

    def feed_watchdog(self) -> None:
        self._since_feed = 0.0

    def request_state(self, requested: int) -> None:
        if requested == AxisState.CLOSED_LOOP_CONTROL:
            if self.error:
                log.info("closed loop refused: error %s", AxisError(self.error))
                return
            self.state = AxisState.CLOSED_LOOP_CONTROL    # keeps input_vel, as firmware does
            self.feed_watchdog()
        elif requested == AxisState.IDLE:
            self.state = AxisState.IDLE

    def input_vel(self, vel: float) -> None:
        self.setpoint = max(-self.vel_limit, min(self.vel_limit, vel))

    def set_limits(self, vel_limit: float, current_limit: float) -> None:
        if vel_limit > 0 and math.isfinite(vel_limit):
            self.vel_limit = vel_limit
            self.setpoint = max(-vel_limit, min(vel_limit, self.setpoint))

    def estop(self) -> None:
        self.error |= AxisError.ESTOP_REQUESTED
        self.state = AxisState.IDLE

    def clear_errors(self) -> None:
        self.error = 0

    def step(self, dt: float) -> None:
        """Advance the axis by ``dt``: watchdog, ramp or coast, encoder."""
        before = vel = self.vel
        closed = self.state == AxisState.CLOSED_LOOP_CONTROL
        if closed:
            self._since_feed += dt
            if self.enable_watchdog and self._since_feed > self.watchdog_timeout + 1e-9:
                self.error |= AxisError.WATCHDOG_TIMER_EXPIRED
                self.state = AxisState.IDLE
                closed = False
                self.watchdog_trips += 1
                log.warning("watchdog expired after %.3f s without a command",
                            self._since_feed)
        if closed:
            target = self.setpoint if (self.control_mode == ControlMode.VELOCITY_CONTROL
                                       and self.input_mode == InputMode.VEL_RAMP) else 0.0
            step = self.ramp * dt
            vel += max(-step, min(step, target - vel))
        else:
            vel *= math.exp(-dt / self.coast_tau)
            if abs(vel) < 1e-4:
                vel = 0.0
        self.vel = vel
        self.pos += vel * dt
        accel = (vel - before) / dt if dt > 0 else 0.0
        self.current = 0.05 * abs(accel) + 0.02 * abs(vel) + (0.1 if closed else 0.0)


@dataclass
class Faults:
    """Injected faults of one node."""

    silent: bool = False             # sends nothing
    drop: float = 0.0                # fraction of its frames dropped
    delay: float = 0.0               # s, its frames are sent this late


@dataclass
class DriverPair:
    """The emulated drivers of one robot: nodes ``left_node`` and ``right_node`` on ``bus``."""

    bus: can.BusABC
    left_node: int = drivers.LEFT_NODE
    right_node: int = drivers.RIGHT_NODE
    heartbeat_period: float = 0.1
    encoder_period: float = 0.01
    axes: dict = field(default_factory=dict)
    faults: dict = field(default_factory=dict)
    rng: random.Random = field(default_factory=lambda: random.Random(0))
    ignored: Counter = field(default_factory=Counter)
    sent: int = 0
    latency: float = 0.0      # s, from a velocity command's arrival to the axis applying it
    # rev, standard deviation of the noise on each reported encoder position: draw k of the
    # right (0) or left (1) wheel is common.draws.normal(noise_seed, ENCODER, noise_key,
    # wheel, k); noise_key is the robot's index in its scenario
    encoder_noise: float = 0.0
    noise_seed: int = 0
    noise_key: int = 0
    _reports: Counter = field(default_factory=Counter)   # node -> encoder estimates made
    _due: dict = field(default_factory=dict)     # node -> [heartbeat, encoder] next due [s]
    _commands: deque = field(default_factory=deque)   # (due [s], axis, Input_Vel [rev/s])
    _queue: list = field(default_factory=list)
    _now: float = 0.0

    def __post_init__(self) -> None:
        for node in (self.right_node, self.left_node):
            self.axes.setdefault(node, EmulatedAxis())
            self.faults.setdefault(node, Faults())

    def configure(self, **axis_settings) -> None:
        """Set emulation parameters on both axes (vel_limit, ramp, enable_watchdog,
        watchdog_timeout, ...)."""
        for axis in self.axes.values():
            for key, value in axis_settings.items():
                setattr(axis, key, value)

    # --- CAN side ---------------------------------------------------------------------------
    def fileno(self) -> int | None:
        """The bus's file descriptor to wait on (None: the bus has none, e.g. virtual)."""
        try:
            fd = self.bus.fileno()
        except NotImplementedError:
            return None
        return fd if fd >= 0 else None

    def service(self, now: float, receive: bool = True) -> None:
        """Handle every frame waiting on the bus (unless ``receive`` is False: the caller
        knows none is), then send what is due at ``now`` [s]."""
        self._now = now
        while receive and (msg := self.bus.recv(0.0)) is not None:
            self._receive(msg)
        while self._commands and self._commands[0][0] <= now:
            _, axis, vel = self._commands.popleft()
            axis.input_vel(vel)
        for node, axis in self.axes.items():
            due = self._due.get(node)
            if due is None:
                due = self._due[node] = [now, now]
            if now >= due[0]:
                due[0] = max(due[0] + self.heartbeat_period, now)
                self._emit(node, self._heartbeat(node, axis))
            if now >= due[1]:
                due[1] = max(due[1] + self.encoder_period, now)
                self._emit(node, self._encoder_estimates(node, axis))
        while self._queue and self._queue[0][0] <= now:
            _, _, msg = heapq.heappop(self._queue)
            self._send(msg)

    def _receive(self, msg: can.Message) -> None:
        """Handle one received frame (frames to ignore counted). Any standard frame to an
        axis' node feeds its watchdog, as CAN Simple does before looking at the command."""
        if not (msg.is_extended_id or msg.is_error_frame):
            axis = self.axes.get(msg.arbitration_id >> 5)
            if axis is not None:
                axis.feed_watchdog()
        try:
            frame = decode(msg)
        except FrameError as exc:
            self.ignored[exc.reason] += 1
            return
        self._handle(frame)

    @staticmethod
    def _heartbeat(node: int, axis: EmulatedAxis) -> can.Message:
        return can.Message(arbitration_id=arbitration_id(node, Cmd.HEARTBEAT),
                           data=_heartbeat_data(node, int(axis.error), int(axis.state)),
                           is_extended_id=False)

    def _encoder_estimates(self, node: int, axis: EmulatedAxis) -> can.Message:
        """The axis' encoder estimates: its position [rev] (plus noise in an imperfect
        world) and speed [rev/s]."""
        pos = axis.pos
        if self.encoder_noise > 0.0:
            k = self._reports[node]
            self._reports[node] = k + 1
            wheel = 0 if node == self.right_node else 1
            pos += self.encoder_noise * normal(self.noise_seed, ENCODER, self.noise_key,
                                               wheel, k)
        return can.Message(arbitration_id=arbitration_id(node, Cmd.GET_ENCODER_ESTIMATES),
                           data=ENCODER_ESTIMATES.pack(pos, axis.vel), is_extended_id=False)

    def _emit(self, node: int, msg: can.Message) -> None:
        f = self.faults[node]
        if f.silent or (f.drop and self.rng.random() < f.drop):
            return
        if f.delay > 0:
            heapq.heappush(self._queue, (self._now + f.delay, self.sent + len(self._queue), msg))
        else:
            self._send(msg)

    def _send(self, msg: can.Message) -> None:
        try:
            self.bus.send(msg)
            self.sent += 1
        except can.CanError as exc:
            log.warning("emulated driver could not send: %s", exc)

    def _handle(self, frame: Frame) -> None:
        axis = self.axes.get(frame.node)
        if axis is None:
            return                                    # another node on the bus
        if frame.rtr:
            self._answer(frame.node, frame.cmd, axis)
            return
        s = frame.signals
        if frame.cmd == Cmd.SET_INPUT_VEL:
            if self.latency > 0.0:         # the drive latency of the robot's profile
                self._commands.append((self._now + self.latency, axis, s["Input_Vel"]))
            else:
                axis.input_vel(s["Input_Vel"])
        elif frame.cmd == Cmd.SET_AXIS_STATE:
            axis.request_state(int(s["Axis_Requested_State"]))
        elif frame.cmd == Cmd.SET_CONTROLLER_MODE:
            axis.control_mode, axis.input_mode = int(s["Control_Mode"]), int(s["Input_Mode"])
        elif frame.cmd == Cmd.SET_LIMITS:
            axis.set_limits(s["Velocity_Limit"], s["Current_Limit"])
        elif frame.cmd == Cmd.ESTOP:
            axis.estop()
        elif frame.cmd == Cmd.CLEAR_ERRORS:
            axis.clear_errors()
        # data frames of what drivers send (heartbeats of a neighbour node...) are not ours

    def _answer(self, node: int, cmd: Cmd, axis: EmulatedAxis) -> None:
        if cmd == Cmd.GET_ENCODER_ESTIMATES:
            reply = self._encoder_estimates(node, axis)
        elif cmd == Cmd.GET_BUS_VOLTAGE_CURRENT:
            reply = encode(node, cmd, Bus_Voltage=axis.bus_voltage, Bus_Current=axis.current)
        elif cmd == Cmd.GET_ERROR:
            reply = encode(node, cmd, Active_Errors=int(axis.error), Disarm_Reason=int(axis.error))
        elif cmd == Cmd.HEARTBEAT:
            reply = self._heartbeat(node, axis)
        else:
            self.ignored["rtr_unsupported"] += 1
            return
        self._emit(node, reply)

    # --- physics side -------------------------------------------------------------------------
    def step(self, dt: float) -> None:
        for axis in self.axes.values():
            axis.step(dt)

    def wheel_state(self) -> tuple[float, float, float, float]:
        """(right, left) wheel positions [rev] and actual speeds [rev/s]: the true turns, with
        no encoder noise."""
        r, l_ = self.axes[self.right_node], self.axes[self.left_node]
        return r.pos, l_.pos, r.vel, l_.vel

    def close(self) -> None:
        self.bus.shutdown()
