import time
from typing import cast

import can
import numpy as np
import pytest

from agent.config import RobotParams


class _Wheels:
    """Drivers with scripted wheels: unknown for ``silent`` steps, then turning at
    (right, left) [rev/s]; their encoders read ``encoder_gain`` times the turns (1: exact)."""

    def __init__(self, right, left, silent=0, encoder_gain=(1.0, 1.0)):
        self.speeds, self.silent, self.k, self.pos = (right, left), silent, 0, [0.25, -0.5]
        self.gain = encoder_gain

    def fileno(self):
        return None

    def service(self, now, receive=True):
        assert receive          # no bus to poll: always asked to read

    def step(self, dt):
        self.k += 1
        self.pos = [p + g * s * dt for p, g, s in zip(self.pos, self.gain, self.speeds)]

    def wheel_state(self):
        return None if self.k <= self.silent else (*self.pos, *self.speeds)

    def close(self):
        pass


def _arc(pose, v, u, t):
    """Closed-form unicycle pose after ``t`` [s] at constant (v, u) (theta not wrapped)."""
    x, y, th = pose
    if u == 0.0:
        return x + v * t * np.cos(th), y + v * t * np.sin(th), th
    return (x + v / u * (np.sin(th + u * t) - np.sin(th)),
            y - v / u * (np.cos(th + u * t) - np.cos(th)), th + u * t)


def _plant(robots, robot=None, sent=None):
    from firmware_sim.sitl_plant import SitlPlant
    from firmware_sim.world import Obstacles

    return SitlPlant(robots, robot or RobotParams(),
                     Obstacles(np.array([[1.0, -1.0]]), np.array([0.5])), 2.0,
                     lambda kind, rid, data: None if sent is None else sent.append(
                         (kind, rid, data)))


def test_sitl_plant_moves_each_robot_along_its_wheels_arc():
    """Straight, turning on the spot, turning while driving, and a robot whose drivers are
    heard from late: each pose is the closed-form unicycle motion of its wheel speeds."""
    from agent.kinematics import TWO_PI, body_velocity, wrap_angle
    from common.payloads import ObstaclesMsg, TruthMsg
    from firmware_sim.sitl_plant import PlantRobot

    robot = RobotParams()
    speeds = [(2.0, 2.0), (3.0, -3.0), (0.5, 1.5), (1.0, 2.0)]
    starts = [(float(i), float(-i), 3.0 - i) for i in range(4)]
    robots = [PlantRobot(i + 1, start, _Wheels(*s, silent=5 * (i == 3)))
              for i, (start, s) in enumerate(zip(starts, speeds))]
    sent: list = []
    plant = _plant(robots, robot, sent)
    dt, steps = 0.005, 40
    for k in range(steps):
        plant.step(dt, dt * k, 100.0 + dt * k)
    for rb, start, (right, left) in zip(robots, starts, speeds):
        v, u = body_velocity(TWO_PI * right, TWO_PI * left, robot.wheel_radius,
                             robot.wheel_base)
        assert (rb.v, rb.u) == (v, u)
        assert isinstance(rb.drivers, _Wheels)
        moving = dt * (steps - rb.drivers.silent)
        x, y, th = _arc(start, v, u, moving)
        assert rb.pose[:2] == pytest.approx((x, y), abs=1e-12)
        assert rb.pose[2] == pytest.approx(wrap_angle(th), abs=1e-12)
    assert robots[1].pose[:2] == pytest.approx(starts[1][:2], abs=1e-12)   # on the spot
    truth = [TruthMsg.decode(d) for kind, _, d in sent if kind == "truth"]
    assert len(truth) == steps // 2 * 4 and [t.robot_id for t in truth[-4:]] == [1, 2, 3, 4]
    assert (truth[-1].x, truth[-1].y, truth[-1].theta) == robots[3].pose
    obstacles = [ObstaclesMsg.decode(d) for kind, _, d in sent if kind == "obstacles"]
    assert len(obstacles) == 2 * 4                                  # 10 Hz over 0.2 s


