"""MAVLink link against a pymavlink ground station on loopback (127.0.0.1 only).

The link runs on simulated monotonic time (``poll(now)``); loopback UDP delivers a datagram
before ``sendto`` returns, so each exchange is one poll and no test sleeps.
"""
import dataclasses
import hashlib
import math
import os
import random
import select
import socket
import struct
import time
from collections import deque

import pytest
from fakes import MirrorMotor, SharedSwarm
from helpers import SimClock, free_port
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mav2

from agent.config import CONTROL_PARAMS, ControlParams
from agent.node import Agent
from agent.process import AgentVehicle
from agent.settings import AgentSettings
from common.schema import ConfigError, Param, from_table
from common.vocabulary import AgentMode
from transport.mavlink_io import (
    MAX_DATAGRAM,
    OUT_BUFFER,
    TcpTransport,
    UdpTransport,
    open_transport,
)
from transport.mavlink_link import (
    MAX_READS,
    CustomMode,
    MavlinkLink,
    VehicleState,
    geodetic,
    ned_yaw,
    open_link,
    wrap_pi,
)
from transport.mavlink_params import ParamTable
from transport.mavlink_signing import (
    SignatureCheck,
    Verdict,
    load_signing_key,
    signing_timestamp,
)
from transport.settings import MavlinkSettings

ROBOT = 7
GCS_SYS, GCS_COMP = 255, 190
STEP = 0.02                     # s of simulated time per poll (the control period)


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


class FakeVehicle:
    """A VehicleControl that records calls; ``refuse`` maps a call name to its reason."""

    def __init__(self):
        self.mode, self.failsafe, self.deadlock = AgentMode.DISARMED, None, None
        self.pose, self.v, self.u = (3.0, 4.0, 0.3), 1.0, 0.5
        self.values = {p.name: float(getattr(ControlParams(), p.field)) for p in CONTROL_PARAMS}
        self.refuse: dict[str, str] = {}
        self.calls: list = []

    def state(self):
        return VehicleState(self.mode, self.failsafe, *self.pose, self.v, self.u,
                            self.deadlock)

    def arm(self):
        self.calls.append("arm")
        if "arm" in self.refuse:
            return self.refuse["arm"]
        if self.mode is AgentMode.DISARMED:
            self.mode = AgentMode.HOLD
        return None

    def disarm(self):
        self.calls.append("disarm")
        self.mode = AgentMode.DISARMED

    def set_mode(self, mode):
        self.calls.append(mode)
        if self.mode is AgentMode.DISARMED:
            return "not armed"
        self.mode = mode
        return None

    def param(self, name):
        return self.values[name]

    def set_param(self, name, value):
        self.calls.append(("set_param", name))
        if "set_param" in self.refuse:
            return self.refuse["set_param"]
        self.values[name] = value
        return None


def gcs_connection(url: str):
    """A pymavlink ground station speaking MAVLink 2 (common dialect) without touching
    pymavlink's process-wide dialect (no MAVLINK20 variable, no auto-switch)."""
    conn = mavutil.mavlink_connection(url, source_system=GCS_SYS, source_component=GCS_COMP)
    conn.mav = mav2.MAVLink(conn, srcSystem=GCS_SYS, srcComponent=GCS_COMP)
    conn.mav.robust_parsing = True
    conn.first_byte = False
    return conn


class Rig:
    """A link polled on simulated time and a GCS that records everything it receives.

    ``seen`` keeps every message; ``until`` examines each one once, in order."""

    def __init__(self, link, gcs, vehicle, clock):
        self.link, self.gcs, self.vehicle, self.clock = link, gcs, vehicle, clock
        self.start, self.ticks = clock.now, 0
        self.seen: list = []
        self.inbox: deque = deque()

    def step(self, n: int = 1) -> list:
        new = []
        for _ in range(n):
            self.link.poll(self.clock.now)
            self.ticks += 1
            self.clock.now = self.start + self.ticks * STEP
            while (m := self.gcs.recv_match(blocking=False)) is not None:
                if m.get_type() != "BAD_DATA":
                    new.append(m)
        self.seen += new
        self.inbox += new
        return new

    def until(self, mtype: str, cond=lambda m: True, polls: int = 100):
        for _ in range(polls + 1):
            while self.inbox:
                m = self.inbox.popleft()
                if m.get_type() == mtype and cond(m):
                    return m
            self.step()
        raise AssertionError(f"no {mtype} within {polls} polls")

    def none_of(self, mtype: str, polls: int = 10) -> None:
        assert not [m for m in self.step(polls) if m.get_type() == mtype]

    def texts(self) -> list[str]:
        return [m.text for m in self.seen if m.get_type() == "STATUSTEXT"]

    def command(self, command, *params, target=ROBOT):
        p = list(params) + [0.0] * (7 - len(params))
        self.gcs.mav.command_long_send(target, 1, command, 0, *p)

    def ack(self, command):
        return self.until("COMMAND_ACK", lambda m: m.command == command).result


