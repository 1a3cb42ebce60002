"""Zenoh payload layouts: the one place where they are defined.

Every payload is little-endian and starts with the same 16-byte header::

    offset size type  field
    0      1    u8    version      (VERSION = 1)
    1      1    u8    kind         (PayloadKind)
    2      2    u16   robot_id     (0 for the mission)
    4      4    u32   seq          (per publisher, wraps)
    8      8    f64   stamp        [s] UNIX time (hosts keep their clocks in sync, e.g. chrony)

followed by the body of its kind:

* STATE (key ``.../robot/<id>/state``, 36-byte body, 52 bytes in all):
  x, y, theta, v, u, x_d, y_d as f32 [m, m, rad, m/s, rad/s, m, m], mode u8
  (common.vocabulary.Mode), flags u8 (common.vocabulary.StateFlags), then the place
  exchange (agent.exchange.Exchange) as 3 x u16, each value + 1 (0: none, as the reserved
  zero bytes of agents that have no place exchange): slot (the robot's place, an index into
  the mission's members), partner (the robot id it asks or gives to), other (the place
  that goes the other way).
* OBSTACLES (``.../robot/<id>/obstacles``): count u16, then count x (cx, cy, r) f32 [m].
* TRUTH (``.../robot/<id>/truth``, SITL only): x, y, theta, v, u as f64.
* WHEELS (``.../robot/<id>/wheels``, multi-host SITL only): the emulated drivers' wheel
  positions [rev] and actual speeds [rev/s], right then left, 4 x f64, for a world
  simulated on another host.
* FIX (``.../robot/<id>/fix``, 44 bytes in all): a pose fix of one robot from an external
  source (motion capture: ``boundswarm mocap``, or the SITL's simulated one): x, y, theta
  as f64 [m, m, rad] in the world frame, error f32 [m] (the bound on the position's error
  that the source states, > 0); the header's stamp is the capture time, not the send time.
* MISSION (``.../mission``): epoch f64 [s, UNIX time], center0 2 x f64 [m], velocity 2 x f32
  [m/s], omega f32 [rad/s], count u16, then count x (robot_id u16, offset_x f32, offset_y f32).

A payload of the wrong size, version or kind, or with a non-finite number, raises
:class:`PayloadError` (with a short ``reason`` for counters) and must be dropped.
"""
from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import Generic, NamedTuple, TypeVar

import numpy as np

from common.vocabulary import StateFlags

VERSION = 1

HEADER = struct.Struct("<BBHId")
STATE_BODY = struct.Struct("<7fBB3H")
TRUTH_BODY = struct.Struct("<5d")
WHEELS_BODY = struct.Struct("<4d")
FIX_BODY = struct.Struct("<3df")
COUNT = struct.Struct("<H")
CIRCLE = struct.Struct("<3f")
MISSION_BODY = struct.Struct("<d2d2ffH")
MEMBER = struct.Struct("<Hff")


class PayloadKind(enum.IntEnum):
    STATE = 1
    OBSTACLES = 2
    TRUTH = 3
    MISSION = 4
    WHEELS = 5
    FIX = 6


_FLAG_MASK = sum(int(f) for f in StateFlags)
_FLAGS = tuple(StateFlags(bits) for bits in range(_FLAG_MASK + 1))   # decoded flags, built once

M = TypeVar("M")


@dataclass(frozen=True)
class Received(Generic[M]):
    """A decoded message, when the receiver took it (UNIX time [s], receiver's clock) and
    when its Zenoh router timestamped it on the way (UNIX time [s]; None: no router stamp)."""

    msg: M
    received: float
    routed: float | None = None


