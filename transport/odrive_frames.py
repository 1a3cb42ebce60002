"""ODrive CAN Simple (v0.6) frames, encoded and decoded from the project's DBC by cantools.

The DBC (``transport/odrive.dbc``) is the one source of truth for layouts, units, value
tables and cycle times; this module builds python-can messages from it and decodes them, at
both ends (the agent's host side and the emulated firmware). cantools encodes and decodes
every frame but the two of the steady flow (Get_Encoder_Estimates and Set_Input_Vel): those
are packed and unpacked with a ``struct`` built from their DBC layout and checked against it
at import, so their layout still comes from the DBC alone.

Node ids: arbitration id = node_id << 5 | cmd_id. The DBC lists every message for nodes 0
and 1 (so ``cantools decode`` reads a capture of a default robot); this module uses the
node-0 layouts for any node id 0..63 by masking the node bits.

Lengths: frames are sent with the DBC's length (that of ODrive's official DBC). A received
frame is read as real firmware reads it: it must carry the bytes its signals need
(:func:`needed_bytes`; a signal the DBC marks ``SigOptional``, such as Clear_Errors'
Identify, may be left off and reads as 0), and bytes past those are ignored.
"""
from __future__ import annotations

import enum
import math
import struct
from collections import Counter
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from typing import Any, Iterator, NamedTuple

import can
import cantools

MAX_NODE = 63


class Cmd(enum.IntEnum):
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


@lru_cache(maxsize=1)
def database() -> cantools.database.can.Database:
    """The project's DBC, loaded once."""
    text = resources.files("transport").joinpath("odrive.dbc").read_text()
    db = cantools.database.load_string(text, database_format="dbc")
    if not isinstance(db, cantools.database.can.Database):     # load_string may load others
        raise TypeError(f"odrive.dbc loaded as {type(db).__name__}, not a CAN database")
    return db


@lru_cache(maxsize=None)
def _layout(cmd: Cmd) -> cantools.database.can.Message:
    """``cmd``'s message in the DBC (looked up once: this runs for every frame)."""
    return database().get_message_by_frame_id(int(cmd))


_CMDS = {int(c): c for c in Cmd}


def float32_layout(cmd: Cmd, *names: str) -> struct.Struct:
    """A struct packing ``cmd``'s signals ``names`` (in this order) exactly as the DBC lays
    them out; ValueError unless they are all its signals, each an unscaled little-endian
    float32, one after the other from bit 0."""
    layout = _layout(cmd)
    for i, name in enumerate(names):
        s = layout.get_signal_by_name(name)
        if not (s.is_float and s.length == 32 and s.byte_order == "little_endian"
                and s.start == 32 * i and s.scale == 1 and s.offset == 0):
            raise ValueError(f"{layout.name}.{name} is not float32 number {i} of the frame")
    if len(layout.signals) != len(names) or layout.length != 4 * len(names):
        raise ValueError(f"{layout.name} has other signals or bytes than {names}")
    return struct.Struct("<" + "f" * len(names))


CLASSIC_CAN_BYTES = 8     # most data bytes of a classic CAN frame


def _optional(signal: cantools.database.can.Signal) -> bool:
    """The DBC marks the signal optional (SigOptional = 1): a frame may leave it off."""
    attr = signal.dbc.attributes.get("SigOptional") if signal.dbc is not None else None
    return attr is not None and attr.value == 1