@pytest.fixture
def make_rig():
    opened = []

    def make(settings=None, key=None, vehicle=None):
        port = free_port("udp")
        gcs = gcs_connection(f"udpin:127.0.0.1:{port}")
        opened.append(gcs)
        s = dataclasses.replace(settings or MavlinkSettings(), url=f"udpout:127.0.0.1:{port}")
        link = MavlinkLink(open_transport(s.url), vehicle or FakeVehicle(), ROBOT, s, key,
                           wall=time.time, params=CONTROL_PARAMS)
        opened.append(link)
        rig = Rig(link, gcs, link.vehicle, SimClock(start=100.0))
        rig.until("HEARTBEAT")                   # the GCS now knows the robot's address
        return rig

    try:
        yield make
    finally:
        for thing in reversed(opened):
            thing.close()


# --- pure conversions ------------------------------------------------------------------
def test_ned_yaw_and_wrap():
    assert ned_yaw(0.0) == pytest.approx(math.pi / 2)            # facing east
    assert ned_yaw(math.pi / 2) == pytest.approx(0.0)            # facing north
    assert ned_yaw(math.pi) == pytest.approx(-math.pi / 2)       # facing west
    assert ned_yaw(-math.pi / 2) == pytest.approx(math.pi)       # facing south: +pi
    assert wrap_pi(-math.pi) == math.pi and wrap_pi(3 * math.pi) == pytest.approx(math.pi)


def test_geodetic_matches_the_usual_metres_per_degree():
    lat0, lon0 = -35.363261, 149.16523
    phi = math.radians(lat0)
    m_per_deg_lat = 111132.92 - 559.82 * math.cos(2 * phi) + 1.175 * math.cos(4 * phi)
    m_per_deg_lon = 111412.84 * math.cos(phi) - 93.5 * math.cos(3 * phi)
    lat, lon, alt = geodetic((lat0, lon0, 0.0), north=100.0, east=-50.0, up=2.0)
    assert lat - lat0 == pytest.approx(100.0 / m_per_deg_lat, abs=1e-8)   # ~1 mm
    assert lon - lon0 == pytest.approx(-50.0 / m_per_deg_lon, abs=1e-8)
    assert alt == 2.0
    assert geodetic((0.0, 179.9999, 0.0), 0.0, 100.0)[1] < -179.99        # wraps at 180


# --- telemetry -------------------------------------------------------------------------
def test_telemetry_rates_frames_and_conversions(make_rig):
    rig = make_rig()
    v = rig.vehicle
    v.mode = AgentMode.FORMATION
    msgs = rig.step(50)                                   # 1 s of polls
    count = {t: sum(m.get_type() == t for m in msgs) for t in
             ("HEARTBEAT", "SYS_STATUS", "LOCAL_POSITION_NED", "ATTITUDE",
              "GLOBAL_POSITION_INT", "GPS_GLOBAL_ORIGIN", "HOME_POSITION")}
    assert count == {"HEARTBEAT": 1, "SYS_STATUS": 1, "LOCAL_POSITION_NED": 10,
                     "ATTITUDE": 10, "GLOBAL_POSITION_INT": 10, "GPS_GLOBAL_ORIGIN": 1,
                     "HOME_POSITION": 1}
    last = {m.get_type(): m for m in msgs}
    for m in msgs:
        assert m.get_msgbuf()[0] == 0xFD                  # MAVLink 2
        assert (m.get_srcSystem(), m.get_srcComponent()) == (ROBOT, 1)
    hb = last["HEARTBEAT"]
    assert (hb.type, hb.autopilot) == (mav2.MAV_TYPE_GROUND_ROVER, mav2.MAV_AUTOPILOT_GENERIC)
    assert hb.base_mode == (mav2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                            | mav2.MAV_MODE_FLAG_SAFETY_ARMED)
    assert hb.custom_mode == CustomMode.FORMATION and hb.system_status == mav2.MAV_STATE_ACTIVE

    x, y, theta = v.pose                                  # ENU: 3 m east, 4 m north
    lp = last["LOCAL_POSITION_NED"]
    assert (lp.x, lp.y, lp.z) == pytest.approx((y, x, 0.0))
    assert (lp.vx, lp.vy) == pytest.approx((v.v * math.sin(theta), v.v * math.cos(theta)))
    att = last["ATTITUDE"]
    assert att.yaw == pytest.approx(math.pi / 2 - theta) and att.yawspeed == pytest.approx(-v.u)
    assert att.roll == att.pitch == 0.0
    assert att.time_boot_ms > lp.time_boot_ms - 100

    origin = MavlinkSettings().origin
    gp = last["GLOBAL_POSITION_INT"]
    lat, lon, alt = geodetic(origin, y, x)
    assert (gp.lat, gp.lon, gp.alt) == (round(lat * 1e7), round(lon * 1e7), round(alt * 1e3))
    assert gp.lat > round(origin[0] * 1e7) and gp.lon > round(origin[1] * 1e7)
    assert gp.hdg == round(math.degrees(math.pi / 2 - theta) * 100)
    assert (gp.vx, gp.vy, gp.relative_alt) == (round(100 * math.sin(theta)),
                                               round(100 * math.cos(theta)), 0)
    go = last["GPS_GLOBAL_ORIGIN"]
    assert (go.latitude, go.longitude, go.altitude) == (round(origin[0] * 1e7),
                                                        round(origin[1] * 1e7), 584000)
    home = last["HOME_POSITION"]                          # where the robot was at start
    assert (home.x, home.y, home.z) == pytest.approx((y, x, 0.0))
    assert (home.latitude, home.longitude) == (gp.lat, gp.lon)


