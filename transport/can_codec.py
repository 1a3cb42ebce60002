"""ODrive CAN Simple (v0.6 message set) frames <-> typed records, through the project's DBC.

``transport/odrive_cansimple.dbc`` is the one source of truth for frame layouts, units, value
tables and cycle times; cantools packs and unpacks every byte, at both ends of the link (the
host side in :mod:`transport.motor` and the emulated firmware in :mod:`firmware_sim.drivers`).

Wire format: standard 11-bit ids, arbitration id = ``node_id << 5 | cmd_id``, little-endian,
float32. **Node ids:** the DBC lists every message for node 0 (``Axis0_*``) and node 1
(``Axis1_*``) with identical layouts, so ``cantools decode`` reads a capture of a default robot
without options. This module strips the node bits and uses the ``Axis0_*`` layout for any node
id 0..63. For a capture of other node ids, ``cantools decode --frame-id-mask 0x1F`` decodes
every frame (printed under its ``Axis1_*`` name; the node id is the frame id >> 5).

Commands are built as data: a frozen record per message (``SetInputVel(node=1, vel_rev_s=-2.5,
torque_ff_nm=0.25)``), :func:`encode` turns one into a :class:`can.Message` and :func:`decode`
turns a received frame back into a record, a :class:`Request` (RTR) or a :class:`Rejected`
(unknown id, wrong DLC, non-finite number, value outside its table) that callers count.
Pure functions, no I/O; the DBC is parsed once, on first use.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from typing import Callable, ClassVar, Union

import can
import cantools
from cantools.database.can import Database
from cantools.database.can import Message as DbcMessage

DBC_RESOURCE = "odrive_cansimple.dbc"
NODE_SHIFT = 5
CMD_MASK = 0x1F
MAX_NODE = 0x3F                      # 6 node bits in an 11-bit id


class Command(enum.IntEnum):
    """CAN Simple command ids (the low 5 bits of the arbitration id)."""

    HEARTBEAT = 0x001
    ESTOP = 0x002
    GET_ERROR = 0x003
    SET_AXIS_STATE = 0x007
    GET_ENCODER_ESTIMATES = 0x009
    SET_CONTROLLER_MODE = 0x00B
    SET_INPUT_VEL = 0x00D
    SET_LIMITS = 0x00F
    GET_BUS_VOLTAGE_CURRENT = 0x017
    CLEAR_ERRORS = 0x018


class AxisState(enum.IntEnum):
    """ODrive v0.6 ``AxisState`` (DBC value table of Axis_State)."""

    UNDEFINED = 0
    IDLE = 1
    STARTUP_SEQUENCE = 2
    FULL_CALIBRATION_SEQUENCE = 3
    MOTOR_CALIBRATION = 4
    ENCODER_INDEX_SEARCH = 6
    ENCODER_OFFSET_CALIBRATION = 7
    CLOSED_LOOP_CONTROL = 8
    LOCKIN_SPIN = 9
    ENCODER_DIR_FIND = 10
    HOMING = 11
    ENCODER_HALL_POLARITY_CALIBRATION = 12
    ENCODER_HALL_PHASE_CALIBRATION = 13
    ANTICOGGING_CALIBRATION = 14


class AxisError(enum.IntFlag):
    """ODrive v0.6 ``ODrive.Error`` bits (DBC value table of Axis_Error)."""

    NONE = 0
    INITIALIZING = 0x1
    SYSTEM_LEVEL = 0x2
    TIMING_ERROR = 0x4
    MISSING_ESTIMATE = 0x8
    BAD_CONFIG = 0x10
    DRV_FAULT = 0x20
    MISSING_INPUT = 0x40
    DC_BUS_OVER_VOLTAGE = 0x100
    DC_BUS_UNDER_VOLTAGE = 0x200
    DC_BUS_OVER_CURRENT = 0x400
    DC_BUS_OVER_REGEN_CURRENT = 0x800
    CURRENT_LIMIT_VIOLATION = 0x1000
    MOTOR_OVER_TEMP = 0x2000
    INVERTER_OVER_TEMP = 0x4000
    VELOCITY_LIMIT_VIOLATION = 0x8000
    POSITION_LIMIT_VIOLATION = 0x10000
    WATCHDOG_TIMER_EXPIRED = 0x1000000
    ESTOP_REQUESTED = 0x2000000
    SPINOUT_DETECTED = 0x4000000
    BRAKE_RESISTOR_DISARMED = 0x8000000
    THERMISTOR_DISCONNECTED = 0x10000000
    CALIBRATION_ERROR = 0x40000000


class ProcedureResult(enum.IntEnum):
    """ODrive v0.6 ``ProcedureResult`` (DBC value table of Procedure_Result)."""

    SUCCESS = 0
    BUSY = 1
    CANCELLED = 2
    DISARMED = 3
    NO_RESPONSE = 4
    POLE_PAIR_CPR_MISMATCH = 5
    PHASE_RESISTANCE_OUT_OF_RANGE = 6
    PHASE_INDUCTANCE_OUT_OF_RANGE = 7
    UNBALANCED_PHASES = 8
    INVALID_MOTOR_TYPE = 9
    ILLEGAL_HALL_STATE = 10
    TIMEOUT = 11
    HOMING_WITHOUT_ENDSTOP = 12
    INVALID_STATE = 13
    NOT_CALIBRATED = 14
    NOT_CONVERGING = 15


class ControlMode(enum.IntEnum):
    """ODrive ``ControlMode`` (DBC value table of Control_Mode)."""

    VOLTAGE_CONTROL = 0
    TORQUE_CONTROL = 1
    VELOCITY_CONTROL = 2
    POSITION_CONTROL = 3


class InputMode(enum.IntEnum):
    """ODrive ``InputMode`` (DBC value table of Input_Mode)."""

    INACTIVE = 0
    PASSTHROUGH = 1
    VEL_RAMP = 2
    POS_FILTER = 3
    MIX_CHANNELS = 4
    TRAP_TRAJ = 5
    TORQUE_RAMP = 6
    MIRROR = 7
    TUNING = 8


class Rejection(enum.Enum):
    """Why a received frame was not used."""

    UNKNOWN_ID = "unknown_id"        # extended/error/FD frame, or a command id not in the DBC
    WRONG_DLC = "wrong_dlc"          # data length differs from the DBC's
    NON_FINITE = "non_finite"        # a float signal is NaN or infinite
    BAD_VALUE = "bad_value"          # an enum signal outside its value table


def error_names(bits: int) -> tuple[str, ...]:
    """Names of the :class:`AxisError` bits set in ``bits``; unknown bits as one hex string."""
    known = [e for e in AxisError.__members__.values() if e.value]
    names = tuple(e.name for e in known if bits & e.value)
    rest = bits & ~sum(e.value for e in known)
    return names + ((f"0x{rest:x}",) if rest else ())


# --- records: one frozen dataclass per message; fields in SI-ish units named in the field ----

@dataclass(frozen=True)
class Heartbeat:
    """0x001, axis -> host every 100 ms."""

    node: int
    axis_error: AxisError            # active_errors | disarm_reason
    axis_state: AxisState
    procedure_result: ProcedureResult
    trajectory_done: bool
    command: ClassVar[Command] = Command.HEARTBEAT


@dataclass(frozen=True)
class Estop:
    """0x002, host -> axis: disarm with ESTOP_REQUESTED."""

    node: int
    command: ClassVar[Command] = Command.ESTOP


@dataclass(frozen=True)
class ErrorStatus:
    """0x003 Get_Error, axis -> host (answer to an RTR request)."""

    node: int
    active_errors: AxisError
    disarm_reason: AxisError
    command: ClassVar[Command] = Command.GET_ERROR


@dataclass(frozen=True)
class SetAxisState:
    """0x007, host -> axis: request a state (IDLE, CLOSED_LOOP_CONTROL, ...)."""

    node: int
    requested_state: AxisState
    command: ClassVar[Command] = Command.SET_AXIS_STATE


@dataclass(frozen=True)
class EncoderEstimates:
    """0x009 Get_Encoder_Estimates, axis -> host every 10 ms."""

    node: int
    pos_rev: float                   # rev
    vel_rev_s: float                 # rev/s
    command: ClassVar[Command] = Command.GET_ENCODER_ESTIMATES


@dataclass(frozen=True)
class SetControllerMode:
    """0x00B, host -> axis."""

    node: int
    control_mode: ControlMode
    input_mode: InputMode
    command: ClassVar[Command] = Command.SET_CONTROLLER_MODE


@dataclass(frozen=True)
class SetInputVel:
    """0x00D, host -> axis: velocity set-point; also feeds the axis watchdog."""

    node: int
    vel_rev_s: float                 # rev/s
    torque_ff_nm: float              # N m
    command: ClassVar[Command] = Command.SET_INPUT_VEL


@dataclass(frozen=True)
class SetLimits:
    """0x00F, host -> axis."""

    node: int
    vel_limit_rev_s: float           # rev/s
    current_limit_a: float           # A
    command: ClassVar[Command] = Command.SET_LIMITS


@dataclass(frozen=True)
class BusVoltageCurrent:
    """0x017 Get_Bus_Voltage_Current, axis -> host (answer to an RTR request)."""

    node: int
    voltage_v: float                 # V
    current_a: float                 # A, + drawn from the supply
    command: ClassVar[Command] = Command.GET_BUS_VOLTAGE_CURRENT


@dataclass(frozen=True)
class ClearErrors:
    """0x018, host -> axis: clear active errors and disarm_reason."""

    node: int
    command: ClassVar[Command] = Command.CLEAR_ERRORS


@dataclass(frozen=True)
class Request:
    """A remote (RTR) frame: ``node`` is asked to send ``command``'s data frame."""

    node: int
    command: Command


