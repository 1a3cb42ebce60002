"""CAN conformance with ODrive's official CAN Simple 0.6.10 DBC (shipped by odrive-can):
our DBC's layouts, what the emulated firmware accepts, what our host side sends, and the
watchdog as the firmware has it (enable flag, timeout, fed by any frame to the node)."""
import math
import struct

import can
import cantools
import pytest

from agent.config import ControlParams, RobotParams
from agent.params import LawParams
from common.schema import ConfigError
from firmware_sim.odrive_sim import DriverPair
from transport.odrive_frames import (
    AxisError,
    AxisState,
    Cmd,
    FrameError,
    database,
    decode,
    encode,
    needed_bytes,
    request,
)
from transport.wheel_drivers import WheelDrivers

odrive_can_utils = pytest.importorskip(
    "odrive_can.utils", reason="odrive-can (test extra; Python >= 3.11) carries the official "
                               "DBC")
OFFICIAL = "odrive-cansimple-0.6.10"

# node names: the official DBC calls the host Master and the drivers ODrive_AxisN
NODE_NAMES = {"Host": "Master", "Axis0": "ODrive_Axis0", "Axis1": "ODrive_Axis1"}
SIGNAL_FIELDS = ("start", "length", "byte_order", "is_float", "is_signed", "scale", "offset",
                 "unit")
# (message without its node prefix, signal, field) -> why ours differs, on purpose
DELIBERATE = {
    (msg, sig, "is_signed"): "float32: the DBC sign flag means nothing for an IEEE float "
                             "(SIG_VALTYPE_ 1) and both decode the same bytes alike"
    for msg, sigs in {"Get_Encoder_Estimates": ("Pos_Estimate", "Vel_Estimate"),
                      "Set_Input_Vel": ("Input_Vel", "Input_Torque_FF"),
                      "Set_Limits": ("Velocity_Limit", "Current_Limit"),
                      "Get_Bus_Voltage_Current": ("Bus_Voltage", "Bus_Current")}.items()
    for sig in sigs}


@pytest.fixture(scope="module")
def official() -> cantools.database.can.Database:
    db = cantools.database.load_file(str(odrive_can_utils.get_dbc_path(OFFICIAL)))
    assert isinstance(db, cantools.database.can.Database), type(db)
    return db


def differences(ours, theirs) -> dict[tuple[str, str, str], tuple]:
    """(message, signal, field) -> (ours, theirs) for every message of ``ours``; message
    fields have signal ''."""
    found: dict[tuple[str, str, str], tuple] = {}
    for m in ours.messages:
        short = m.name.split("_", 1)[1]
        try:
            t = theirs.get_message_by_frame_id(m.frame_id)
        except KeyError:
            found[(short, "", "frame_id")] = (m.frame_id, None)
            continue
        for field, a, b in (("name", m.name, t.name), ("length", m.length, t.length),
                            ("senders", [NODE_NAMES.get(n, n) for n in m.senders], t.senders),
                            ("cycle_time", m.cycle_time, t.cycle_time),
                            ("signals", sorted(s.name for s in m.signals),
                             sorted(s.name for s in t.signals))):
            if a != b:
                found[(short, "", field)] = (a, b)
        for s in m.signals:
            u = next((u for u in t.signals if u.name == s.name), None)
            if u is None:
                continue                                     # named by "signals" above
            for field in SIGNAL_FIELDS:
                if getattr(s, field) != getattr(u, field):
                    found[(short, s.name, field)] = (getattr(s, field), getattr(u, field))
            if [NODE_NAMES.get(n, n) for n in s.receivers] != u.receivers:
                found[(short, s.name, "receivers")] = (s.receivers, u.receivers)
    return found


def test_every_message_we_use_has_the_official_id_length_and_layout(official):
    """Each message of our DBC (nodes 0 and 1) against the official one: same id, name,
    length, direction, cycle time and signals (start, length, byte order, type, scale,
    offset, unit); a difference is either listed in DELIBERATE with its reason, or named."""
    found = differences(database(), official)
    unexplained = {k: v for k, v in found.items() if k not in DELIBERATE}
    assert not unexplained, "our DBC differs from ODrive's " + OFFICIAL + ": " + "; ".join(
        f"{m}.{s or '*'} {f}: ours {a!r}, official {b!r}"
        for (m, s, f), (a, b) in sorted(unexplained.items()))
    stale = set(DELIBERATE) - set(found)
    assert not stale, f"listed as deliberate but no longer different: {sorted(stale)}"


def test_the_deliberate_differences_decode_the_same_bytes_alike(official):
    for msg, sig, _ in DELIBERATE:
        ours = database().get_message_by_name(f"Axis0_{msg}")
        theirs = official.get_message_by_name(f"Axis0_{msg}")
        for value in (-2.5, 0.25, -1e-30, 3.3e38):
            data = ours.encode({s.name: value for s in ours.signals}, strict=False)
            # decode_simple: decode for a message that is not a container, typed as such
            assert theirs.decode(data)[sig] == pytest.approx(ours.decode_simple(data)[sig])