class _NoBus:
    """A CAN bus on which nothing arrives and whatever is sent vanishes."""

    def fileno(self):
        raise NotImplementedError

    def recv(self, timeout=None):
        return None

    def send(self, msg):
        pass

    def shutdown(self):
        pass


def test_sitl_plant_holds_the_drivers_ramped_speed_over_each_step_like_the_batch_plant():
    """From rest, the emulated drivers ramp to their set-points: the robot moves as the batch
    simulator's wheels plant moves it for the same wheel set-points (the ramped speed at
    each step's end, held over the step), and the drivers' encoders count those turns."""
    from agent.kinematics import TWO_PI, body_velocity
    from firmware_sim.odrive_sim import DriverPair
    from firmware_sim.sitl_plant import PlantRobot
    from firmware_sim.swarm_step import advance
    from transport.odrive_frames import AxisState

    robot = RobotParams(wheel_ramp=100.0)
    right, left = 3.0, 1.0                                  # rev/s, reached after 30 ms
    drivers = DriverPair(cast(can.BusABC, _NoBus()))      # a stand-in bus
    drivers.configure(ramp=robot.wheel_ramp, vel_limit=robot.wheel_speed_limit,
                      enable_watchdog=False)
    for node, target in ((drivers.right_node, right), (drivers.left_node, left)):
        drivers.axes[node].request_state(AxisState.CLOSED_LOOP_CONTROL)
        drivers.axes[node].input_vel(target)
    start = (1.0, 2.0, 0.5)
    rb = PlantRobot(1, start, drivers)
    plant = _plant([rb], robot)
    pose = np.array([start])
    wheels = np.zeros((1, 2))                               # the batch plant's wheels [rev/s]
    turns = np.zeros((1, 2))                                # the truth's wheel turns [rev]
    dt = 0.005
    for k in range(20):
        plant.step(dt, dt * k, 100.0 + dt * k)
        advance(pose, np.array([[[right, left]]]), wheels, np.zeros((1, 2)), turns, False,
                robot.wheel_radius, robot.wheel_base, robot.wheel_speed_limit,
                robot.wheel_ramp, dt, 1, np.ones(1, bool), np.zeros((2, 1, 2)))
        v, u = body_velocity(TWO_PI * wheels[0, 0], TWO_PI * wheels[0, 1], robot.wheel_radius,
                             robot.wheel_base)
        assert (rb.v, rb.u) == pytest.approx((v, u), abs=1e-12)
        assert rb.pose == pytest.approx(tuple(pose[0]), abs=1e-12)
    assert wheels[0] == pytest.approx([right, left])                  # the ramp is over
    encoders = drivers.wheel_state()[:2]
    assert encoders == pytest.approx(tuple(turns[0]), abs=1e-12)


def test_odometry_of_the_emulated_encoders_follows_the_truth_over_uneven_steps():
    """A fast-ramping robot whose set-points jump every period, on a plant stepped by uneven
    real-time steps: odometry integrating the encoders every 20 ms ends where the truth is
    (the encoders count the turns the truth moves by, so no heading drift builds up)."""
    from agent.odometry import Odometry
    from firmware_sim.odrive_sim import DriverPair
    from firmware_sim.sitl_plant import PlantRobot
    from transport.odrive_frames import AxisState

    robot = RobotParams(wheel_ramp=1000.0, wheel_speed_limit=10.0)
    drivers = DriverPair(cast(can.BusABC, _NoBus()))      # a stand-in bus
    drivers.configure(ramp=robot.wheel_ramp, vel_limit=robot.wheel_speed_limit,
                      enable_watchdog=False)
    for node in (drivers.right_node, drivers.left_node):
        drivers.axes[node].request_state(AxisState.CLOSED_LOOP_CONTROL)
    rb = PlantRobot(1, (0.0, 0.0, 0.0), drivers)
    plant = _plant([rb], robot)
    odometry = Odometry(robot.wheel_radius, robot.wheel_base, rb.pose)
    odometry.update(*drivers.wheel_state()[:2])
    rng = np.random.default_rng(3)
    t = 0.0
    for k in range(500):                                    # 10 s of 20 ms periods
        for node in (drivers.right_node, drivers.left_node):
            drivers.axes[node].input_vel(float(rng.uniform(-10.0, 10.0)))
        end = 0.02 * (k + 1)
        while t < end - 1e-9:
            dt = min(float(rng.uniform(0.002, 0.008)), end - t)
            plant.step(dt, t, 100.0 + t)
            t += dt
        odometry.update(*drivers.wheel_state()[:2])
    x, y, theta = rb.pose
    assert odometry.pose[2] == pytest.approx(theta, abs=1e-9)
    assert np.hypot(odometry.pose[0] - x, odometry.pose[1] - y) < 0.05