class PayloadError(ValueError):
    """A payload that must be dropped; ``reason`` is one of size, version, kind, nonfinite."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


class Header(NamedTuple):
    """The common header of every payload (a tuple: built for every message received)."""

    kind: PayloadKind
    robot_id: int
    seq: int
    stamp: float   # s, UNIX time


def _header(data: bytes, kind: PayloadKind) -> Header:
    if len(data) < HEADER.size:
        raise PayloadError("size", f"{len(data)} bytes, shorter than the header")
    version, got, robot_id, seq, stamp = HEADER.unpack_from(data)
    if version != VERSION:
        raise PayloadError("version", f"version {version}, expected {VERSION}")
    if got != kind:
        raise PayloadError("kind", f"kind {got}, expected {int(kind)} ({kind.name})")
    if not math.isfinite(stamp):
        raise PayloadError("nonfinite", "stamp")
    return Header(kind, robot_id, seq, stamp)


def _fixed(data: bytes, kind: PayloadKind, body: struct.Struct, what: str
           ) -> tuple[Header, tuple]:
    """Header and body values of a fixed-size payload, every value finite."""
    h = _header(data, kind)
    _exact(data, HEADER.size + body.size)
    values = body.unpack_from(data, HEADER.size)
    _finite(values, what)
    return h, values


def _pack_header(kind: PayloadKind, robot_id: int, seq: int, stamp: float) -> bytes:
    return HEADER.pack(VERSION, kind, robot_id, seq & 0xFFFFFFFF, stamp)


def _finite(values, what: str) -> None:
    if not all(map(math.isfinite, values)):
        raise PayloadError("nonfinite", what)


def _exact(data: bytes, size: int) -> None:
    if len(data) != size:
        raise PayloadError("size", f"{len(data)} bytes, expected {size}")


@dataclass(frozen=True)
class StateMsg:
    """An agent's own state, published every period for its neighbours."""

    robot_id: int
    seq: int
    stamp: float
    x: float
    y: float
    theta: float
    v: float
    u: float
    x_d: float
    y_d: float
    mode: int
    flags: StateFlags
    slot: int = -1         # its place exchange (agent.exchange.Exchange), -1: none
    partner: int = -1
    other: int = -1

    SIZE = HEADER.size + STATE_BODY.size

    def encode(self) -> bytes:
        for name in ("slot", "partner", "other"):
            if not -1 <= getattr(self, name) < 0xFFFF:
                raise ValueError(f"StateMsg.{name}: {getattr(self, name)} is not in -1..65534")
        return (_pack_header(PayloadKind.STATE, self.robot_id, self.seq, self.stamp)
                + STATE_BODY.pack(self.x, self.y, self.theta, self.v, self.u, self.x_d,
                                  self.y_d, self.mode, int(self.flags), self.slot + 1,
                                  self.partner + 1, self.other + 1))

    @classmethod
    def decode(cls, data: bytes) -> "StateMsg":
        h, (x, y, th, v, u, xd, yd, mode, flags, slot, partner, other) = _fixed(
            data, PayloadKind.STATE, STATE_BODY, "state")
        return cls(h.robot_id, h.seq, h.stamp, x, y, th, v, u, xd, yd, mode,
                   _FLAGS[flags & _FLAG_MASK], slot - 1, partner - 1, other - 1)


@dataclass(frozen=True)
class ObstaclesMsg:
    """Circular obstacles detected around one robot."""

    robot_id: int
    seq: int
    stamp: float
    centers: np.ndarray    # (K, 2) m
    radii: np.ndarray      # (K,) m

    def encode(self) -> bytes:
        k = len(self.radii)
        body = np.column_stack([self.centers, self.radii]).astype("<f4").tobytes() if k else b""
        return (_pack_header(PayloadKind.OBSTACLES, self.robot_id, self.seq, self.stamp)
                + COUNT.pack(k) + body)

    @classmethod
    def decode(cls, data: bytes) -> "ObstaclesMsg":
        h = _header(data, PayloadKind.OBSTACLES)
        if len(data) < HEADER.size + COUNT.size:
            raise PayloadError("size", f"{len(data)} bytes, no obstacle count")
        (k,) = COUNT.unpack_from(data, HEADER.size)
        _exact(data, HEADER.size + COUNT.size + k * CIRCLE.size)
        arr = np.frombuffer(data, dtype="<f4", offset=HEADER.size + COUNT.size).reshape(k, 3)
        arr = arr.astype(float)
        if not np.isfinite(arr).all():
            raise PayloadError("nonfinite", "obstacles")
        if (arr[:, 2] <= 0).any():
            raise PayloadError("nonfinite", "obstacle radius <= 0")
        return cls(h.robot_id, h.seq, h.stamp, arr[:, :2].copy(), arr[:, 2].copy())