def test_our_value_tables_name_values_as_the_official_ones_do(official):
    for m in database().messages:
        theirs = official.get_message_by_frame_id(m.frame_id)
        for s in m.signals:
            if s.choices:
                official_choices = theirs.get_signal_by_name(s.name).choices or {}
                wrong = {int(k): str(v) for k, v in s.choices.items()
                         if str(official_choices.get(k)) != str(v)}
                assert not wrong, f"{m.name}.{s.name}: {wrong} (official: {official_choices})"


def test_the_frames_our_host_sends_have_the_official_layout(official):
    """Every frame WheelDrivers sends is as long as the official DBC says and decodes with
    it to the values we meant."""
    host_bus = can.Bus(interface="virtual", channel="conformance-host")
    tap = can.Bus(interface="virtual", channel="conformance-host")
    try:
        host = WheelDrivers(host_bus, left_node=0, right_node=1)
        host.clear_errors()
        host.arm()
        host.command(1.5, -2.0)
        host.estop()
        host.disarm()
        sent = []
        while (msg := tap.recv(0.0)) is not None:
            sent.append(msg)
        assert len(sent) == host.sent == 18      # 2 clear, 8 arm, 2 command, 2 estop, 4 disarm
        seen = set()
        for msg in sent:
            layout = official.get_message_by_frame_id(msg.arbitration_id)
            assert len(msg.data) == layout.length, layout.name
            seen.add(layout.name.split("_", 1)[1])
            values = layout.decode(bytes(msg.data), decode_choices=False)
            if layout.name == "Axis1_Set_Input_Vel" and values["Input_Vel"]:
                assert values["Input_Vel"] == 1.5
            if layout.name == "Axis0_Clear_Errors":
                assert values == {"Identify": 0}
        assert seen == {"Clear_Errors", "Set_Controller_Mode", "Set_Limits", "Set_Input_Vel",
                        "Set_Axis_State", "Estop"}
    finally:
        host_bus.shutdown()
        tap.shutdown()


@pytest.mark.parametrize("cmd, shortest", [
    (Cmd.SET_AXIS_STATE, 4), (Cmd.CLEAR_ERRORS, 0), (Cmd.ESTOP, 0), (Cmd.SET_INPUT_VEL, 8),
    (Cmd.SET_CONTROLLER_MODE, 8), (Cmd.SET_LIMITS, 8), (Cmd.HEARTBEAT, 7)])
def test_a_frame_is_read_from_the_bytes_its_signals_need(cmd, shortest):
    assert needed_bytes(cmd) == shortest
    for size in range(shortest, 9):
        frame = decode(can.Message(arbitration_id=cmd, data=bytes(size), is_extended_id=False))
        assert frame.cmd == cmd
    for size in [*range(shortest), 9, 64]:
        msg = can.Message(arbitration_id=cmd, data=bytes(size), is_extended_id=False,
                          is_fd=size > 8)
        with pytest.raises(FrameError, match=f"{size} bytes, expected {shortest} to 8") as e:
            decode(msg)
        assert e.value.reason == "dlc"


def test_short_and_long_frames_carry_the_values_of_their_bytes():
    state = decode(can.Message(arbitration_id=0x027, data=struct.pack("<I", 8),
                               is_extended_id=False))
    assert state.node == 1 and state.signals == {"Axis_Requested_State": 8}
    assert decode(can.Message(arbitration_id=0x018, data=b"", is_extended_id=False)
                  ).signals == {"Identify": 0}
    assert decode(can.Message(arbitration_id=0x018, data=b"\x01", is_extended_id=False)
                  ).signals == {"Identify": 1}
    padded = decode(can.Message(arbitration_id=0x007, data=struct.pack("<I", 1) + b"\xff" * 4,
                                is_extended_id=False))         # bytes past the signal: unread
    assert padded.signals == {"Axis_Requested_State": 1}


class Rig:
    """Emulated drivers (nodes 0 left, 1 right) and a raw python-can host on a virtual bus,
    stepped in simulated time."""

    def __init__(self, channel: str, **axis_settings):
        self.drivers = DriverPair(can.Bus(interface="virtual", channel=channel))
        self.drivers.configure(**axis_settings)
        self.host = can.Bus(interface="virtual", channel=channel)
        self.now = 0.0

    def send(self, arbitration_id: int, data: bytes = b"", rtr: bool = False) -> None:
        self.host.send(can.Message(arbitration_id=arbitration_id, data=data,
                                   is_remote_frame=rtr, dlc=8 if rtr else len(data),
                                   is_extended_id=False))

    def run(self, seconds: float, dt: float = 0.005) -> None:
        for _ in range(round(seconds / dt)):
            self.now += dt
            self.drivers.service(self.now)
            self.drivers.step(dt)
        while self.host.recv(0.0) is not None:        # the drivers' frames, not read here
            pass

    def close(self) -> None:
        self.drivers.close()
        self.host.shutdown()


@pytest.fixture
def rig(request):
    r = Rig(f"conf-{request.node.name}")
    yield r
    r.close()