def test_a_poll_sends_its_telemetry_as_one_datagram_every_tenth_of_a_second():
    """All streams fall on the same polls and leave as one datagram of whole frames."""
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    link = MavlinkLink(open_transport(f"udpout:127.0.0.1:{gcs.getsockname()[1]}"),
                       FakeVehicle(), ROBOT)
    parser = mav2.MAVLink(None)
    try:
        per_poll = []
        for k in range(50):                               # 1 s at 50 Hz
            link.poll(100.0 + k * STEP)
            datagrams = []
            while select.select([gcs], [], [], 0.0)[0]:
                datagrams.append(gcs.recv(65535))
            per_poll.append([[m.get_type() for m in parser.parse_buffer(d) or []]
                             for d in datagrams])
    finally:
        link.close()
        gcs.close()
    sending = [k for k, d in enumerate(per_poll) if d]
    assert sending == list(range(0, 50, 5))               # every fifth poll, from the first
    assert all(len(per_poll[k]) == 1 for k in sending)    # one datagram each
    assert sorted(per_poll[0][0]) == sorted(
        ["HEARTBEAT", "LOCAL_POSITION_NED", "ATTITUDE", "GLOBAL_POSITION_INT", "SYS_STATUS",
         "GPS_GLOBAL_ORIGIN", "HOME_POSITION"])
    assert sorted(per_poll[5][0]) == ["ATTITUDE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"]