@dataclass(frozen=True)
class TruthMsg:
    """Ground-truth pose and velocities of one robot (SITL world only)."""

    robot_id: int
    seq: int
    stamp: float
    x: float
    y: float
    theta: float
    v: float
    u: float

    SIZE = HEADER.size + TRUTH_BODY.size

    def encode(self) -> bytes:
        return (_pack_header(PayloadKind.TRUTH, self.robot_id, self.seq, self.stamp)
                + TRUTH_BODY.pack(self.x, self.y, self.theta, self.v, self.u))

    @classmethod
    def decode(cls, data: bytes) -> "TruthMsg":
        h, values = _fixed(data, PayloadKind.TRUTH, TRUTH_BODY, "truth")
        return cls(h.robot_id, h.seq, h.stamp, *values)


@dataclass(frozen=True)
class WheelsMsg:
    """One robot's emulated wheels (for a world simulated on another host)."""

    robot_id: int
    seq: int
    stamp: float
    right_pos: float  # rev
    left_pos: float   # rev
    right_vel: float  # rev/s
    left_vel: float   # rev/s

    SIZE = HEADER.size + WHEELS_BODY.size

    def encode(self) -> bytes:
        return (_pack_header(PayloadKind.WHEELS, self.robot_id, self.seq, self.stamp)
                + WHEELS_BODY.pack(self.right_pos, self.left_pos, self.right_vel,
                                   self.left_vel))

    @classmethod
    def decode(cls, data: bytes) -> "WheelsMsg":
        h, values = _fixed(data, PayloadKind.WHEELS, WHEELS_BODY, "wheels")
        return cls(h.robot_id, h.seq, h.stamp, *values)


@dataclass(frozen=True)
class FixMsg:
    """A pose fix of one robot from an external source (motion capture), stamped with its
    capture time."""

    robot_id: int
    seq: int
    stamp: float      # s, UNIX time of the capture
    x: float          # m, world frame
    y: float          # m
    theta: float      # rad
    error: float      # m, bound on the position's error the source states

    SIZE = HEADER.size + FIX_BODY.size

    def encode(self) -> bytes:
        return (_pack_header(PayloadKind.FIX, self.robot_id, self.seq, self.stamp)
                + FIX_BODY.pack(self.x, self.y, self.theta, self.error))

    @classmethod
    def decode(cls, data: bytes) -> "FixMsg":
        h, (x, y, theta, error) = _fixed(data, PayloadKind.FIX, FIX_BODY, "fix")
        if error <= 0.0:
            raise PayloadError("nonfinite", f"fix error {error:g} m, must be > 0")
        return cls(h.robot_id, h.seq, h.stamp, x, y, theta, error)


@dataclass(frozen=True)
class MissionMsg:
    """The formation and its start time (the shared epoch) for the whole swarm."""

    seq: int
    stamp: float
    epoch: float                      # s, UNIX time at which t = 0
    center0: tuple[float, float]      # m
    velocity: tuple[float, float]     # m/s
    omega: float                      # rad/s
    ids: np.ndarray                   # (N,) robot ids, formation order
    offsets: np.ndarray               # (N, 2) m

    def encode(self) -> bytes:
        n = len(self.ids)
        members = b"".join(MEMBER.pack(int(i), float(o[0]), float(o[1]))
                           for i, o in zip(self.ids, self.offsets))
        return (_pack_header(PayloadKind.MISSION, 0, self.seq, self.stamp)
                + MISSION_BODY.pack(self.epoch, *self.center0, *self.velocity, self.omega, n)
                + members)

    @classmethod
    def decode(cls, data: bytes) -> "MissionMsg":
        h = _header(data, PayloadKind.MISSION)
        if len(data) < HEADER.size + MISSION_BODY.size:
            raise PayloadError("size", f"{len(data)} bytes, shorter than a mission")
        epoch, cx, cy, vx, vy, omega, n = MISSION_BODY.unpack_from(data, HEADER.size)
        _exact(data, HEADER.size + MISSION_BODY.size + n * MEMBER.size)
        _finite((epoch, cx, cy, vx, vy, omega), "mission")
        members = [MEMBER.unpack_from(data, HEADER.size + MISSION_BODY.size + k * MEMBER.size)
                   for k in range(n)]
        ids = np.array([m[0] for m in members], dtype=int)
        offsets = np.array([m[1:] for m in members], dtype=float).reshape(n, 2)
        _finite(offsets.ravel(), "mission offsets")
        return cls(h.seq, h.stamp, epoch, (cx, cy), (vx, vy), omega, ids, offsets)
