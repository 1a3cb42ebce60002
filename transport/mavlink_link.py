"""One agent as a MAVLink 2 system (sysid = robot id, compid 1) for a ground station.

Theory of operation. The link has no thread: the agent's loop calls :meth:`MavlinkLink.poll`
once per tick, after the tick, with its monotonic time. A poll does a bounded amount of work
and never waits:

1. receive: at most ``MAX_READS`` reads and ``MAX_BYTES`` bytes fed to the parser, at most
   ``MAX_MESSAGES`` messages handled (the rest waits for the next poll);
2. handle: commands, mode requests and parameter writes call the :class:`VehicleControl`
   directly, in the loop's thread, between two ticks, so no lock is needed and a change
   takes effect at the next period; each command is answered by COMMAND_ACK;
3. report: STATUSTEXT on mode changes, failsafes and refusals; the ground-station heartbeat
   failsafe (when enabled);
4. send: at most ``PARAMS_PER_POLL`` queued PARAM_VALUEs and the telemetry streams that are
   due, then flush the transport: what a poll wrote leaves as one UDP datagram. All streams
   fall on the same polls (one in five at 50 Hz), which send one datagram every 0.1 s; the
   polls between only receive. On a machine running many agents a poll's cost is mostly in
   touching the codec at all (cold caches), not in each message, so grouped sends cost less
   than spread ones, and the ground station (or the SITL's router) wakes once per robot and
   0.1 s instead of three to four times.

Why not a thread: in Python it would share the interpreter lock with the loop, so its parsing
and encoding would still delay ticks, only at unpredictable moments; commands would need a
queue, a lock and a way back for their ACK. Polling does the same bounded work at one known
point of the tick (``bench/mavlink_poll.py`` measures a poll's cost).

Telemetry (world frame ENU: x east, y north, theta from +x counter-clockwise; MAVLink local
frame NED: north = y, east = x, down = 0, yaw = pi/2 - theta wrapped to (-pi, pi])::

    HEARTBEAT, SYS_STATUS                     1 Hz
    GPS_GLOBAL_ORIGIN, HOME_POSITION          1 Hz   origin from the settings; home = where
                                                     the robot was at the first poll
    LOCAL_POSITION_NED, ATTITUDE,
    GLOBAL_POSITION_INT                      10 Hz   lat/lon from the origin by a local
                                                     tangent plane (WGS84 radii at the origin)

HEARTBEAT: type GROUND_ROVER, autopilot GENERIC, base_mode CUSTOM_MODE_ENABLED (+ SAFETY_ARMED
when armed), custom_mode :class:`CustomMode` (4 HOLD, also reported while disarmed; 10
FORMATION, shown as AUTO), system_status CRITICAL during a failsafe, else ACTIVE when armed,
STANDBY when not.

Commands (only those whose target_system is this robot; target_component 0 or 1):
COMMAND_LONG/COMMAND_INT MAV_CMD_COMPONENT_ARM_DISARM (param1 1 arm, 0 disarm),
MAV_CMD_DO_SET_MODE (param1 with CUSTOM_MODE_ENABLED, param2 the custom mode), and the SET_MODE
message (acknowledged as MAV_CMD_DO_SET_MODE). Answers: ACCEPTED; DENIED with the reason in a
STATUSTEXT; UNSUPPORTED for any other command. A broadcast (target_system 0) is ignored: one
message must not arm a whole swarm. Parameters: see :mod:`transport.mavlink_params`; reads
accept a broadcast target, writes do not; a write goes to the vehicle's one
``set_param``, which validates it (a refusal keeps the old value and says why).

With signing on (:mod:`transport.mavlink_signing`) every incoming frame must carry a good
signature from the key, on a fresh timestamp; unsigned, wrong-key and replayed frames are
dropped and counted, and outgoing frames are signed. Malformed input is counted, never raised.
"""
from __future__ import annotations

import dataclasses
import enum
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, Protocol

from pymavlink.dialects.v20 import common as mav2