def test_udp_flush_packs_whole_frames_into_datagrams_up_to_the_mtu():
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    out = UdpTransport("127.0.0.1", gcs.getsockname()[1], listen=False)
    try:
        frames = [bytes([k]) * 280 for k in range(12)]    # MAVLink 2's largest frame
        for f in frames:
            out.write(f)
        assert not select.select([gcs], [], [], 0.05)[0]  # nothing leaves before a flush
        out.flush()
        got = []
        while select.select([gcs], [], [], 0.2)[0]:
            got.append(gcs.recv(65535))
        assert [len(d) for d in got] == [5 * 280, 5 * 280, 2 * 280]    # 1472 bytes at most
        assert b"".join(got) == b"".join(frames)          # in order, none cut
        assert max(map(len, got)) <= MAX_DATAGRAM and out.dropped == 0
        for _ in range(OUT_BUFFER // 280 + 5):            # not flushed: the buffer is bounded
            out.write(bytes(280))
        assert out.dropped == 5
    finally:
        out.close()
        gcs.close()


def test_heartbeat_follows_mode_and_failsafe(make_rig):
    rig = make_rig()
    hb = rig.until("HEARTBEAT")
    assert hb.base_mode == mav2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert (hb.custom_mode, hb.system_status) == (CustomMode.HOLD, mav2.MAV_STATE_STANDBY)
    rig.vehicle.mode = AgentMode.HOLD
    rig.vehicle.failsafe = "driver feedback lost"
    hb = rig.until("HEARTBEAT")
    assert hb.base_mode & mav2.MAV_MODE_FLAG_SAFETY_ARMED and hb.custom_mode == CustomMode.HOLD
    assert hb.system_status == mav2.MAV_STATE_CRITICAL
    texts = rig.texts()
    assert "armed, mode HOLD" in texts and "failsafe: driver feedback lost" in texts


def test_deadlock_is_reported_once_and_its_end_too(make_rig):
    rig = make_rig()
    rig.until("HEARTBEAT")
    rig.vehicle.deadlock = "12.0 m off, <0.5 m closer in 10 s"
    rig.until("HEARTBEAT")
    rig.vehicle.deadlock = "12.1 m off, <0.5 m closer in 10 s"    # still deadlocked
    rig.until("HEARTBEAT")
    texts = rig.texts()
    assert [t for t in texts if t.startswith("deadlocked")] == [
        "deadlocked: 12.0 m off, <0.5 m closer in 10 s"]
    rig.vehicle.deadlock = None
    rig.until("HEARTBEAT")
    assert "progressing again" in rig.texts()


# --- commands ---------------------------------------------------------------------------
def test_arm_disarm_and_modes_are_acknowledged(make_rig):
    rig = make_rig()
    v = rig.vehicle
    rig.command(mav2.MAV_CMD_DO_SET_MODE, mav2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                CustomMode.FORMATION)
    assert rig.ack(mav2.MAV_CMD_DO_SET_MODE) == mav2.MAV_RESULT_DENIED
    assert "not armed" in rig.texts()                     # the reason, before the ACK

    rig.command(mav2.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert rig.ack(mav2.MAV_CMD_COMPONENT_ARM_DISARM) == mav2.MAV_RESULT_ACCEPTED
    assert v.mode is AgentMode.HOLD

    rig.command(mav2.MAV_CMD_DO_SET_MODE, mav2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                CustomMode.FORMATION)
    assert rig.ack(mav2.MAV_CMD_DO_SET_MODE) == mav2.MAV_RESULT_ACCEPTED
    assert v.mode is AgentMode.FORMATION
    rig.gcs.mav.set_mode_send(ROBOT, mav2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, CustomMode.HOLD)
    assert rig.ack(mav2.MAV_CMD_DO_SET_MODE) == mav2.MAV_RESULT_ACCEPTED
    assert v.mode is AgentMode.HOLD
    assert rig.until("HEARTBEAT").custom_mode == CustomMode.HOLD

    for base, custom, why in ((mav2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 5, "unknown custom mode 5"),
                              (0, 1, "only custom modes")):
        rig.command(mav2.MAV_CMD_DO_SET_MODE, base, custom)
        assert rig.ack(mav2.MAV_CMD_DO_SET_MODE) == mav2.MAV_RESULT_DENIED
        assert any(why in t for t in rig.texts())
    rig.command(mav2.MAV_CMD_COMPONENT_ARM_DISARM, 0.5)
    assert rig.ack(mav2.MAV_CMD_COMPONENT_ARM_DISARM) == mav2.MAV_RESULT_DENIED
    rig.command(mav2.MAV_CMD_NAV_TAKEOFF)
    assert rig.ack(mav2.MAV_CMD_NAV_TAKEOFF) == mav2.MAV_RESULT_UNSUPPORTED

    v.refuse["arm"] = "drivers report an error"
    rig.command(mav2.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert rig.ack(mav2.MAV_CMD_COMPONENT_ARM_DISARM) == mav2.MAV_RESULT_DENIED
    assert "drivers report an error" in rig.texts()

    rig.command(mav2.MAV_CMD_COMPONENT_ARM_DISARM, 0)
    assert rig.ack(mav2.MAV_CMD_COMPONENT_ARM_DISARM) == mav2.MAV_RESULT_ACCEPTED
    assert v.mode is AgentMode.DISARMED and "disarmed" in rig.texts()
    ack = [m for m in rig.seen if m.get_type() == "COMMAND_ACK"][-1]
    assert (ack.target_system, ack.target_component) == (GCS_SYS, GCS_COMP)


def test_commands_for_other_systems_and_broadcasts_are_ignored(make_rig):
    rig = make_rig()
    calls = len(rig.vehicle.calls)
    for target in (ROBOT + 1, 0):
        rig.command(mav2.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=target)
        rig.none_of("COMMAND_ACK")
    rig.gcs.mav.set_mode_send(ROBOT + 1, mav2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                              CustomMode.FORMATION)
    rig.gcs.mav.param_set_send(ROBOT + 1, 1, b"BS_K", 1.0, mav2.MAV_PARAM_TYPE_REAL32)
    rig.none_of("COMMAND_ACK")
    assert len(rig.vehicle.calls) == calls and rig.vehicle.mode is AgentMode.DISARMED
    assert rig.link.counters.not_for_us == 4


def test_gcs_heartbeat_failsafe_holds_and_refuses_formation(make_rig):
    rig = make_rig(MavlinkSettings(gcs_failsafe=True))
    v = rig.vehicle
    v.mode = AgentMode.FORMATION

    def gcs_heartbeat():
        rig.gcs.mav.heartbeat_send(mav2.MAV_TYPE_GCS, mav2.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    for _ in range(6):                                    # 3 s with a heartbeat every 0.5 s
        gcs_heartbeat()
        rig.step(25)
    assert v.mode is AgentMode.FORMATION
    rig.step(int(1.5 / STEP) + 2)                         # silence for > 1.5 s
    assert v.mode is AgentMode.HOLD
    assert "no GCS heartbeat for 1.5 s: HOLD" in rig.texts()
    v.mode = AgentMode.FORMATION                          # e.g. autostart: held again
    rig.step()
    assert v.mode is AgentMode.HOLD
    rig.gcs.mav.set_mode_send(ROBOT, mav2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                              CustomMode.FORMATION)
    assert rig.ack(mav2.MAV_CMD_DO_SET_MODE) == mav2.MAV_RESULT_DENIED
    gcs_heartbeat()
    rig.step()
    assert "GCS heartbeat back" in rig.texts()
    rig.gcs.mav.set_mode_send(ROBOT, mav2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                              CustomMode.FORMATION)
    assert rig.ack(mav2.MAV_CMD_DO_SET_MODE) == mav2.MAV_RESULT_ACCEPTED
    assert v.mode is AgentMode.FORMATION


# --- parameters -------------------------------------------------------------------------
NEW_VALUES = {"BS_K": 3.5, "BS_K_THETA": 2.5, "BS_D_MAX": 2.5, "BS_K_IJ": 2.0, "BS_A": 0.75,
              "BS_B": 2.5, "BS_C": 4.5, "BS_U_MAX": 6.0, "BS_HYST": 0.25, "BS_EXCHANGE": 2.0}


def test_param_names_fit_mavlink():
    names = [p.name for p in ParamTable(CONTROL_PARAMS).params]
    numeric = [f for f in dataclasses.fields(ControlParams) if f.type not in ("bool", "str")]
    assert len(set(names)) == len(names) == len(numeric)
    assert all(len(n) <= 16 for n in names)
    assert set(NEW_VALUES) | {"BS_PERIOD"} == set(names)
    with pytest.raises(ValueError, match="longer than 16"):
        ParamTable([Param(0, "BS_" + "X" * 14, "x", "m", "x", None, None, None)])


def test_param_list_read_and_every_write_round_trips(make_rig):
    rig = make_rig()
    v = rig.vehicle
    rig.gcs.mav.param_request_list_send(ROBOT, 1)
    values = {}
    for _ in range(len(CONTROL_PARAMS)):
        m = rig.until("PARAM_VALUE", lambda m: m.param_id not in values)
        values[m.param_id] = m
    defaults = ControlParams()
    for spec in CONTROL_PARAMS:
        m = values[spec.name]
        assert (m.param_index, m.param_count) == (spec.index, len(CONTROL_PARAMS))
        assert m.param_type == mav2.MAV_PARAM_TYPE_REAL32
        assert m.param_value == f32(getattr(defaults, spec.field))

    rig.gcs.mav.param_request_read_send(ROBOT, 1, b"BS_C", -1)
    assert rig.until("PARAM_VALUE").param_value == 4.0
    rig.gcs.mav.param_request_read_send(ROBOT, 1, b"", 1)
    assert rig.until("PARAM_VALUE").param_id == "BS_K_THETA"

    for name, value in NEW_VALUES.items():
        rig.gcs.mav.param_set_send(ROBOT, 1, name.encode(), value, mav2.MAV_PARAM_TYPE_REAL32)
        m = rig.until("PARAM_VALUE", lambda m, name=name: m.param_id == name)
        assert m.param_value == value and v.values[name] == value
    assert rig.link.counters.params_set == len(NEW_VALUES)
    assert v.calls == [("set_param", name) for name in NEW_VALUES]


def test_a_refused_write_sends_the_value_in_force_and_the_reason(make_rig):
    rig = make_rig()
    rig.vehicle.refuse["set_param"] = "BS_K = 9 refused: no"
    rig.gcs.mav.param_set_send(ROBOT, 1, b"BS_K", 9.0, mav2.MAV_PARAM_TYPE_REAL32)
    assert rig.until("PARAM_VALUE", lambda m: m.param_id == "BS_K").param_value == 4.0
    assert "BS_K = 9 refused: no" in rig.texts()
    assert (rig.link.counters.params_set, rig.link.counters.params_refused) == (0, 1)


@pytest.mark.parametrize("name, value, why", [
    ("BS_K", -1.0, "ControlParams.K: must be > 0 [1/s]"),
    ("BS_B", 10.0, "need 0 < a < b < c"),
    ("BS_K", 100.0, "period"),
    ("BS_U_MAX", float("nan"), "must be finite"),
    ("BS_PERIOD", 0.01, "BS_PERIOD is read-only at runtime"),
])
def test_invalid_param_is_refused_with_the_old_value_and_a_reason(make_rig, name, value, why):
    clock = SimClock()
    agent = Agent(AgentSettings(robot_id=ROBOT, swarm="t", initial_pose=(1.0, 2.0, 0.0)),
                  MirrorMotor(clock), SharedSwarm(clock).port(ROBOT), clock)
    rig = make_rig(vehicle=AgentVehicle(agent))
    before = agent.s
    rig.gcs.mav.param_set_send(ROBOT, 1, name.encode(), value, mav2.MAV_PARAM_TYPE_REAL32)
    m = rig.until("PARAM_VALUE", lambda m: m.param_id == name)
    assert m.param_value == f32(agent.param(name))
    assert agent.s is before
    chunks = [m for m in rig.seen if m.get_type() == "STATUSTEXT"]
    text = "".join(m.text for m in chunks)
    assert why in text and text.startswith(name)
    if len(text) > 50:                                  # long reasons come in chunks
        assert len({m.id for m in chunks}) == 1 and chunks[0].id != 0
        assert [m.chunk_seq for m in chunks] == list(range(len(chunks)))


def test_unknown_param_is_reported(make_rig):
    rig = make_rig()
    rig.gcs.mav.param_set_send(ROBOT, 1, b"BS_NOPE", 1.0, mav2.MAV_PARAM_TYPE_REAL32)
    rig.step(3)
    assert "no parameter BS_NOPE" in rig.texts()
    assert not [m for m in rig.seen if m.get_type() == "PARAM_VALUE"]


# --- signing ----------------------------------------------------------------------------
@pytest.fixture
def key_file(tmp_path):
    path = tmp_path / "signing.key"
    path.write_text("swarm-secret\n")
    return path


def test_signing_key_file_forms(tmp_path, key_file):
    assert load_signing_key(key_file) == hashlib.sha256(b"swarm-secret").digest()
    raw = tmp_path / "raw.key"
    raw.write_bytes(bytes(range(32)))
    assert load_signing_key(raw) == bytes(range(32))
    for content, why in ((b"  \n", "empty"), (b"\xff" * 40, "neither")):
        bad = tmp_path / "bad.key"
        bad.write_bytes(content)
        with pytest.raises(ValueError, match=why):
            load_signing_key(bad)
    with pytest.raises(ValueError, match="cannot read"):
        load_signing_key(tmp_path / "missing.key")


def signed_gcs(rig, key: bytes, link_id: int = 1) -> None:
    rig.gcs.setup_signing(key, sign_outgoing=True, link_id=link_id,
                          initial_timestamp=signing_timestamp(time.time()))


def test_signing_refuses_unsigned_wrong_key_and_replayed(make_rig, key_file):
    key = load_signing_key(key_file)
    rig = make_rig(key=key)
    signed_gcs(rig, key)
    hb = rig.until("HEARTBEAT")
    assert hb.get_signed()                               # verified by the GCS's pymavlink
    arm = mav2.MAV_CMD_COMPONENT_ARM_DISARM

    rig.gcs.disable_signing()                            # unsigned
    rig.command(arm, 1)
    rig.none_of("COMMAND_ACK")
    signed_gcs(rig, hashlib.sha256(b"guess").digest())  # wrong key
    rig.command(arm, 1)
    rig.none_of("COMMAND_ACK")
    assert rig.vehicle.calls == []
    assert (rig.link.counters.unsigned, rig.link.counters.wrong_key) == (1, 1)

    signed_gcs(rig, key)
    frame = rig.gcs.mav.command_long_encode(ROBOT, 1, arm, 0, 1, 0, 0, 0, 0, 0, 0).pack(
        rig.gcs.mav)
    rig.gcs.write(frame)
    assert rig.ack(arm) == mav2.MAV_RESULT_ACCEPTED
    rig.gcs.write(frame)                                 # the same frame again
    rig.none_of("COMMAND_ACK")
    assert rig.vehicle.calls == ["arm"] and rig.link.counters.replayed == 1


def test_a_forged_future_timestamp_does_not_lock_out_the_gcs(make_rig, key_file):
    key = load_signing_key(key_file)
    rig = make_rig(key=key)
    signed_gcs(rig, key)
    forger = mav2.MAVLink(None, srcSystem=GCS_SYS, srcComponent=GCS_COMP)
    forger.signing.secret_key = hashlib.sha256(b"guess").digest()
    forger.signing.sign_outgoing, forger.signing.link_id = True, 1      # the GCS's stream
    forger.signing.timestamp = signing_timestamp(time.time()) + 10 ** 9  # ~3 h ahead
    rig.gcs.write(forger.command_long_encode(ROBOT, 1, mav2.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                             1, 0, 0, 0, 0, 0, 0).pack(forger))
    rig.none_of("COMMAND_ACK", polls=2)
    rig.command(mav2.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert rig.ack(mav2.MAV_CMD_COMPONENT_ARM_DISARM) == mav2.MAV_RESULT_ACCEPTED
    assert rig.link.counters.wrong_key == 1 and rig.vehicle.calls == ["arm"]


def test_signature_check_new_stream_window():
    key = bytes(32)
    mav = mav2.MAVLink(None, srcSystem=GCS_SYS, srcComponent=GCS_COMP)
    mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.link_id = key, True, 3
    now = signing_timestamp(1.7e9)
    mav.signing.timestamp = now - 61 * 100_000           # a stream that starts 61 s ago
    frame = mav.heartbeat_encode(mav2.MAV_TYPE_GCS, 0, 0, 0, 0).pack(mav)
    assert SignatureCheck(key).verify(frame, now)[0] is Verdict.REPLAYED
    mav.signing.timestamp = now - 59 * 100_000
    frame = mav.heartbeat_encode(mav2.MAV_TYPE_GCS, 0, 0, 0, 0).pack(mav)
    assert SignatureCheck(key).verify(frame, now) == (Verdict.ACCEPTED, now - 59 * 100_000)


# --- robustness ------------------------------------------------------------------------
def test_random_bytes_and_malformed_frames_do_not_disturb(make_rig):
    rig = make_rig()
    rng = random.Random(1234)
    port = rig.link.transport.local_address[1]
    good = rig.gcs.mav.command_long_encode(ROBOT, 1, mav2.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                           1, 0, 0, 0, 0, 0, 0).pack(rig.gcs.mav)
    bad_crc = good[:-1] + bytes([good[-1] ^ 0xFF])
    junk = [bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 600))) for _ in range(150)]
    junk += [b"\xfd" + bytes(rng.getrandbits(8) for _ in range(300)) for _ in range(50)]
    junk += [good[:n] for n in range(1, len(good))] + [bad_crc, b"\x00" * 60000,
                                                      b"\xfd\x09\xff" + b"\x00" * 30]
    reads: list[int] = []                                # transport reads in each poll
    recv = rig.link.transport.recv

    def counted_recv():
        reads[-1] += 1
        return recv()

    rig.link.transport.recv = counted_recv

    def poll(step):
        reads.append(0)
        step()

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as attacker:
        for i, datagram in enumerate(junk):
            attacker.sendto(datagram, ("127.0.0.1", port))
            if i % 10 == 0:
                poll(lambda: rig.link.poll(rig.clock.now))
                rig.clock.now += STEP
    for _ in range(200):                                 # work through the backlog
        poll(rig.step)
    # bounded work per poll: a backlog is read MAX_READS datagrams at a time, never at once
    assert max(reads) == MAX_READS
    assert rig.link.counters.bad_frames > 100
    assert rig.vehicle.calls == []                       # no junk became a command
    rig.gcs.write(good)
    assert rig.ack(mav2.MAV_CMD_COMPONENT_ARM_DISARM) == mav2.MAV_RESULT_ACCEPTED
    assert rig.until("HEARTBEAT").base_mode & mav2.MAV_MODE_FLAG_SAFETY_ARMED


# --- other transports and settings ------------------------------------------------------
def test_tcp_client_reconnects_to_the_ground_station():
    port = free_port("tcp")
    clock = SimClock()
    server = socket.socket()
    link = conns = None
    try:
        server.bind(("127.0.0.1", port))
        server.listen(1)
        server.settimeout(2.0)
        transport = TcpTransport("127.0.0.1", port, clock=clock.monotonic)
        link = MavlinkLink(transport, FakeVehicle(), ROBOT)
        conns = []
        for _ in range(2):
            conn, _ = server.accept()
            conns.append(conn)
            conn.settimeout(2.0)
            parser = mav2.MAVLink(None)
            hb = None
            while hb is None:
                clock.now += STEP
                link.poll(clock.now)
                try:
                    data = conn.recv(4096)
                except TimeoutError:
                    continue
                msgs = parser.parse_buffer(data) or []
                hb = next((m for m in msgs if m.get_type() == "HEARTBEAT"), None)
            assert hb.get_srcSystem() == ROBOT
            conn.close()                                 # the GCS goes away
            for _ in range(int(1.5 / STEP)):             # reconnects within RECONNECT_S
                clock.now += STEP
                link.poll(clock.now)
    finally:
        if link is not None:
            link.close()
        for c in conns or []:
            c.close()
        server.close()


def test_serial_transport_on_a_pty():
    master, slave = os.openpty()
    link = None
    try:
        link = MavlinkLink(open_transport(os.ttyname(slave) + ",115200"), FakeVehicle(), ROBOT)
        link.poll(0.0)
        link.poll(0.02)
        parser, types = mav2.MAVLink(None), set()
        while select.select([master], [], [], 0.5)[0] and "HEARTBEAT" not in types:
            types |= {m.get_type() for m in parser.parse_buffer(os.read(master, 4096)) or []}
        assert {"HEARTBEAT", "LOCAL_POSITION_NED", "ATTITUDE"} <= types
    finally:
        if link is not None:
            link.close()
        os.close(master)
        os.close(slave)


@pytest.mark.parametrize("url", ["udp:1.2.3.4", "udpout:localhost", "tcp:host:99999",
                                 "mcast:", "/dev/ttyUSB0,fast"])
def test_bad_urls_are_refused_by_name(url):
    with pytest.raises(ValueError, match="MAVLink URL"):
        open_transport(url)


def test_settings_validation_and_table():
    with pytest.raises(ConfigError, match="MavlinkSettings.origin: latitude"):
        MavlinkSettings(origin=(89.0, 0.0, 0.0))
    with pytest.raises(ConfigError, match="MavlinkSettings.gcs_timeout"):
        MavlinkSettings(gcs_timeout=0.0)
    where = "agent.toml [mavlink]"
    s = from_table(MavlinkSettings, {"url": "udpin:127.0.0.1:14551", "gcs_failsafe": True,
                                     "origin": [47, 8.0, 400.0]}, where)
    assert s.gcs_failsafe and s.origin == (47.0, 8.0, 400.0) and s.gcs_timeout == 1.5
    with pytest.raises(ConfigError, match=r"agent.toml \[mavlink\]: unknown field\(s\) rate"):
        from_table(MavlinkSettings, {"rate": 4}, where)
    with pytest.raises(ConfigError, match=r"\[mavlink\]: MavlinkSettings.origin: longitude"):
        from_table(MavlinkSettings, {"origin": [0.0, 200.0, 0.0]}, where)
    with pytest.raises(ConfigError, match=r"^agent.toml \[mavlink\]: MavlinkSettings.gcs_timeout"
                                          r": must be > 0 \[s\], got -1.0"):
        from_table(MavlinkSettings, {"gcs_timeout": -1}, where)
    with pytest.raises(ConfigError, match="MavlinkSettings.url: MAVLink URL 'udp:1.2.3.4'"):
        MavlinkSettings(url="udp:1.2.3.4")


def test_open_link_reads_a_relative_key_file(tmp_path, key_file):
    port = free_port("udp")
    link = open_link(MavlinkSettings(url=f"udpout:127.0.0.1:{port}",
                                     signing_key_file=key_file.name),
                     FakeVehicle(), ROBOT, SimClock().monotonic, time.time, base=tmp_path)
    try:
        assert isinstance(link.transport, UdpTransport)
        assert link.signing
    finally:
        link.close()


def test_the_agent_is_commanded_through_the_adapter(make_rig):
    clock = SimClock()
    agent = Agent(AgentSettings(robot_id=ROBOT, swarm="t", initial_pose=(1.0, 2.0, 0.0)),
                  MirrorMotor(clock), SharedSwarm(clock).port(ROBOT), clock)
    rig = make_rig(vehicle=AgentVehicle(agent))
    rig.command(mav2.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert rig.ack(mav2.MAV_CMD_COMPONENT_ARM_DISARM) == mav2.MAV_RESULT_ACCEPTED
    rig.command(mav2.MAV_CMD_DO_SET_MODE, mav2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                CustomMode.FORMATION)
    assert rig.ack(mav2.MAV_CMD_DO_SET_MODE) == mav2.MAV_RESULT_ACCEPTED
    assert agent.mode is AgentMode.FORMATION
    rig.gcs.mav.param_set_send(ROBOT, 1, b"BS_K_THETA", 2.5, mav2.MAV_PARAM_TYPE_REAL32)
    assert rig.until("PARAM_VALUE").param_value == 2.5 and agent.s.control.K_theta == 2.5
    agent.tick()                                          # the next period uses it
    lp = rig.until("LOCAL_POSITION_NED")
    assert (lp.x, lp.y) == pytest.approx((2.0, 1.0))