@dataclass(frozen=True)
class Rejected:
    """A received frame that is not used; ``detail`` says why in words (for logs)."""

    reason: Rejection
    arbitration_id: int
    detail: str


Record = Union[Heartbeat, Estop, ErrorStatus, SetAxisState, EncoderEstimates, SetControllerMode,
               SetInputVel, SetLimits, BusVoltageCurrent, ClearErrors]

# record field -> (DBC signal name, wire value -> field value)
_SIGNALS: dict[type, dict[str, tuple[str, Callable]]] = {
    Heartbeat: {"axis_error": ("Axis_Error", AxisError), "axis_state": ("Axis_State", AxisState),
                "procedure_result": ("Procedure_Result", ProcedureResult),
                "trajectory_done": ("Trajectory_Done_Flag", bool)},
    Estop: {},
    ErrorStatus: {"active_errors": ("Active_Errors", AxisError),
                  "disarm_reason": ("Disarm_Reason", AxisError)},
    SetAxisState: {"requested_state": ("Axis_Requested_State", AxisState)},
    EncoderEstimates: {"pos_rev": ("Pos_Estimate", float), "vel_rev_s": ("Vel_Estimate", float)},
    SetControllerMode: {"control_mode": ("Control_Mode", ControlMode),
                        "input_mode": ("Input_Mode", InputMode)},
    SetInputVel: {"vel_rev_s": ("Input_Vel", float), "torque_ff_nm": ("Input_Torque_FF", float)},
    SetLimits: {"vel_limit_rev_s": ("Velocity_Limit", float),
                "current_limit_a": ("Current_Limit", float)},
    BusVoltageCurrent: {"voltage_v": ("Bus_Voltage", float), "current_a": ("Bus_Current", float)},
    ClearErrors: {},
}
_RECORD_OF: dict[Command, type] = {rec.command: rec for rec in _SIGNALS}


