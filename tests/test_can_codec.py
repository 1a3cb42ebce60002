"""The CAN Simple codec: golden bytes, round trips, rejections, and the DBC as other tools
read it (cantools CLI on a candump log written by python-can)."""
import math
import struct
import subprocess
import sys
from pathlib import Path

import can
import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

from transport import can_codec as cc
from transport.can_codec import (AxisError, AxisState, BusVoltageCurrent, ClearErrors, Command,
                                 ControlMode, EncoderEstimates, ErrorStatus, Estop, Heartbeat,
                                 InputMode, ProcedureResult, Rejected, Rejection, Request,
                                 SetAxisState, SetControllerMode, SetInputVel, SetLimits, decode,
                                 encode)

DBC = Path(__file__).resolve().parent.parent / "transport" / "odrive_cansimple.dbc"


def frame(fid: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=fid, data=data, is_extended_id=False)


def test_design_worked_example():
    msg = cc.make_set_input_vel(1, -2.5, 0.25)
    assert msg.arbitration_id == 0x02D and not msg.is_extended_id
    assert msg.data == bytes.fromhex("00 00 20 C0 00 00 80 3E")
    assert decode(msg) == SetInputVel(node=1, vel_rev_s=-2.5, torque_ff_nm=0.25)


@pytest.mark.parametrize("msg, fid, data", [
    (cc.make_set_axis_state(0, AxisState.CLOSED_LOOP_CONTROL), 0x007, "08000000 00000000"),
    (cc.make_set_axis_state(1, AxisState.IDLE), 0x027, "01000000 00000000"),
    (cc.make_set_controller_mode(0, ControlMode.VELOCITY_CONTROL, InputMode.VEL_RAMP), 0x00B,
     "02000000 02000000"),
    (cc.make_set_limits(1, 10.0, 20.0), 0x02F, "00002041 0000a041"),
    (cc.make_estop(1), 0x022, ""),
    (cc.make_clear_errors(0), 0x018, ""),
    (encode(Heartbeat(1, AxisError.WATCHDOG_TIMER_EXPIRED, AxisState.IDLE,
                      ProcedureResult.DISARMED, True)), 0x021, "00000001 01030100"),
    (encode(EncoderEstimates(0, 1.5, -2.0)), 0x009, "0000c03f 000000c0"),
    (encode(BusVoltageCurrent(1, 24.0, 0.5)), 0x037, "0000c041 0000003f"),
    (encode(ErrorStatus(0, AxisError.DRV_FAULT, AxisError.ESTOP_REQUESTED)), 0x003,
     "20000000 00000002"),
])
def test_golden_bytes(msg, fid, data):
    assert (msg.arbitration_id, bytes(msg.data)) == (fid, bytes.fromhex(data))


def test_remote_requests_carry_the_message_length():
    msg = cc.make_request(1, Command.GET_ENCODER_ESTIMATES)
    assert (msg.arbitration_id, msg.is_remote_frame, msg.dlc) == (0x029, True, 8)
    assert decode(msg) == Request(1, Command.GET_ENCODER_ESTIMATES)


finite32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
nodes = st.integers(0, cc.MAX_NODE)
records = st.one_of(
    st.builds(Heartbeat, nodes, st.sampled_from(list(AxisError)), st.sampled_from(AxisState),
              st.sampled_from(ProcedureResult), st.booleans()),
    st.builds(Estop, nodes), st.builds(ClearErrors, nodes),
    st.builds(ErrorStatus, nodes, st.sampled_from(list(AxisError)),
              st.sampled_from(list(AxisError))),
    st.builds(SetAxisState, nodes, st.sampled_from(AxisState)),
    st.builds(EncoderEstimates, nodes, finite32, finite32),
    st.builds(SetControllerMode, nodes, st.sampled_from(ControlMode), st.sampled_from(InputMode)),
    st.builds(SetInputVel, nodes, finite32, finite32),
    st.builds(SetLimits, nodes, finite32, finite32),
    st.builds(BusVoltageCurrent, nodes, finite32, finite32),
)