@lru_cache(maxsize=None)
def needed_bytes(cmd: Cmd) -> int:
    """The data bytes a frame of ``cmd`` must carry: up to the last byte of its last
    signal that is not optional (0 for a frame without one, e.g. Estop, Clear_Errors)."""
    ends = []
    for s in _layout(cmd).signals:
        if s.byte_order != "little_endian":       # the end below holds for these only
            raise ValueError(f"{_layout(cmd).name}.{s.name} is not little-endian")
        if not _optional(s):
            ends.append((s.start + s.length + 7) // 8)
    return max(ends, default=0)


class FloatFrame(NamedTuple):
    """A frame of float32 signals only, packed by a struct checked against the DBC."""

    packer: struct.Struct
    names: tuple[str, ...]
    limits: tuple[tuple[float, float], ...]     # DBC (minimum, maximum) of each signal

    @classmethod
    def of(cls, cmd: Cmd, *names: str) -> "FloatFrame":
        signals = [_layout(cmd).get_signal_by_name(n) for n in names]
        limits = []
        for s in signals:
            if s.minimum is None or s.maximum is None:
                raise ValueError(f"{_layout(cmd).name}.{s.name} has no DBC limits")
            limits.append((s.minimum, s.maximum))
        return cls(float32_layout(cmd, *names), names, tuple(limits))


# The steady flow (about 100 frames per second per axis each way) packed by a struct checked
# against the DBC at import: the same bytes as cantools, for a fraction of its cost.
FLOAT_FRAMES = {Cmd.GET_ENCODER_ESTIMATES: FloatFrame.of(Cmd.GET_ENCODER_ESTIMATES,
                                                         "Pos_Estimate", "Vel_Estimate"),
                Cmd.SET_INPUT_VEL: FloatFrame.of(Cmd.SET_INPUT_VEL, "Input_Vel",
                                                 "Input_Torque_FF")}
ENCODER_ESTIMATES = FLOAT_FRAMES[Cmd.GET_ENCODER_ESTIMATES].packer
INPUT_VEL = FLOAT_FRAMES[Cmd.SET_INPUT_VEL].packer


def _choices(message: str, signal: str) -> dict[int, str]:
    sig = database().get_message_by_name(f"Axis0_{message}").get_signal_by_name(signal)
    if sig.choices is None:
        raise ValueError(f"Axis0_{message}.{signal} has no value table in the DBC")
    return {int(k): str(v) for k, v in sig.choices.items()}


def _dbc_enum(kind: enum.EnumMeta, name: str, table: dict[int, str]) -> Any:
    """The enum ``name`` of kind ``kind`` with a member per entry of a DBC value table.

    The ODrive enums below are built at run time from the DBC's value tables: the DBC is
    their one source of truth, and a hand-written copy for the type checker would be a
    second one to keep in step. mypy cannot know the members of an enum built from a
    computed table (and rejects a direct ``IntEnum(name, table)`` call), so this returns Any:
    member access such as ``AxisState.IDLE`` is not checked by mypy; a misspelt member
    raises AttributeError when the code using it runs."""
    return kind(name, {v: k for k, v in table.items()})


AxisState = _dbc_enum(enum.IntEnum, "AxisState", _choices("Heartbeat", "Axis_State"))
AxisState.__doc__ = "ODrive axis states (from the DBC value table)."
AxisError = _dbc_enum(enum.IntFlag, "AxisError",
                      {k: v for k, v in _choices("Heartbeat", "Axis_Error").items() if k})
AxisError.__doc__ = "ODrive axis error bits (from the DBC value table)."
ControlMode = _dbc_enum(enum.IntEnum, "ControlMode",
                        _choices("Set_Controller_Mode", "Control_Mode"))
InputMode = _dbc_enum(enum.IntEnum, "InputMode", _choices("Set_Controller_Mode", "Input_Mode"))


_ERRORS = tuple(sorted(AxisError, key=lambda e: e.value))
_KNOWN_ERRORS = sum(e.value for e in AxisError)


@lru_cache(maxsize=64)
def error_names(bits: int) -> tuple[str, ...]:
    """Names of the error bits set in ``bits`` (unknown bits as hex)."""
    names = tuple(e.name for e in _ERRORS if bits & e.value)
    rest = bits & ~_KNOWN_ERRORS
    return names + ((f"0x{rest:x}",) if rest else ())


def arbitration_id(node: int, cmd: Cmd) -> int:
    if not 0 <= node <= MAX_NODE:
        raise ValueError(f"ODrive node id must be 0..{MAX_NODE}, got {node}")
    return node << 5 | int(cmd)


class FrameError(ValueError):
    """A frame to ignore; ``reason``: unknown_id, dlc (fewer bytes than its signals need,
    or more than a classic CAN frame has) or nonfinite."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


@dataclass(frozen=True)
class Frame:
    """A decoded frame: node, command, raw signal values (numbers), remote request?"""

    node: int
    cmd: Cmd
    signals: dict
    rtr: bool = False


def encode(node: int, cmd: Cmd, **signals: float) -> can.Message:
    """A data frame of ``cmd`` for ``node`` with the given signal values."""
    fast = FLOAT_FRAMES.get(cmd)
    if fast is not None and signals.keys() == set(fast.names) and _within(signals, fast):
        data = fast.packer.pack(*(signals[name] for name in fast.names))
    else:                       # cantools, also for the errors: EncodeError names the signal
        layout = _layout(cmd)
        data = layout.encode(signals, strict=True) if layout.signals else b""
    return can.Message(arbitration_id=arbitration_id(node, cmd), data=data,
                       is_extended_id=False)


def _within(signals: dict, fast: FloatFrame) -> bool:
    """Every value a number within its signal's DBC limits (NaN is not)."""
    try:
        return all(lo <= signals[n] <= hi for n, (lo, hi) in zip(fast.names, fast.limits))
    except TypeError:                                   # not a number
        return False


def request(node: int, cmd: Cmd) -> can.Message:
    """A remote (RTR) request for ``cmd``: the drivers answer with the data frame."""
    return can.Message(arbitration_id=arbitration_id(node, cmd), is_remote_frame=True,
                       dlc=_layout(cmd).length, is_extended_id=False)


def decode(msg: can.Message) -> Frame:
    """Decode a received frame; raises :class:`FrameError` for one to ignore."""
    if msg.is_extended_id or msg.is_error_frame or msg.arbitration_id > 0x7FF:
        raise FrameError("unknown_id", f"0x{msg.arbitration_id:x} is not an 11-bit ODrive id")
    node, cmd_id = msg.arbitration_id >> 5, msg.arbitration_id & 0x1F
    cmd = _CMDS.get(cmd_id)
    if cmd is None:
        raise FrameError("unknown_id", f"command 0x{cmd_id:02x} of node {node}")
    layout = _layout(cmd)
    if msg.is_remote_frame:
        return Frame(node, cmd, {}, rtr=True)
    size = len(msg.data)
    if not needed_bytes(cmd) <= size <= CLASSIC_CAN_BYTES:
        raise FrameError("dlc", f"{cmd.name} of node {node}: {size} bytes, expected "
                                f"{needed_bytes(cmd)} to {CLASSIC_CAN_BYTES}")
    fast = FLOAT_FRAMES.get(cmd)
    if fast is not None:
        values = fast.packer.unpack_from(msg.data)
        signals = dict(zip(fast.names, values))
        finite = all(map(math.isfinite, values))
    else:      # the bytes the layout has: optional ones left off read as 0, extra ignored
        data = bytes(msg.data[:layout.length]).ljust(layout.length, b"\0")
        decoded = (layout.decode(data, decode_choices=False, scaling=False)
                   if layout.signals else {})
        if not isinstance(decoded, dict):   # a list only for container messages: none here
            raise TypeError(f"{layout.name} decoded as a container message")
        signals = decoded
        finite = all(math.isfinite(v) for v in signals.values() if isinstance(v, float))
    if not finite:
        raise FrameError("nonfinite", f"{cmd.name} of node {node}: {signals}")
    return Frame(node, cmd, signals)


def message_name(cmd: Cmd) -> str:
    """The DBC's name of a message without its node prefix, e.g. ``Get_Encoder_Estimates``."""
    return _layout(cmd).name.split("_", 1)[1]


def receive(bus: can.BusABC, rejected: Counter) -> Iterator[Frame]:
    """The decoded frames waiting on ``bus`` (never blocks); frames to ignore are counted
    in ``rejected`` by reason."""
    while (msg := bus.recv(0.0)) is not None:
        try:
            yield decode(msg)
        except FrameError as exc:
            rejected[exc.reason] += 1


def cycle_time(cmd: Cmd) -> float | None:
    """The DBC cycle time [s] of a cyclic message, or None."""
    ms = _layout(cmd).cycle_time
    return ms / 1000.0 if ms else None