def test_sitl_plant_truth_is_independent_of_the_encoders_and_of_odometry():
    """Encoders that misread the turns (one 3 % long, one 1 % short) make the agent's
    odometry drift; the plant's truth is the motion the wheels really made."""
    from agent.kinematics import TWO_PI, body_velocity
    from agent.odometry import Odometry
    from firmware_sim.sitl_plant import PlantRobot

    robot = RobotParams()
    start, (right, left) = (0.0, 0.0, 0.0), (2.0, 1.0)
    wheels = _Wheels(right, left, encoder_gain=(1.03, 0.99))
    rb = PlantRobot(1, start, wheels)
    odometry = Odometry(robot.wheel_radius, robot.wheel_base, start)
    odometry.update(*wheels.pos)                            # the encoders' origin
    plant = _plant([rb], robot)
    dt, steps = 0.005, 200
    for k in range(steps):
        plant.step(dt, dt * k, 100.0 + dt * k)
        odometry.update(*wheels.wheel_state()[:2])
    v, u = body_velocity(TWO_PI * right, TWO_PI * left, robot.wheel_radius, robot.wheel_base)
    truth = _arc(start, v, u, dt * steps)
    assert rb.pose[:2] == pytest.approx(truth[:2], abs=1e-12)
    assert np.hypot(odometry.pose[0] - truth[0], odometry.pose[1] - truth[1]) > 0.05


def test_sitl_plant_does_not_import_the_agents_estimator():
    import ast
    from pathlib import Path

    from firmware_sim import sitl_plant

    tree = ast.parse(Path(sitl_plant.__file__).read_text())
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert "agent.odometry" not in imported


def test_sitl_plant_reads_only_the_buses_with_frames_waiting():
    """One poll per physics step: a robot's bus is read only when a frame waits on it, and
    a command on one bus reaches that robot's drivers within the step."""
    import socket

    from firmware_sim.odrive_sim import DriverPair
    from firmware_sim.sitl_plant import PlantRobot, SitlPlant
    from firmware_sim.world import Obstacles
    from transport.canbus import open_bus
    from transport.odrive_frames import Cmd, encode

    ports = []
    for _ in range(2):
        with socket.socket(socket.AF_INET6, socket.SOCK_DGRAM) as s:
            s.bind(("::1", 0))
            ports.append(s.getsockname()[1])
    reads = {1: 0, 2: 0}

    class Counted(DriverPair):
        def __init__(self, bus, rid):
            super().__init__(bus)
            self.rid = rid

        def service(self, now, receive=True):
            reads[self.rid] += receive
            super().service(now, receive)

    drivers = [Counted(open_bus("udp_multicast", "ff11::b5:7", port=port), rid)
               for rid, port in ((1, ports[0]), (2, ports[1]))]
    robots = [PlantRobot(d.rid, (0.0, 5.0 * d.rid, 0.0), d) for d in drivers]
    host = open_bus("udp_multicast", "ff11::b5:7", port=ports[0])
    try:
        plant = SitlPlant(robots, RobotParams(), Obstacles(np.zeros((0, 2)), np.zeros(0)), 2.0,
                          lambda *_: None)
        plant.step(0.005, 0.0, 100.0)
        assert reads == {1: 0, 2: 0}                   # nothing waiting: no bus read
        host.send(encode(0, Cmd.SET_INPUT_VEL, Input_Vel=2.5, Input_Torque_FF=0.0))
        deadline = time.monotonic() + 2.0
        while drivers[0].axes[0].setpoint != 2.5:
            assert time.monotonic() < deadline, "the command never reached robot 1"
            plant.step(0.005, 0.0, 100.0)
        assert reads[1] >= 1 and reads[2] == 0
        assert drivers[1].axes[0].setpoint == 0.0
    finally:
        host.shutdown()
        plant.close()