@given(records)
def test_every_record_round_trips(record):
    msg = encode(record)
    assert msg.arbitration_id == record.node << 5 | record.command
    assert decode(msg) == record


@pytest.mark.parametrize("msg, reason", [
    (frame(0x02D, bytes(3)), Rejection.WRONG_DLC),
    (frame(0x001, bytes(9)[:7]), Rejection.WRONG_DLC),
    (frame(0x022, bytes(1)), Rejection.WRONG_DLC),                  # Estop has no payload
    (frame(0x03E, bytes(8)), Rejection.UNKNOWN_ID),                 # command 0x1E
    (can.Message(arbitration_id=0x02D, data=bytes(8), is_extended_id=True), Rejection.UNKNOWN_ID),
    (can.Message(arbitration_id=0x02D, is_error_frame=True, is_extended_id=False),
     Rejection.UNKNOWN_ID),
    (frame(0x02D, struct.pack("<ff", math.nan, 0.0)), Rejection.NON_FINITE),
    (frame(0x009, struct.pack("<ff", 0.0, math.inf)), Rejection.NON_FINITE),
    (frame(0x001, bytes([0, 0, 0, 0, 5, 0, 1, 0])), Rejection.BAD_VALUE),   # axis state 5
    (frame(0x00B, struct.pack("<II", 2, 99)), Rejection.BAD_VALUE),        # input mode 99
])
def test_frames_to_ignore_are_rejected_with_a_reason(msg, reason):
    got = decode(msg)
    assert isinstance(got, Rejected) and got.reason is reason
    assert got.arbitration_id == msg.arbitration_id and got.detail


def test_encoding_refuses_what_the_wire_cannot_carry():
    with pytest.raises(ValueError, match="vel_rev_s"):
        cc.make_set_input_vel(0, math.nan)
    with pytest.raises(ValueError, match="node"):
        cc.make_estop(64)


def test_error_names_name_each_bit():
    assert cc.error_names(0) == ()
    bits = AxisError.WATCHDOG_TIMER_EXPIRED | AxisError.DRV_FAULT
    assert cc.error_names(bits) == ("DRV_FAULT", "WATCHDOG_TIMER_EXPIRED")
    assert cc.error_names(0x2000000 | 0x80) == ("ESTOP_REQUESTED", "0x80")


def test_enums_are_the_dbc_value_tables():
    tables = {("Heartbeat", "Axis_State"): AxisState, ("Heartbeat", "Axis_Error"): AxisError,
              ("Heartbeat", "Procedure_Result"): ProcedureResult,
              ("Set_Axis_State", "Axis_Requested_State"): AxisState,
              ("Get_Error", "Active_Errors"): AxisError, ("Get_Error", "Disarm_Reason"): AxisError,
              ("Set_Controller_Mode", "Control_Mode"): ControlMode,
              ("Set_Controller_Mode", "Input_Mode"): InputMode}
    db = cc.database()
    for (message, signal), enum_type in tables.items():
        choices = db.get_message_by_name(f"Axis0_{message}").get_signal_by_name(signal).choices
        assert {int(k): str(v) for k, v in choices.items()} == {
            e.value: e.name for e in enum_type.__members__.values()}, (message, signal)
    assert AxisError.WATCHDOG_TIMER_EXPIRED == 0x1000000
    assert AxisError.ESTOP_REQUESTED == 0x2000000