@lru_cache(maxsize=1)
def database() -> Database:
    """The project's DBC (package data of ``transport``), parsed on first use."""
    text = resources.files("transport").joinpath(DBC_RESOURCE).read_text(encoding="utf-8")
    return cantools.database.load_string(text, database_format="dbc")


def layout(command: Command) -> DbcMessage:
    """The DBC message of ``command`` (its node-0 entry; every node shares it)."""
    return database().get_message_by_frame_id(int(command))


def cycle_time_s(command: Command) -> float | None:
    """The DBC cycle time (GenMsgCycleTime) of ``command`` [s], None if not cyclic."""
    ms = layout(command).cycle_time
    return ms / 1000.0 if ms else None


def arbitration_id(node: int, command: Command) -> int:
    """``node << 5 | command``; ValueError for a node id outside 0..63."""
    if not 0 <= node <= MAX_NODE:
        raise ValueError(f"node: CAN Simple node ids are 0..{MAX_NODE}, got {node}")
    return node << NODE_SHIFT | int(command)


def encode(record: Record) -> can.Message:
    """The data frame of ``record``; ValueError for a non-finite float or a bad node id."""
    message = layout(record.command)
    signals = {}
    for name, (signal, _) in _SIGNALS[type(record)].items():
        value = getattr(record, name)
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"{name}: {type(record).__name__} needs a finite number, got {value}")
        signals[signal] = int(value) if isinstance(value, (enum.Enum, bool)) else value
    data = message.encode(signals, strict=True) if signals else b""
    return can.Message(arbitration_id=arbitration_id(record.node, record.command), data=data,
                       is_extended_id=False)


