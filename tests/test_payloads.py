import math
import struct

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from common.payloads import (
    HEADER,
    FixMsg,
    MissionMsg,
    ObstaclesMsg,
    PayloadError,
    StateMsg,
    TruthMsg,
)
from common.vocabulary import StateFlags

STATE = StateMsg(robot_id=3, seq=7, stamp=1_700_000_000.25, x=1.5, y=-2.0, theta=0.5,
                 v=1.0, u=-0.25, x_d=4.0, y_d=-8.0, mode=2, flags=StateFlags.ARMED)


def test_state_golden_bytes():
    data = STATE.encode()
    assert len(data) == StateMsg.SIZE == 52
    assert data[:16] == bytes([1, 1, 3, 0, 7, 0, 0, 0]) + struct.pack("<d", 1_700_000_000.25)
    assert data[16:20] == bytes.fromhex("0000c03f")          # 1.5 as f32 LE
    assert data[44:46] == bytes([2, 1]) and data[46:] == bytes(6)    # no place exchange
    assert StateMsg.decode(data) == STATE


def test_state_carries_the_place_exchange():
    """slot, partner and other as u16, each + 1; zero bytes (an agent without them) read
    as -1, none."""
    msg = StateMsg(**{**STATE.__dict__, "slot": 0, "partner": 12, "other": 65534})
    data = msg.encode()
    assert data[46:] == struct.pack("<3H", 1, 13, 65535)
    assert StateMsg.decode(data) == msg
    with pytest.raises(ValueError, match="StateMsg.slot: 65535"):
        StateMsg(**{**STATE.__dict__, "slot": 65535}).encode()


@pytest.mark.parametrize("flags", [StateFlags(0), StateFlags.GOVERNED,
                                   StateFlags.ARMED | StateFlags.FAILSAFE | StateFlags.GOVERNED])
def test_every_state_flag_survives_the_wire(flags):
    msg = StateMsg(**{**STATE.__dict__, "flags": flags})
    assert StateMsg.decode(msg.encode()).flags == flags


@pytest.mark.parametrize("mutate, reason", [
    (lambda d: d[:-1], "size"),
    (lambda d: d + b"\0", "size"),
    (lambda d: b"\x02" + d[1:], "version"),
    (lambda d: d[:1] + b"\x03" + d[2:], "kind"),
    (lambda d: d[:16] + struct.pack("<f", math.nan) + d[20:], "nonfinite"),
    (lambda d: d[:8] + struct.pack("<d", math.inf) + d[16:], "nonfinite"),
    (lambda d: d[:5], "size"),
])
def test_malformed_state_is_refused_with_a_reason(mutate, reason):
    with pytest.raises(PayloadError) as exc:
        StateMsg.decode(mutate(STATE.encode()))
    assert exc.value.reason == reason


def test_obstacles_round_trip_and_bad_sizes():
    msg = ObstaclesMsg(2, 1, 10.0, np.array([[0.0, -20.0], [15.0, -5.0]]), np.array([3.0, 4.0]))
    data = msg.encode()
    assert len(data) == HEADER.size + 2 + 2 * 12
    back = ObstaclesMsg.decode(data)
    assert back.centers.tolist() == [[0.0, -20.0], [15.0, -5.0]] and back.radii.tolist() == [3, 4]
    assert ObstaclesMsg.decode(ObstaclesMsg(2, 1, 1.0, np.zeros((0, 2)), np.zeros(0)).encode()
                               ).radii.size == 0
    with pytest.raises(PayloadError, match="size"):
        ObstaclesMsg.decode(data[:-4])
    with pytest.raises(PayloadError, match="nonfinite"):
        ObstaclesMsg.decode(ObstaclesMsg(2, 1, 1.0, np.array([[0.0, 0.0]]),
                                         np.array([-1.0])).encode())


def test_truth_and_mission_round_trip():
    t = TruthMsg(4, 9, 5.0, 1.0, 2.0, 3.0, 4.0, 5.0)
    assert TruthMsg.decode(t.encode()) == t
    m = MissionMsg(1, 2.0, 1e9, (20.0, 0.0), (2.0, 0.0), 0.1, np.array([1, 2, 9]),
                   np.array([[0.0, -4.0], [0.0, 0.0], [0.0, 4.0]]))
    back = MissionMsg.decode(m.encode())
    assert back.epoch == 1e9 and back.ids.tolist() == [1, 2, 9]
    assert back.offsets.tolist() == m.offsets.tolist() and back.omega == pytest.approx(0.1)
    with pytest.raises(PayloadError, match="kind"):
        MissionMsg.decode(t.encode())


def test_fix_round_trip_and_refusals():
    f = FixMsg(3, 7, 1.7e9, 1.5, -2.25, 3.0, 0.004)
    data = f.encode()
    assert len(data) == FixMsg.SIZE == 44
    back = FixMsg.decode(data)
    assert (back.robot_id, back.seq, back.stamp, back.x, back.y, back.theta) == (
        3, 7, 1.7e9, 1.5, -2.25, 3.0)
    assert back.error == pytest.approx(0.004)
    with pytest.raises(PayloadError, match="size"):
        FixMsg.decode(data[:-1])
    with pytest.raises(PayloadError, match="kind"):
        FixMsg.decode(TruthMsg(4, 9, 5.0, 1.0, 2.0, 3.0, 4.0, 5.0).encode())
    with pytest.raises(PayloadError, match="nonfinite"):
        FixMsg.decode(FixMsg(3, 7, 1.0, float("nan"), 0.0, 0.0, 0.01).encode())
    with pytest.raises(PayloadError, match="error"):
        FixMsg.decode(FixMsg(3, 7, 1.0, 0.0, 0.0, 0.0, 0.0).encode())


@given(st.binary(max_size=80))
def test_random_bytes_never_crash(data):
    for cls in (StateMsg, ObstaclesMsg, TruthMsg, MissionMsg, FixMsg):
        try:
            cls.decode(data)
        except PayloadError:
            pass