class _RemoteReports:
    """Remote drivers whose wheels turn at (right, left) [rev/s], the right one reversing
    every 10 steps of 5 ms, reported each step (stamped 100 s + its time) and delivered to
    the world in bursts of ``every`` reports; ``keep_last``: only the last of each burst
    arrives (the others lost)."""

    def __init__(self, right, left, every, keep_last=False):
        self.speeds, self.every, self.keep_last = (right, left), every, keep_last
        self.k, self.pos, self.queued = 0, [0.25, -0.5], []

    def reports(self):
        self.k += 1
        right = self.speeds[0] * (1 if (self.k // 10) % 2 == 0 else -1)
        self.pos = [self.pos[0] + right * 0.005, self.pos[1] + self.speeds[1] * 0.005]
        self.queued.append((100.0 + 0.005 * self.k, *self.pos))
        if self.k % self.every:
            return []
        burst, self.queued = self.queued, []
        return burst[-1:] if self.keep_last else burst

    def fileno(self):
        return None

    def service(self, now, receive=True):
        raise AssertionError("remote drivers are not served by the world")

    def step(self, dt):
        raise AssertionError("remote drivers are not advanced by the world")

    def wheel_state(self):
        raise AssertionError("the world rolls a remote robot through its reports")

    def close(self):
        pass


def test_remote_robot_rolls_through_every_report_late_or_not():
    """A world whose drivers are on other hosts: reports that arrive late, in a burst, move
    the robot along the path its wheels took (not one arc from the first to the last), and
    its truth is stamped when its wheels were last reported, not now."""
    from common.payloads import TruthMsg
    from firmware_sim.sitl_plant import PlantRobot

    def remote(rid, drivers):
        return PlantRobot(rid, (0.0, 0.0, 0.3), drivers, remote=drivers)

    prompt = remote(1, _RemoteReports(2.0, 1.0, every=1))
    late = remote(2, _RemoteReports(2.0, 1.0, every=12))
    merged = remote(3, _RemoteReports(2.0, 1.0, every=12, keep_last=True))
    sent: list[tuple[str, int, bytes]] = []
    plant = _plant([prompt, late, merged], RobotParams(), sent)
    for k in range(60):
        plant.step(0.005, 0.005 * k, 200.0 + 0.005 * k)
    assert late.pose == pytest.approx(prompt.pose, abs=1e-12)
    assert np.hypot(merged.pose[0] - prompt.pose[0], merged.pose[1] - prompt.pose[1]) > 0.01
    assert np.hypot(prompt.pose[0], prompt.pose[1]) > 0.15                 # it did move
    stamps = {TruthMsg.decode(d).robot_id: TruthMsg.decode(d).stamp
              for kind, _, d in sent if kind == "truth"}
    assert stamps == {1: pytest.approx(100.3), 2: pytest.approx(100.3), 3: pytest.approx(100.3)}


def test_truth_between_late_reports_is_interpolated():
    """The SITL report's truth at a control period lies between the samples stamped before
    and after it (a late report must not show a robot behind where it was)."""
    from hil.sitl.report import _pose_at

    times = np.array([0.0, 0.2])
    values = np.array([[0.0, 0.0, 0.0, 2.0, 0.0], [0.4, 0.1, 0.5, 2.0, 0.0]])
    got = _pose_at(times, values, np.array([-0.1, 0.1, 0.2, 0.3]))
    assert got[:, 0] == pytest.approx([0.0, 0.2, 0.4, 0.4])
    assert got[:, 1] == pytest.approx([0.0, 0.05, 0.1, 0.1])
    assert got[:, 2] == pytest.approx([0.0, 0.0, 0.5, 0.5])