def test_dbc_lists_each_message_for_nodes_0_and_1_with_one_layout():
    db = cc.database()
    assert {m.frame_id for m in db.messages} == {n << 5 | c for n in (0, 1) for c in Command}
    for command in Command:
        axis0, axis1 = db.get_message_by_frame_id(command), db.get_message_by_frame_id(
            0x20 | command)
        assert axis1.name == axis0.name.replace("Axis0_", "Axis1_")
        assert axis0.length == axis1.length and not axis0.is_extended_frame
        assert [(s.name, s.start, s.length, s.is_float, s.is_signed, s.byte_order, s.unit,
                 s.choices) for s in axis0.signals] == [
            (s.name, s.start, s.length, s.is_float, s.is_signed, s.byte_order, s.unit, s.choices)
            for s in axis1.signals]
        assert axis0.cycle_time == axis1.cycle_time
    assert all(s.is_float and s.length == 32 and s.byte_order == "little_endian"
               for c in (Command.SET_INPUT_VEL, Command.GET_ENCODER_ESTIMATES,
                         Command.SET_LIMITS, Command.GET_BUS_VOLTAGE_CURRENT)
               for s in cc.layout(c).signals)


def test_cycle_times():
    assert cc.cycle_time_s(Command.HEARTBEAT) == 0.1
    assert cc.cycle_time_s(Command.GET_ENCODER_ESTIMATES) == 0.01
    assert cc.cycle_time_s(Command.SET_INPUT_VEL) is None


def traffic() -> list[can.Message]:
    """One of each frame our link sends, for both nodes, plus an RTR request."""
    msgs = []
    for node in (0, 1):
        msgs += [cc.make_set_controller_mode(node, ControlMode.VELOCITY_CONTROL,
                                             InputMode.VEL_RAMP),
                 cc.make_set_limits(node, 10.0, 20.0),
                 cc.make_set_axis_state(node, AxisState.CLOSED_LOOP_CONTROL),
                 cc.make_set_input_vel(node, -2.5, 0.25),
                 encode(Heartbeat(node, AxisError.WATCHDOG_TIMER_EXPIRED, AxisState.IDLE,
                                  ProcedureResult.DISARMED, True)),
                 encode(EncoderEstimates(node, 12.25, 3.5))]
    msgs.append(cc.make_request(1, Command.GET_BUS_VOLTAGE_CURRENT))
    for i, msg in enumerate(msgs):
        msg.timestamp, msg.channel = 100.0 + i * 0.01, "vcan0"
    return msgs


@pytest.fixture
def candump_log(tmp_path):
    path = tmp_path / "traffic.log"
    with can.Logger(str(path)) as logger:           # .log: candump -L format
        for msg in traffic():
            logger(msg)
    return path


def test_cantools_cli_decodes_a_candump_log_of_both_nodes(candump_log):
    out = subprocess.run([sys.executable, "-m", "cantools", "decode", "--single-line", str(DBC)],
                         stdin=candump_log.open(), capture_output=True, text=True, timeout=60,
                         check=True).stdout
    decoded = [line for line in out.splitlines() if ":: Axis" in line]
    assert len(decoded) == sum(not m.is_remote_frame for m in traffic())   # no RTR in cantools
    assert "Axis1_Set_Input_Vel(Input_Vel: -2.5 rev/s, Input_Torque_FF: 0.25 Nm)" in out
    assert "Axis0_Set_Input_Vel(Input_Vel: -2.5 rev/s" in out
    assert "Axis1_Heartbeat(Axis_Error: WATCHDOG_TIMER_EXPIRED, Axis_State: IDLE" in out
    assert "Axis0_Get_Encoder_Estimates(Pos_Estimate: 12.25 rev, Vel_Estimate: 3.5 rev/s)" in out
    assert "Axis0_Set_Controller_Mode(Control_Mode: VELOCITY_CONTROL, Input_Mode: VEL_RAMP)" in out
    assert "Unknown frame" not in out


def test_python_can_log_reader_and_cantools_agree_with_the_codec(candump_log):
    db = cantools.database.load_file(DBC)
    for original, logged in zip(traffic(), can.LogReader(str(candump_log))):
        assert logged.arbitration_id == original.arbitration_id
        assert decode(logged) == decode(original)
        if not logged.is_remote_frame:
            assert db.decode_message(logged.arbitration_id, logged.data) is not None