from common.schema import Param
from common.vocabulary import AgentMode
from transport.mavlink_io import Transport, open_transport
from transport.mavlink_params import ParamTable
from transport.mavlink_signing import (
    SignatureCheck,
    Verdict,
    load_signing_key,
    signing_timestamp,
)
from transport.settings import MavlinkSettings

log = logging.getLogger(__name__)

COMPONENT_ID = 1                  # MAV_COMP_ID_AUTOPILOT1
MAX_READS = 16                    # transport reads per poll
MAX_BYTES = 4096                  # bytes handed to the parser per poll
FEED = 280                        # bytes per parser call: one MAVLink 2 frame at most
MAX_MESSAGES = 16                 # messages handled per poll
PARAMS_PER_POLL = 4               # PARAM_VALUEs of a list request sent per poll
STATUSTEXT_LEN = 50               # characters per STATUSTEXT chunk
STATUSTEXT_CHUNKS = 4             # longer texts are cut
ARM_DISARM = mav2.MAV_CMD_COMPONENT_ARM_DISARM
DO_SET_MODE = mav2.MAV_CMD_DO_SET_MODE
_CUSTOM = mav2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
_LOG_LEVEL = {mav2.MAV_SEVERITY_EMERGENCY: logging.CRITICAL,
              mav2.MAV_SEVERITY_ALERT: logging.CRITICAL,
              mav2.MAV_SEVERITY_CRITICAL: logging.CRITICAL,
              mav2.MAV_SEVERITY_ERROR: logging.ERROR, mav2.MAV_SEVERITY_WARNING: logging.WARNING}

# WGS84
_A = 6378137.0                    # m, equatorial radius
_E2 = 6.69437999014e-3            # first eccentricity squared


class CustomMode(enum.IntEnum):
    """HEARTBEAT.custom_mode and the custom mode of DO_SET_MODE / SET_MODE.

    Numbered as ArduPilot's Rover modes, which ground stations apply to any GROUND_ROVER:
    HOLD is HOLD, and FORMATION (the robot follows its mission on its own) shows as AUTO, so
    ``mode HOLD`` / ``mode AUTO`` in MAVProxy or QGroundControl's mode menu work as is."""

    HOLD = 4
    FORMATION = 10


_AGENT_MODE = {CustomMode.HOLD: AgentMode.HOLD, CustomMode.FORMATION: AgentMode.FORMATION}


@dataclass(frozen=True)
class VehicleState:
    """What the link reports, read once per poll."""

    mode: AgentMode
    failsafe: str | None          # reason of the active failsafe
    x: float                      # m, east (world ENU)
    y: float                      # m, north
    theta: float                  # rad, heading from +x (east), counter-clockwise
    v: float                      # m/s, forward speed commanded (after saturation)
    u: float                      # rad/s, turn rate commanded, counter-clockwise
    deadlock: str | None = None   # why the robot is deadlocked (agent.progress), if it is


class VehicleControl(Protocol):
    """What the link needs from the agent; called only from inside :meth:`MavlinkLink.poll`."""

    def state(self) -> VehicleState: ...
    def arm(self) -> str | None: ...                       # reason when refused
    def disarm(self) -> str | None: ...
    def set_mode(self, mode: AgentMode) -> str | None: ...  # HOLD or FORMATION
    def param(self, name: str) -> float: ...                # a parameter's value in force
    def set_param(self, name: str, value: float) -> str | None: ...  # validated; next period


def wrap_pi(angle: float) -> float:
    """``angle`` [rad] wrapped to (-pi, pi]."""
    a = math.remainder(angle, 2.0 * math.pi)
    return math.pi if a == -math.pi else a


def ned_yaw(theta: float) -> float:
    """NED yaw [rad, from north, clockwise] of ENU heading ``theta`` [rad, from east, CCW]."""
    return wrap_pi(math.pi / 2.0 - theta)