def test_minimal_frames_arm_drive_and_clear_the_emulated_drivers(rig):
    """A host sending only the bytes each command needs (Set_Axis_State as 4 bytes,
    Clear_Errors without Identify) arms, drives, and clears a watchdog trip."""
    axis = rig.drivers.axes[0]
    rig.send(0x00B, struct.pack("<II", 2, 2))                 # velocity control, VEL_RAMP
    rig.send(0x007, struct.pack("<I", 8))                     # closed loop: 4 bytes
    rig.send(0x00D, struct.pack("<ff", 1.0, 0.0))
    rig.run(0.05)
    assert axis.state == AxisState.CLOSED_LOOP_CONTROL and axis.setpoint == 1.0
    rig.run(0.2)                                              # silence: the watchdog trips
    assert axis.state == AxisState.IDLE and axis.error == AxisError.WATCHDOG_TIMER_EXPIRED
    rig.send(0x018)                                           # Clear_Errors, 0 bytes
    rig.send(0x007, struct.pack("<I", 8))
    rig.run(0.01)
    assert axis.error == 0 and axis.state == AxisState.CLOSED_LOOP_CONTROL
    rig.send(0x002)                                           # Estop
    rig.run(0.01)
    rig.send(0x018, b"\x00")                                  # Clear_Errors, 1 byte
    rig.run(0.01)
    assert axis.error == 0 and axis.state == AxisState.IDLE
    assert rig.drivers.ignored == {}


def test_only_truly_malformed_frames_are_counted(rig):
    rig.send(0x00D, struct.pack("<f", 1.0))                   # Set_Input_Vel, 4 of 8 bytes
    rig.send(0x007, b"\x08\x00")                              # Set_Axis_State, 2 of 4
    rig.send(0x00D, struct.pack("<ff", math.inf, 0.0))
    rig.send(0x007, struct.pack("<II", 8, 0))                 # 8 bytes: fine
    rig.send(0x018, b"\x00" * 8)                              # 8 bytes: fine
    rig.run(0.01)
    assert rig.drivers.ignored == {"dlc": 2, "nonfinite": 1}
    assert rig.drivers.axes[0].state == AxisState.CLOSED_LOOP_CONTROL


@pytest.mark.parametrize("feed", [
    lambda r: r.send(0x00D, struct.pack("<ff", 0.5, 0.0)),    # Set_Input_Vel
    lambda r: r.send(0x00F, struct.pack("<ff", 10.0, 20.0)),  # Set_Limits
    lambda r: r.send(0x009, rtr=True),                        # a request (RTR)
    lambda r: r.send(0x01F, bytes(8)),                        # a command we do not emulate
])
def test_any_frame_to_the_node_feeds_its_watchdog(rig, feed):
    rig.send(0x007, struct.pack("<II", 8, 0))                 # both axes to closed loop
    rig.send(0x027, struct.pack("<II", 8, 0))
    for _ in range(10):                                       # 0.5 s, a frame every 50 ms
        feed(rig)
        rig.run(0.05)
    left, right = rig.drivers.axes[0], rig.drivers.axes[1]
    assert left.state == AxisState.CLOSED_LOOP_CONTROL and left.watchdog_trips == 0
    assert right.state == AxisState.IDLE and right.watchdog_trips == 1   # node 1: not fed


def test_watchdog_enable_flag_and_timeout():
    for enable, timeout, trips in ((True, 0.3, (0, 1)), (False, 0.3, (0, 0)),
                                   (True, 0.05, (1, 1))):
        r = Rig(f"conf-wd-{enable}-{timeout}", enable_watchdog=enable,
                watchdog_timeout=timeout)
        try:
            r.send(0x007, struct.pack("<II", 8, 0))
            r.run(0.2)
            first = r.drivers.axes[0].watchdog_trips
            r.run(0.2)
            assert (first, r.drivers.axes[0].watchdog_trips) == trips, (enable, timeout)
        finally:
            r.close()


def test_the_robot_profile_sets_the_watchdog_for_drivers_and_law(tmp_path):
    from hil.files.robot_profile import load_robot_profile
    path = tmp_path / "bot.toml"
    path.write_text("[robot]\nwatchdog_timeout = 0.25\n")
    robot = load_robot_profile(path)
    assert robot.watchdog_timeout == 0.25
    assert LawParams.of(ControlParams(), robot).watchdog == 0.25
    assert RobotParams().watchdog_timeout == 0.1
    for bad in ("0", "-1", "11.0"):
        path.write_text(f"[robot]\nwatchdog_timeout = {bad}\n")
        with pytest.raises(ConfigError, match="watchdog_timeout"):
            load_robot_profile(path)


def test_the_remote_request_we_send_is_what_the_official_dbc_expects(official):
    rtr = request(1, Cmd.GET_ENCODER_ESTIMATES)
    assert rtr.dlc == official.get_message_by_frame_id(rtr.arbitration_id).length
    assert encode(1, Cmd.CLEAR_ERRORS, Identify=0).dlc == 1
