import can
import pytest

from transport.busload import bus_load, crc15, frame_bits, stuff_count
from transport.odrive_frames import Cmd, encode


def test_crc15_of_a_known_sequence():
    # CRC of nothing is 0; a single 1 bit gives the polynomial itself
    assert crc15([]) == 0 and crc15([1]) == 0x4599


def test_stuff_count():
    assert stuff_count([0] * 5) == 1
    assert stuff_count([0] * 10) == 2          # the stuff bit starts the next run
    assert stuff_count([0, 1] * 20) == 0
    assert stuff_count([1] * 4 + [0] * 4) == 0


@pytest.mark.parametrize("dlc", [0, 1, 4, 8])
def test_frame_bits_within_the_textbook_bounds(dlc):
    msg = can.Message(arbitration_id=0x155, data=bytes([0x55] * dlc), is_extended_id=False)
    n = frame_bits(msg)
    base = 47 + 8 * dlc
    assert base <= n <= base + (34 + 8 * dlc - 1) // 4


def test_all_zero_frame_is_heavily_stuffed():
    msg = can.Message(arbitration_id=0x000, data=bytes(8), is_extended_id=False)
    assert frame_bits(msg) >= 111 + 15


def test_one_robot_at_50_hz_on_500_kbit():
    """Per second: 2 x Set_Input_Vel at 50 Hz, 2 x encoder estimates at 100 Hz, 2 x
    heartbeat at 10 Hz."""
    frames = ([encode(n, Cmd.SET_INPUT_VEL, Input_Vel=3.1, Input_Torque_FF=0.0)
               for n in (0, 1)] * 50
              + [encode(n, Cmd.GET_ENCODER_ESTIMATES, Pos_Estimate=12.3, Vel_Estimate=3.1)
                 for n in (0, 1)] * 100
              + [encode(n, Cmd.HEARTBEAT, Axis_Error=0, Axis_State=8, Procedure_Result=0,
                        Trajectory_Done_Flag=0) for n in (0, 1)] * 10)
    load = bus_load(frames, 1.0, 500_000)
    assert 0.06 < load < 0.085                  # 320 frames of 8 bytes, ~115 bits each
    with pytest.raises(ValueError):
        bus_load(frames, 0.0)