def geodetic(origin: tuple[float, float, float], north: float, east: float,
             up: float = 0.0) -> tuple[float, float, float]:
    """(lat [deg], lon [deg], alt [m]) of a point ``north``/``east``/``up`` [m] from ``origin``.

    Local tangent plane: the meridian and prime-vertical radii of WGS84 at the origin;
    within a few kilometres of the origin the error is centimetres."""
    lat0, lon0, alt0 = origin
    phi = math.radians(lat0)
    w = 1.0 - _E2 * math.sin(phi) ** 2
    r_north = _A * (1.0 - _E2) / w ** 1.5 + alt0          # meridian radius
    r_east = (_A / math.sqrt(w) + alt0) * math.cos(phi)   # radius of the parallel
    lat = lat0 + math.degrees(north / r_north)
    lon = (lon0 + math.degrees(east / r_east) + 180.0) % 360.0 - 180.0
    return lat, lon, alt0 + up


@dataclass
class LinkCounters:
    received: int = 0        # messages accepted
    bad_frames: int = 0      # garbage, bad CRC, bad length (pymavlink BAD_DATA)
    unknown: int = 0         # framed, but a message id outside the common dialect
    unsigned: int = 0        # refused while signing is on
    wrong_key: int = 0
    replayed: int = 0        # signed with the key, but an old timestamp
    not_for_us: int = 0      # commands and writes for another system or component, broadcasts
    commands: int = 0        # commands and mode requests answered
    params_set: int = 0
    params_refused: int = 0
    io_errors: int = 0       # transport errors (read or write)


@dataclass
class _Stream:
    period: float            # s
    send: Callable[[int, VehicleState], None]
    k: int = 0               # next occurrence

    def due(self, start: float, now: float) -> bool:
        if now + 1e-6 < start + self.k * self.period:   # 1 us: rounding
            return False
        self.k = max(self.k + 1, math.floor((now - start) / self.period) + 1)
        return True


