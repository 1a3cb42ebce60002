"""Host side and emulated ODrive drivers talking over python-can's virtual bus, on
simulated time."""
import math
import struct
import uuid

import can
import pytest

from agent.kinematics import body_velocity, wheel_command
from firmware_sim.odrive_sim import DriverPair, EmulatedAxis
from transport.odrive_frames import AxisState, Cmd, encode, request
from transport.wheel_drivers import WheelDrivers


class Rig:
    """One robot: host side and drivers on their own virtual bus, 1 ms physics steps."""

    def __init__(self):
        channel = f"robot-{uuid.uuid4()}"
        self.now = 0.0
        self.host_bus = can.Bus(interface="virtual", channel=channel)
        self.drv_bus = can.Bus(interface="virtual", channel=channel)
        self.host = WheelDrivers(self.host_bus, clock=lambda: self.now)
        self.drivers = DriverPair(self.drv_bus)

    def run(self, seconds, command=None, period=0.02, dt=0.001):
        steps = int(round(seconds / dt))
        every = int(round(period / dt))
        for k in range(steps):
            if command is not None and k % every == 0:
                self.host.command(*command)
            self.drivers.service(self.now)
            self.drivers.step(dt)
            self.now += dt
            self.host.poll()

    def close(self):
        self.host_bus.shutdown()
        self.drivers.close()


@pytest.fixture
def rig():
    r = Rig()
    try:
        yield r
    finally:
        r.close()


def test_arming_and_commanded_velocities_reach_the_encoders(rig):
    rig.host.arm()
    rig.run(0.05, command=(0.0, 0.0))
    fb = rig.host.feedback()
    assert fb.closed_loop and fb.errors == ()
    rig.run(0.03, command=(5.0, -3.0))               # ramp 1000 rev/s^2: 5 ms to 5 rev/s
    fb = rig.host.feedback()
    assert fb.vel_rev_s == pytest.approx((5.0, -3.0), abs=1e-6)
    assert fb.age <= 0.011                             # estimates every 10 ms
    pos0 = fb.pos_rev
    rig.run(1.0, command=(5.0, -3.0))
    fb = rig.host.feedback()
    assert fb.pos_rev[0] - pos0[0] == pytest.approx(5.0, abs=0.06)
    assert fb.pos_rev[1] - pos0[1] == pytest.approx(-3.0, abs=0.04)
    # decoded frames give plain floats, as the agent's law and governor take them
    assert {type(v) for v in (*fb.pos_rev, *fb.vel_rev_s)} == {float}


def test_velocity_limit_and_saturation_keep_the_curvature(rig):
    rig.host.arm()
    right, left = wheel_command(12.0, 6.0, 0.2, 0.8, 10.0)   # beyond the wheel limit
    rig.run(0.1, command=(float(right), float(left)))
    fb = rig.host.feedback()
    v, u = body_velocity(2 * math.pi * fb.vel_rev_s[0], 2 * math.pi * fb.vel_rev_s[1], 0.2, 0.8)
    assert max(map(abs, fb.vel_rev_s)) == pytest.approx(10.0)
    assert u / v == pytest.approx(6.0 / 12.0)


def test_watchdog_trips_when_commands_stop_and_rearming_recovers(rig):
    rig.host.arm()
    rig.run(0.2, command=(4.0, 4.0))
    t_stop = rig.now
    tripped_at = None
    for _ in range(300):
        rig.run(0.001)
        if rig.drivers.axes[0].state == AxisState.IDLE and tripped_at is None:
            tripped_at = rig.now
    assert tripped_at is not None and tripped_at - t_stop <= 0.1 + 0.02
    rig.run(0.12)
    fb = rig.host.feedback()
    assert "right: WATCHDOG_TIMER_EXPIRED" in fb.errors and not fb.closed_loop
    assert abs(fb.vel_rev_s[0]) < 4.0                  # coasting down, not driven
    rig.host.clear_errors()
    rig.host.arm()                                     # closed loop again
    rig.run(0.2, command=(2.0, 2.0))
    fb = rig.host.feedback()
    assert fb.errors == () and fb.closed_loop and fb.vel_rev_s == pytest.approx((2.0, 2.0))


def test_no_motion_unless_closed_loop(rig):
    rig.run(0.2, command=(3.0, 3.0))
    fb = rig.host.feedback()
    assert fb.vel_rev_s == (0.0, 0.0) and not fb.closed_loop


def test_estop_and_disarm(rig):
    rig.host.arm()
    rig.run(0.1, command=(2.0, 2.0))
    rig.host.estop()
    rig.run(0.12)
    fb = rig.host.feedback()
    assert "left: ESTOP_REQUESTED" in fb.errors
    rig.host.clear_errors()
    rig.host.arm()
    rig.run(0.05, command=(1.0, 1.0))
    rig.host.disarm()
    rig.run(0.12)
    assert rig.drivers.axes[1].state == AxisState.IDLE and rig.host.feedback().errors == ()


def test_remote_requests_are_answered(rig):
    rig.host_bus.send(request(1, Cmd.GET_BUS_VOLTAGE_CURRENT))
    rig.drivers.service(0.0)
    got = [m for m in iter(lambda: rig.host_bus.recv(0.0), None)
           if m.arbitration_id == (1 << 5 | Cmd.GET_BUS_VOLTAGE_CURRENT)]
    assert got and struct.unpack("<f", got[0].data[:4])[0] == pytest.approx(24.0)


