"""Exact bit lengths of classic CAN frames on the wire, and bus load.

A classic data or remote frame with an 11-bit id is SOF, id, RTR, IDE, r0, DLC, data and the
CRC-15, all subject to bit stuffing (after five equal bits the transmitter inserts one of the
opposite level), then the unstuffed CRC delimiter, ACK slot and delimiter, 7-bit EOF and the
3-bit intermission: 47 + 8 * DLC bits before stuffing. Extended (29-bit) ids add the SRR,
IDE and 18 more id bits. The CRC is computed, so the stuffing count is exact.
"""
from __future__ import annotations

from typing import Iterable

import can

TRAILER_BITS = 1 + 2 + 7 + 3     # CRC delimiter, ACK slot + delimiter, EOF, intermission


def _bits(value: int, width: int) -> list[int]:
    return [(value >> (width - 1 - i)) & 1 for i in range(width)]


def crc15(bits: list[int]) -> int:
    """CAN CRC-15 (polynomial 0x4599) of a bit sequence."""
    crc = 0
    for bit in bits:
        nxt = bit ^ ((crc >> 14) & 1)
        crc = (crc << 1) & 0x7FFF
        if nxt:
            crc ^= 0x4599
    return crc


def stuff_count(bits: list[int]) -> int:
    """Number of stuff bits a transmitter inserts into ``bits``."""
    count, run, last = 0, 0, None
    for bit in bits:
        if bit == last:
            run += 1
        else:
            run, last = 1, bit
        if run == 5:
            count += 1
            last = 1 - bit          # the stuff bit starts a new run of the opposite level
            run = 1
    return count


def frame_bits(msg: can.Message) -> int:
    """Bits the frame occupies on the bus, stuffing and intermission included."""
    dlc = msg.dlc
    data = b"" if msg.is_remote_frame else bytes(msg.data)[:8]
    rtr = 1 if msg.is_remote_frame else 0
    if msg.is_extended_id:
        head = ([0] + _bits(msg.arbitration_id >> 18, 11) + [1, 1]
                + _bits(msg.arbitration_id & 0x3FFFF, 18) + [rtr, 0, 0])
    else:
        head = [0] + _bits(msg.arbitration_id, 11) + [rtr, 0, 0]
    body = head + _bits(dlc, 4) + [b for byte in data for b in _bits(byte, 8)]
    stuffed = body + _bits(crc15(body), 15)
    return len(stuffed) + stuff_count(stuffed) + TRAILER_BITS


def bus_load(frames: Iterable[can.Message], seconds: float, bitrate: int = 500_000) -> float:
    """Fraction of the bus's capacity the frames use over ``seconds``."""
    if seconds <= 0 or bitrate <= 0:
        raise ValueError("bus load needs a positive duration and bit rate")
    return sum(frame_bits(m) for m in frames) / (seconds * bitrate)