class MavlinkLink:
    """The MAVLink side of robot ``system_id``, polled by its loop (see the module doc)."""

    def __init__(self, transport: Transport, vehicle: VehicleControl, system_id: int,
                 settings: MavlinkSettings | None = None,
                 signing_key: bytes | None = None,
                 wall: Callable[[], float] | None = None, params: Sequence[Param] = ()):
        if not 1 <= system_id <= 255:
            raise ValueError(f"MAVLink system id must be in 1..255, got {system_id}")
        self.transport, self.vehicle, self.system_id = transport, vehicle, system_id
        self.s = settings if settings is not None else MavlinkSettings()
        self.params = ParamTable(params)
        self.counters = LinkCounters()
        self._tx = mav2.MAVLink(transport, srcSystem=system_id, srcComponent=COMPONENT_ID)
        self._rx = self._parser()
        self._pending = memoryview(b"")
        self._check: SignatureCheck | None = None
        self._wall = wall
        if signing_key is not None:
            if wall is None:
                raise ValueError("MAVLink signing needs the wall clock (wall=...)")
            self._check = SignatureCheck(signing_key)
            self._tx.signing.secret_key = bytes(signing_key)
            self._tx.signing.sign_outgoing = True
            self._tx.signing.timestamp = signing_timestamp(wall())
        self._start: float | None = None
        self._home = (0.0, 0.0)                  # north, east [m]
        self._last: VehicleState | None = None
        self._last_gcs = -math.inf               # s, monotonic
        self._gcs_lost = False
        self._param_queue: list[int] = []
        self._text_id = 0
        self._streams = [                # all due from the first poll on (the module doc)
            _Stream(1.0, self._send_heartbeat),
            _Stream(0.1, self._send_local_position),
            _Stream(0.1, self._send_attitude),
            _Stream(0.1, self._send_global_position),
            _Stream(1.0, self._send_sys_status),
            _Stream(1.0, self._send_origin_and_home),
        ]

    # --- the loop's entry point ---------------------------------------------------------
    def poll(self, now: float) -> None:
        """Receive, handle, report and send, without waiting; ``now`` monotonic [s]."""
        if self._start is None:
            state = self.vehicle.state()
            self._start, self._last_gcs, self._last = now, now, state
            self._home = (state.y, state.x)
        if self._check is not None and self._wall is not None:
            self._tx.signing.timestamp = max(self._tx.signing.timestamp,
                                             signing_timestamp(self._wall()))
        self._receive(now)
        state = self.vehicle.state()
        self._report_changes(state)
        state = self._gcs_failsafe(now, state)
        boot_ms = int((now - self._start) * 1000.0) & 0xFFFFFFFF
        for _ in range(min(PARAMS_PER_POLL, len(self._param_queue))):
            self._send_param(self.params.params[self._param_queue.pop(0)])
        for stream in self._streams:
            if stream.due(self._start, now):
                stream.send(boot_ms, state)
        self._flush()

    @property
    def signing(self) -> bool:
        """Whether frames are signed and incoming ones checked."""
        return self._check is not None

    def close(self) -> None:
        self._flush()
        self.transport.close()

    def counter_summary(self) -> dict:
        """The counters, with the frames the transport dropped and the frames sent."""
        return {**dataclasses.asdict(self.counters), "sent": self._tx.total_packets_sent,
                "send_dropped": self.transport.dropped}

    # --- receive ------------------------------------------------------------------------
    def _parser(self) -> mav2.MAVLink:
        rx = mav2.MAVLink(None, srcSystem=self.system_id, srcComponent=COMPONENT_ID)
        rx.robust_parsing = True                  # garbage becomes BAD_DATA, never raises
        return rx

    def _receive(self, now: float) -> None:
        reads = fed = handled = 0
        while handled < MAX_MESSAGES:
            msg = self._rx.parse_char(b"")
            while msg is None:
                if not self._pending:
                    if reads == MAX_READS:
                        return
                    reads += 1
                    try:
                        self._pending = memoryview(self.transport.recv())
                    except OSError as exc:
                        self._io_error("receive", exc)
                        return
                    if not self._pending:
                        return
                    if self.transport.datagrams and self._rx.buf_len():
                        self.counters.bad_frames += 1     # a frame never spans datagrams
                        self._rx = self._parser()
                if fed >= MAX_BYTES:
                    return
                chunk, self._pending = self._pending[:FEED], self._pending[FEED:]
                fed += len(chunk)
                msg = self._rx.parse_char(chunk)
            handled += 1
            self._accept(msg, now)

    def _accept(self, msg, now: float) -> None:
        msg_id = msg.get_msgId()
        if msg_id == mav2.MAVLINK_MSG_ID_BAD_DATA:
            self.counters.bad_frames += 1
            return
        if msg_id == mav2.MAVLINK_MSG_ID_UNKNOWN:
            self.counters.unknown += 1
            return
        if self._check is not None:
            verdict, stamp = self._check.verify(msg.get_msgbuf(), self._tx.signing.timestamp)
            if verdict is not Verdict.ACCEPTED:
                if verdict is Verdict.UNSIGNED:
                    self.counters.unsigned += 1
                elif verdict is Verdict.WRONG_KEY:
                    self.counters.wrong_key += 1
                else:
                    self.counters.replayed += 1
                log.debug("robot %d: dropped %s from %d/%d: %s", self.system_id,
                          msg.get_type(), msg.get_srcSystem(), msg.get_srcComponent(),
                          verdict.value)
                return
            self._tx.signing.timestamp = max(self._tx.signing.timestamp, stamp)
        self.counters.received += 1
        handler = self._handlers.get(msg_id)
        if handler is not None:
            handler(self, msg, now)

    def _for_us(self, msg, broadcast_ok: bool = False) -> bool:
        ok = ((msg.target_system == self.system_id or (broadcast_ok and msg.target_system == 0))
              and msg.target_component in (0, COMPONENT_ID))
        if not ok:
            self.counters.not_for_us += 1
        return ok

    # --- handlers -----------------------------------------------------------------------
    def _on_heartbeat(self, msg, now: float) -> None:
        if msg.type == mav2.MAV_TYPE_GCS:
            self._last_gcs = now

    def _on_command(self, msg, now: float) -> None:
        if not self._for_us(msg):
            return
        if msg.command == ARM_DISARM:
            if msg.param1 == 1.0:
                reason = self.vehicle.arm()
            elif msg.param1 == 0.0:
                reason = self.vehicle.disarm()
            else:
                reason = f"ARM_DISARM param1 must be 1 (arm) or 0 (disarm), got {msg.param1:g}"
            self._answer(msg, reason)
        elif msg.command == DO_SET_MODE:
            base_mode = int(msg.param1) if math.isfinite(msg.param1) else 0
            self._answer(msg, self._set_mode(base_mode, msg.param2))
        else:
            self.counters.commands += 1
            log.info("robot %d: command %d unsupported", self.system_id, msg.command)
            self._tx.command_ack_send(msg.command, mav2.MAV_RESULT_UNSUPPORTED, 0, 0,
                                      msg.get_srcSystem(), msg.get_srcComponent())

    def _on_set_mode(self, msg, now: float) -> None:
        if msg.target_system != self.system_id:
            self.counters.not_for_us += 1
            return
        reason = self._set_mode(msg.base_mode, msg.custom_mode)
        self._answer(msg, reason, DO_SET_MODE)

    def _set_mode(self, base_mode: int, custom_mode: float) -> str | None:
        if not base_mode & _CUSTOM:
            return "set mode: only custom modes (base_mode with CUSTOM_MODE_ENABLED)"
        try:
            mode = CustomMode(int(custom_mode))
            if mode != custom_mode:
                raise ValueError
        except (ValueError, OverflowError):
            return (f"unknown custom mode {custom_mode:g}: "
                    + ", ".join(f"{m.value} {m.name}" for m in CustomMode))
        if mode is CustomMode.FORMATION and self._gcs_lost:
            return (f"FORMATION refused: no ground-station heartbeat for "
                    f"{self.s.gcs_timeout:g} s")
        return self.vehicle.set_mode(_AGENT_MODE[mode])

    def _answer(self, msg, reason: str | None, command: int | None = None) -> None:
        self.counters.commands += 1
        if reason is not None:
            self._statustext(mav2.MAV_SEVERITY_WARNING, reason)
        self._tx.command_ack_send(msg.command if command is None else command,
                                  mav2.MAV_RESULT_ACCEPTED if reason is None
                                  else mav2.MAV_RESULT_DENIED, 0, 0,
                                  msg.get_srcSystem(), msg.get_srcComponent())

    def _on_param_request_list(self, msg, now: float) -> None:
        if self._for_us(msg, broadcast_ok=True):
            self._param_queue = list(range(len(self.params)))

    def _on_param_request_read(self, msg, now: float) -> None:
        if not self._for_us(msg, broadcast_ok=True):
            return
        spec = self.params.find(msg.param_id, msg.param_index)
        if spec is None:
            log.info("robot %d: no parameter %r (index %d)", self.system_id, msg.param_id,
                     msg.param_index)
        else:
            self._send_param(spec)

    def _on_param_set(self, msg, now: float) -> None:
        if not self._for_us(msg):
            return
        spec = self.params.find(msg.param_id)
        if spec is None:
            self.counters.params_refused += 1
            self._statustext(mav2.MAV_SEVERITY_WARNING, f"no parameter {msg.param_id}")
            return
        refused = self.vehicle.set_param(spec.name, msg.param_value)
        if refused is None:
            self.counters.params_set += 1
        else:
            self.counters.params_refused += 1
            self._statustext(mav2.MAV_SEVERITY_WARNING, refused)
        self._send_param(spec)

    _handlers: ClassVar[dict] = {
        mav2.MAVLINK_MSG_ID_HEARTBEAT: _on_heartbeat,
        mav2.MAVLINK_MSG_ID_COMMAND_LONG: _on_command,
        mav2.MAVLINK_MSG_ID_COMMAND_INT: _on_command,
        mav2.MAVLINK_MSG_ID_SET_MODE: _on_set_mode,
        mav2.MAVLINK_MSG_ID_PARAM_REQUEST_LIST: _on_param_request_list,
        mav2.MAVLINK_MSG_ID_PARAM_REQUEST_READ: _on_param_request_read,
        mav2.MAVLINK_MSG_ID_PARAM_SET: _on_param_set,
    }

    # --- events -------------------------------------------------------------------------
    def _report_changes(self, state: VehicleState) -> None:
        last, self._last = self._last, state
        if last is None:
            return
        if state.mode is not last.mode:
            if state.mode is AgentMode.DISARMED:
                self._statustext(mav2.MAV_SEVERITY_NOTICE, "disarmed")
            elif last.mode is AgentMode.DISARMED:
                self._statustext(mav2.MAV_SEVERITY_NOTICE, f"armed, mode {state.mode.name}")
            else:
                self._statustext(mav2.MAV_SEVERITY_INFO, f"mode {state.mode.name}")
        if state.failsafe != last.failsafe:
            if state.failsafe is None:
                self._statustext(mav2.MAV_SEVERITY_INFO, "failsafe cleared")
            else:
                self._statustext(mav2.MAV_SEVERITY_CRITICAL, f"failsafe: {state.failsafe}")
        if (state.deadlock is None) != (last.deadlock is None):
            if state.deadlock is None:
                self._statustext(mav2.MAV_SEVERITY_INFO, "progressing again")
            else:
                self._statustext(mav2.MAV_SEVERITY_WARNING, f"deadlocked: {state.deadlock}")

    def _gcs_failsafe(self, now: float, state: VehicleState) -> VehicleState:
        """HOLD while no GCS heartbeat for ``gcs_timeout`` (counted from the first poll)."""
        if not self.s.gcs_failsafe:
            return state
        lost = now - self._last_gcs > self.s.gcs_timeout
        if lost != self._gcs_lost:
            self._gcs_lost = lost
            if lost:
                self._statustext(mav2.MAV_SEVERITY_CRITICAL,
                                 f"no GCS heartbeat for {self.s.gcs_timeout:g} s: HOLD")
            else:
                self._statustext(mav2.MAV_SEVERITY_INFO, "GCS heartbeat back")
        if lost and state.mode is AgentMode.FORMATION:
            reason = self.vehicle.set_mode(AgentMode.HOLD)
            if reason is not None:
                log.error("robot %d: GCS failsafe could not HOLD: %s", self.system_id, reason)
            state = self.vehicle.state()
            self._report_changes(state)
        return state

    def _statustext(self, severity: int, text: str) -> None:
        """Log ``text`` and send it, in chunks of 50 characters when longer (MAVLink 2)."""
        log.log(_LOG_LEVEL.get(severity, logging.INFO), "robot %d: %s", self.system_id, text)
        data = text.encode("ascii", "replace")[:STATUSTEXT_LEN * STATUSTEXT_CHUNKS - 1]
        if len(data) <= STATUSTEXT_LEN:
            self._send(self._tx.statustext_encode(severity, data))
            return
        self._text_id = self._text_id % 0xFFFF + 1
        chunks = [data[i:i + STATUSTEXT_LEN] for i in range(0, len(data), STATUSTEXT_LEN)]
        if len(chunks[-1]) == STATUSTEXT_LEN:
            chunks.append(b"")                       # a NUL-only chunk ends the text
        for seq, chunk in enumerate(chunks):
            self._send(self._tx.statustext_encode(severity, chunk, self._text_id, seq))

    # --- send ---------------------------------------------------------------------------
    def _send(self, msg) -> None:
        try:
            self._tx.send(msg)
        except OSError as exc:
            self._io_error("send", exc)

    def _flush(self) -> None:
        try:
            self.transport.flush()
        except OSError as exc:
            self._io_error("send", exc)

    def _io_error(self, what: str, exc: OSError) -> None:
        self.counters.io_errors += 1
        if self.counters.io_errors == 1:
            log.error("robot %d: MAVLink %s failed: %s (further errors only counted)",
                      self.system_id, what, exc)

    def _send_param(self, spec: Param) -> None:
        """PARAM_VALUE of ``spec``: the value in force (after a write, accepted or not)."""
        self._send(self._tx.param_value_encode(
            spec.name.encode("ascii"), self.vehicle.param(spec.name),
            mav2.MAV_PARAM_TYPE_REAL32, len(self.params), spec.index))

    def _send_heartbeat(self, boot_ms: int, st: VehicleState) -> None:
        armed = st.mode is not AgentMode.DISARMED
        custom = CustomMode.FORMATION if st.mode is AgentMode.FORMATION else CustomMode.HOLD
        status = (mav2.MAV_STATE_CRITICAL if st.failsafe is not None
                  else mav2.MAV_STATE_ACTIVE if armed else mav2.MAV_STATE_STANDBY)
        self._send(self._tx.heartbeat_encode(
            mav2.MAV_TYPE_GROUND_ROVER, mav2.MAV_AUTOPILOT_GENERIC,
            _CUSTOM | (mav2.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0), int(custom), status))

    def _send_sys_status(self, boot_ms: int, st: VehicleState) -> None:
        c = self.counters
        errors = c.bad_frames + c.unknown + c.unsigned + c.wrong_key + c.replayed
        self._send(self._tx.sys_status_encode(0, 0, 0, 0, 0xFFFF, -1, -1, 0,
                                              min(errors, 0xFFFF), 0, 0, 0, 0))

    def _send_local_position(self, boot_ms: int, st: VehicleState) -> None:
        self._send(self._tx.local_position_ned_encode(
            boot_ms, st.y, st.x, 0.0,
            st.v * math.sin(st.theta), st.v * math.cos(st.theta), 0.0))

    def _send_attitude(self, boot_ms: int, st: VehicleState) -> None:
        self._send(self._tx.attitude_encode(boot_ms, 0.0, 0.0, ned_yaw(st.theta),
                                            0.0, 0.0, -st.u))

    def _send_global_position(self, boot_ms: int, st: VehicleState) -> None:
        if not all(map(math.isfinite, (st.x, st.y, st.theta, st.v))):
            return                                   # integer fields cannot carry NaN
        lat, lon, alt = geodetic(self.s.origin, st.y, st.x)
        yaw_cdeg = round(math.degrees(ned_yaw(st.theta)) * 100.0) % 36000

        def cm_s(speed: float) -> int:
            return max(-32768, min(32767, round(speed * 100.0)))
        self._send(self._tx.global_position_int_encode(
            boot_ms, round(lat * 1e7), round(lon * 1e7), round(alt * 1000.0), 0,
            cm_s(st.v * math.sin(st.theta)), cm_s(st.v * math.cos(st.theta)), 0, yaw_cdeg))

    def _send_origin_and_home(self, boot_ms: int, st: VehicleState) -> None:
        lat0, lon0, alt0 = self.s.origin
        self._send(self._tx.gps_global_origin_encode(round(lat0 * 1e7), round(lon0 * 1e7),
                                                     round(alt0 * 1000.0)))
        north, east = self._home
        if not (math.isfinite(north) and math.isfinite(east)):
            return
        lat, lon, alt = geodetic(self.s.origin, north, east)
        self._send(self._tx.home_position_encode(
            round(lat * 1e7), round(lon * 1e7), round(alt * 1000.0), north, east, 0.0,
            [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0))


def open_link(settings: MavlinkSettings, vehicle: VehicleControl, system_id: int,
              monotonic: Callable[[], float], wall: Callable[[], float],
              base: Path | None = None, params: Sequence[Param] = ()) -> MavlinkLink:
    """Open the transport of ``settings.url`` and load the signing key, if any.

    ``monotonic`` [s] paces TCP reconnects, ``wall`` [s, UNIX] sets signing timestamps; a
    relative key file is taken from ``base`` (the agent config's folder); ``params`` is the
    parameter table served (transport.mavlink_params)."""
    key = None
    if settings.signing_key_file is not None:
        path = Path(settings.signing_key_file)
        key = load_signing_key(base / path if base is not None and not path.is_absolute()
                               else path)
    transport = open_transport(settings.url, monotonic)
    return MavlinkLink(transport, vehicle, system_id, settings, key, wall, params)