def make_request(node: int, command: Command) -> can.Message:
    """A remote (RTR) request for ``command``; the axis answers with the data frame."""
    return can.Message(arbitration_id=arbitration_id(node, command), is_remote_frame=True,
                       dlc=layout(command).length, is_extended_id=False)


def make_set_input_vel(node: int, vel_rev_s: float, torque_ff_nm: float = 0.0) -> can.Message:
    """Set_Input_Vel: velocity set-point [rev/s], torque feed-forward [N m]."""
    return encode(SetInputVel(node, float(vel_rev_s), float(torque_ff_nm)))


def make_set_axis_state(node: int, state: AxisState) -> can.Message:
    """Set_Axis_State: request ``state``."""
    return encode(SetAxisState(node, state))


def make_set_controller_mode(node: int, control_mode: ControlMode,
                             input_mode: InputMode) -> can.Message:
    """Set_Controller_Mode."""
    return encode(SetControllerMode(node, control_mode, input_mode))


def make_set_limits(node: int, vel_limit_rev_s: float, current_limit_a: float) -> can.Message:
    """Set_Limits: velocity limit [rev/s], current limit [A]."""
    return encode(SetLimits(node, float(vel_limit_rev_s), float(current_limit_a)))


def make_estop(node: int) -> can.Message:
    """Estop."""
    return encode(Estop(node))


def make_clear_errors(node: int) -> can.Message:
    """Clear_Errors."""
    return encode(ClearErrors(node))


def decode(msg: can.Message) -> Record | Request | Rejected:
    """A received frame as a record, an RTR :class:`Request`, or :class:`Rejected`."""
    fid = msg.arbitration_id
    if msg.is_extended_id or msg.is_error_frame or msg.is_fd:
        return Rejected(Rejection.UNKNOWN_ID, fid, "not a classic 11-bit data or remote frame")
    node, cmd_id = fid >> NODE_SHIFT, fid & CMD_MASK
    try:
        command = Command(cmd_id)
    except ValueError:
        return Rejected(Rejection.UNKNOWN_ID, fid, f"command 0x{cmd_id:02X} of node {node}")
    if msg.is_remote_frame:
        return Request(node, command)
    message = layout(command)
    if len(msg.data) != message.length:
        return Rejected(Rejection.WRONG_DLC, fid, f"{command.name} of node {node}: "
                        f"{len(msg.data)} bytes, the DBC says {message.length}")
    wire = message.decode(bytes(msg.data), decode_choices=False) if message.signals else {}
    if any(isinstance(v, float) and not math.isfinite(v) for v in wire.values()):
        return Rejected(Rejection.NON_FINITE, fid, f"{command.name} of node {node}: {wire}")
    record_type = _RECORD_OF[command]
    try:
        values = {name: convert(wire[signal])
                  for name, (signal, convert) in _SIGNALS[record_type].items()}
    except ValueError as exc:
        return Rejected(Rejection.BAD_VALUE, fid, f"{command.name} of node {node}: {exc}")
    return record_type(node=node, **values)
