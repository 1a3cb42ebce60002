"""Frame layouts from the DBC: golden bytes, node ids, rejection of bad frames."""
import math
import struct
import subprocess
import sys
from pathlib import Path

import can
import pytest

from transport.odrive_frames import (
    AxisError,
    AxisState,
    Cmd,
    FrameError,
    cycle_time,
    decode,
    encode,
    error_names,
    request,
)


def test_design_worked_example():
    msg = encode(1, Cmd.SET_INPUT_VEL, Input_Vel=-2.5, Input_Torque_FF=0.25)
    assert msg.arbitration_id == 0x02D and not msg.is_extended_id
    assert msg.data == bytes.fromhex("000020C00000803E")


@pytest.mark.parametrize("node, cmd, signals, hexdata", [
    (0, Cmd.HEARTBEAT, dict(Axis_Error=0x1000000, Axis_State=8, Procedure_Result=0,
                            Trajectory_Done_Flag=0), "0000000108000000"),
    (0, Cmd.SET_AXIS_STATE, dict(Axis_Requested_State=8), "0800000000000000"),
    (1, Cmd.SET_CONTROLLER_MODE, dict(Control_Mode=2, Input_Mode=2), "0200000002000000"),
    (1, Cmd.SET_LIMITS, dict(Velocity_Limit=10.0, Current_Limit=20.0), "0000204100 00a041"),
    (0, Cmd.GET_ENCODER_ESTIMATES, dict(Pos_Estimate=1.0, Vel_Estimate=-0.5),
     "0000803f000000bf"),
])
def test_golden_bytes(node, cmd, signals, hexdata):
    msg = encode(node, cmd, **signals)
    assert msg.arbitration_id == node << 5 | cmd
    assert msg.data.hex() == hexdata.replace(" ", "")
    assert decode(msg).signals == pytest.approx(signals)


def test_any_node_id_uses_the_same_layouts():
    msg = encode(17, Cmd.SET_INPUT_VEL, Input_Vel=1.0, Input_Torque_FF=0.0)
    assert msg.arbitration_id == 17 << 5 | 0x0D and decode(msg).node == 17
    with pytest.raises(ValueError, match="node id"):
        encode(64, Cmd.ESTOP)


def test_remote_requests_and_empty_messages():
    rtr = request(1, Cmd.GET_ENCODER_ESTIMATES)
    assert rtr.is_remote_frame and rtr.dlc == 8 and decode(rtr).rtr
    assert encode(0, Cmd.ESTOP).dlc == 0
    clear = encode(0, Cmd.CLEAR_ERRORS, Identify=0)
    assert clear.data == b"\0" and decode(clear).signals == {"Identify": 0}


@pytest.mark.parametrize("msg, reason", [
    (can.Message(arbitration_id=0x02D, data=bytes(4), is_extended_id=False), "dlc"),
    (can.Message(arbitration_id=0x01F, data=bytes(8), is_extended_id=False), "unknown_id"),
    (can.Message(arbitration_id=0x12345, data=bytes(8), is_extended_id=True), "unknown_id"),
    (can.Message(arbitration_id=0x02D, data=struct.pack("<ff", math.nan, 0.0),
                 is_extended_id=False), "nonfinite"),
])
def test_bad_frames_are_refused_with_a_reason(msg, reason):
    with pytest.raises(FrameError) as exc:
        decode(msg)
    assert exc.value.reason == reason


def test_value_tables_and_cycle_times_come_from_the_dbc():
    assert AxisState.CLOSED_LOOP_CONTROL == 8 and AxisState.IDLE == 1
    assert AxisError.WATCHDOG_TIMER_EXPIRED == 0x1000000
    assert AxisError.ESTOP_REQUESTED == 0x2000000
    assert error_names(0x3000000) == ("WATCHDOG_TIMER_EXPIRED", "ESTOP_REQUESTED")
    assert cycle_time(Cmd.HEARTBEAT) == 0.1 and cycle_time(Cmd.GET_ENCODER_ESTIMATES) == 0.01
    assert cycle_time(Cmd.SET_INPUT_VEL) is None