def test_bad_frames_are_ignored_and_counted_at_both_ends(rig):
    bad = [can.Message(arbitration_id=0x02D, data=bytes(3), is_extended_id=False),
           can.Message(arbitration_id=0x03E, data=bytes(8), is_extended_id=False),
           can.Message(arbitration_id=0x02D, data=struct.pack("<ff", math.nan, 0.0),
                       is_extended_id=False)]
    rig.host.arm()
    for msg in bad:
        rig.host_bus.send(msg)
    rig.run(0.05, command=(1.0, 1.0))
    assert rig.drivers.ignored == {"dlc": 1, "unknown_id": 1, "nonfinite": 1}
    assert rig.drivers.axes[1].setpoint == 1.0          # the NaN never reached the axis
    for msg in bad:
        rig.drv_bus.send(msg)
    rig.host.poll()
    assert rig.host.ignored == {"dlc": 1, "unknown_id": 1, "nonfinite": 1}


def test_fault_injection_silent_node_and_error_bit(rig):
    rig.host.arm()
    rig.run(0.1, command=(1.0, 1.0))
    rig.drivers.faults[1].silent = True
    rig.run(0.3, command=(1.0, 1.0))
    assert rig.host.feedback().age > 0.25               # right node went quiet
    rig.drivers.faults[1].silent = False
    rig.drivers.axes[0].error |= 0x20                   # DRV_FAULT on the left
    rig.run(0.15, command=(1.0, 1.0))
    assert "left: DRV_FAULT" in rig.host.feedback().errors


def test_dropped_and_delayed_frames():
    assert EmulatedAxis().state == AxisState.IDLE
    r = Rig()
    try:
        r.drivers.faults[0].drop = 0.5
        r.drivers.faults[1].delay = 0.05
        r.host.arm()
        r.run(0.5, command=(1.0, 1.0))
        fb = r.host.feedback()
        assert fb is not None
        # the right wheel's estimates arrive 50 ms late: its position lags by 0.05 rev
        assert fb.pos_rev[1] - fb.pos_rev[0] == pytest.approx(0.05, abs=0.012)
        # half of the left node's 50 estimates and 5 heartbeats were dropped
        assert 70 < r.drivers.sent < 95
    finally:
        r.close()


def test_feedback_pairs_the_wheels_at_one_instant():
    """Estimates of the two axes that arrive 10 ms apart are paired at the newer one's
    arrival: the older position carried forward at its velocity."""
    from common import drivers
    channel = f"robot-{uuid.uuid4()}"
    now = [0.0]
    host_bus = can.Bus(interface="virtual", channel=channel)
    peer = can.Bus(interface="virtual", channel=channel)
    try:
        host = WheelDrivers(host_bus, clock=lambda: now[0])
        peer.send(encode(drivers.RIGHT_NODE, Cmd.GET_ENCODER_ESTIMATES, Pos_Estimate=1.0,
                         Vel_Estimate=10.0))
        host.poll()
        now[0] = 0.01
        peer.send(encode(drivers.LEFT_NODE, Cmd.GET_ENCODER_ESTIMATES, Pos_Estimate=2.0,
                         Vel_Estimate=5.0))
        host.poll()
        now[0] = 0.015
        fb = host.feedback()
        assert fb is not None
        assert fb.pos_rev == pytest.approx((1.1, 2.0))
        assert fb.age == pytest.approx(0.015)
    finally:
        host_bus.shutdown()
        peer.shutdown()


def test_frames_sent_by_the_host_are_valid_for_any_peer():
    msg = encode(0, Cmd.SET_AXIS_STATE, Axis_Requested_State=AxisState.CLOSED_LOOP_CONTROL)
    assert msg.data[:4] == bytes([8, 0, 0, 0])


def test_non_finite_commands_never_reach_the_bus(rig):
    rig.host.arm()
    rig.run(0.05, command=(float("nan"), 1.0))
    assert rig.host.ignored["nonfinite_command"] >= 1
    assert rig.drivers.axes[1].setpoint == 0.0 and rig.drivers.ignored["nonfinite"] == 0


def test_arming_does_not_clear_a_latched_estop(rig):
    rig.host.arm()
    rig.run(0.05, command=(1.0, 1.0))
    rig.host.estop()
    rig.run(0.05)
    rig.host.arm()                                     # no clear_errors: stays latched
    rig.run(0.15, command=(1.0, 1.0))
    fb = rig.host.feedback()
    assert "left: ESTOP_REQUESTED" in fb.errors and not fb.closed_loop


def test_cyclic_estimates_and_answers_carry_the_axis_state(rig):
    rig.host.arm()
    rig.run(0.1, command=(2.5, -1.25))
    axis = rig.drivers.axes[1]
    rig.host_bus.send(request(1, Cmd.GET_ENCODER_ESTIMATES))
    rig.drivers.service(rig.now)
    got = [m for m in iter(lambda: rig.host_bus.recv(0.0), None)
           if m.arbitration_id == (1 << 5 | Cmd.GET_ENCODER_ESTIMATES)]
    assert got and struct.unpack("<ff", got[-1].data) == pytest.approx((axis.pos, axis.vel))
    assert got[-1].data == encode(1, Cmd.GET_ENCODER_ESTIMATES, Pos_Estimate=axis.pos,
                                  Vel_Estimate=axis.vel).data


def test_drive_latency_delays_velocity_commands(rig):
    """A robot profile's drive latency: the emulated drivers apply a velocity command that
    long after it arrived (the setpoint is unchanged until then)."""
    rig.drivers.latency = 0.05
    rig.host.arm()
    rig.run(0.05, command=(0.0, 0.0))
    rig.host.command(4.0, 4.0)
    rig.run(0.045)                                     # less than the latency
    assert [a.setpoint for a in rig.drivers.axes.values()] == [0.0, 0.0]
    rig.run(0.01)
    assert [a.setpoint for a in rig.drivers.axes.values()] == [4.0, 4.0]