def test_cantools_cli_decodes_a_candump_log_of_our_frames(tmp_path):
    log_path = tmp_path / "capture.log"
    frames = [encode(1, Cmd.SET_INPUT_VEL, Input_Vel=-2.5, Input_Torque_FF=0.25),
              encode(0, Cmd.HEARTBEAT, Axis_Error=0x1000000, Axis_State=1, Procedure_Result=0,
                     Trajectory_Done_Flag=0),
              encode(1, Cmd.GET_ENCODER_ESTIMATES, Pos_Estimate=12.5, Vel_Estimate=3.0)]
    with can.Logger(str(log_path)) as logger:                  # candump -L format (.log)
        for i, msg in enumerate(frames):
            msg.timestamp, msg.channel = 100.0 + i / 100, "vcan0"
            logger.on_message_received(msg)
    dbc = Path(__file__).resolve().parent.parent / "transport" / "odrive.dbc"
    text = log_path.read_text()
    out = subprocess.run([sys.executable, "-m", "cantools", "decode", str(dbc)], input=text,
                         capture_output=True, text=True, check=True).stdout
    assert "Axis1_Set_Input_Vel" in out and "Input_Vel: -2.5 rev/s" in out
    assert "Axis_Error: WATCHDOG_TIMER_EXPIRED" in out and "Axis_State: IDLE" in out
    assert "Pos_Estimate: 12.5 rev" in out


def test_steady_flow_frames_are_the_bytes_cantools_makes_from_the_dbc():
    """encode/decode pack the two steady-flow frames with a struct: same bytes and values as
    cantools' own codec from the DBC, for ordinary, tiny, huge and signed values."""
    from transport.odrive_frames import (
        ENCODER_ESTIMATES,
        FLOAT_FRAMES,
        INPUT_VEL,
        database,
        float32_layout,
    )
    values = [0.0, -0.0, 1e-40, 1.0 / 3.0, -123.456789, 5e7, 3.3e38, -3.3e38]
    for cmd, frame in FLOAT_FRAMES.items():
        names = frame.names
        dbc = database().get_message_by_frame_id(int(cmd))
        for a in values:
            for b in values[:4]:
                signals = dict(zip(names, (a, b)))
                msg = encode(3, cmd, **signals)
                assert bytes(msg.data) == dbc.encode(signals, strict=True)
                assert decode(msg).signals == dbc.decode(bytes(msg.data), decode_choices=False,
                                                         scaling=False)
    assert ENCODER_ESTIMATES.size == INPUT_VEL.size == 8
    # what cantools refuses is refused the same way (or encoded the same way: NaN)
    dbc = database().get_message_by_frame_id(int(Cmd.SET_INPUT_VEL))
    for bad in (math.inf, -math.inf, 1e39, "1"):
        with pytest.raises(Exception) as refused:
            dbc.encode({"Input_Vel": bad, "Input_Torque_FF": 0.0}, strict=True)
        with pytest.raises(refused.type):
            # bad values (a str among them) on purpose: refused as cantools refuses them
            encode(1, Cmd.SET_INPUT_VEL, Input_Vel=bad,  # type: ignore[arg-type]
                   Input_Torque_FF=0.0)
    nan = encode(1, Cmd.SET_INPUT_VEL, Input_Vel=math.nan, Input_Torque_FF=0.0)
    assert bytes(nan.data) == dbc.encode({"Input_Vel": math.nan, "Input_Torque_FF": 0.0},
                                         strict=True)
    with pytest.raises(ValueError):
        float32_layout(Cmd.HEARTBEAT, "Axis_Error", "Axis_State")
    with pytest.raises(ValueError):
        float32_layout(Cmd.GET_ENCODER_ESTIMATES, "Vel_Estimate", "Pos_Estimate")
    with pytest.raises(ValueError):
        float32_layout(Cmd.GET_ENCODER_ESTIMATES, "Pos_Estimate")
