import time

import numpy as np
import pytest

from agent.config import RobotParams
from firmware_sim.plant import IdealPlant, PlantKind, WheelPlant, make_plant


def test_ideal_plant_applies_commands_exactly():
    pose, v, u = IdealPlant().step(np.zeros((1, 3)), np.array([2.0]), np.array([0.0]), 0.5)
    assert pose[0] == pytest.approx([1.0, 0.0, 0.0]) and v[0] == 2.0 and u[0] == 0.0


def test_wheel_plant_ramps_and_limits():
    robot = RobotParams(wheel_ramp=100.0, wheel_speed_limit=5.0)
    plant = WheelPlant(robot, 1)
    pose = np.zeros((1, 3))
    pose, v, _ = plant.step(pose, np.array([50.0]), np.array([0.0]), 0.01)
    assert plant.wheel_rev_s[0] == pytest.approx([1.0, 1.0])        # 100 rev/s^2 * 0.01 s
    for _ in range(100):
        pose, v, u = plant.step(pose, np.array([50.0]), np.array([0.0]), 0.01)
    assert plant.wheel_rev_s[0] == pytest.approx([5.0, 5.0])        # velocity limit
    assert v[0] == pytest.approx(robot.v_wheel_max)                 # 2 pi r_w * 5 rev/s
    assert u[0] == pytest.approx(0.0)


def test_make_plant():
    assert isinstance(make_plant(PlantKind.IDEAL, RobotParams(), 3), IdealPlant)
    assert isinstance(make_plant(PlantKind.WHEELS, RobotParams(), 3), WheelPlant)


class _Wheels:
    """Drivers with scripted wheels: unknown for ``silent`` steps, then turning at
    (right, left) [rev/s]."""

    def __init__(self, right, left, silent=0):
        self.speeds, self.silent, self.k, self.pos = (right, left), silent, 0, [0.25, -0.5]

    def fileno(self):
        return None

    def service(self, now, receive=True):
        assert receive          # no bus to poll: always asked to read

    def step(self, dt):
        self.k += 1
        self.pos = [p + s * dt for p, s in zip(self.pos, self.speeds)]

    def wheel_state(self):
        return None if self.k <= self.silent else (*self.pos, *self.speeds)

    def close(self):
        pass


def test_sitl_plant_rolls_each_robot_as_its_odometry_would():
    from agent.kinematics import TWO_PI, body_velocity
    from agent.odometry import Odometry
    from common.payloads import ObstaclesMsg, TruthMsg
    from firmware_sim.sitl_plant import PlantRobot, SitlPlant
    from firmware_sim.world import Obstacles

    robot = RobotParams()
    speeds = [(2.0, 2.0), (3.0, -1.0), (0.5, 1.5), (1.0, 2.0)]
    robots = [PlantRobot(i + 1, (float(i), float(-i), 3.0 - i), _Wheels(*s, silent=5 * (i == 3)))
              for i, s in enumerate(speeds)]
    odometry = [Odometry(robot.wheel_radius, robot.wheel_base, rb.pose) for rb in robots]
    sent = []
    plant = SitlPlant(robots, robot, Obstacles(np.array([[1.0, -1.0]]), np.array([0.5])), 2.0,
                      lambda kind, rid, data: sent.append((kind, rid, data)))
    for k in range(40):
        plant.step(0.005, 0.005 * k, 100.0 + 0.005 * k)
        for rb, odo in zip(robots, odometry):
            state = rb.drivers.wheel_state()
            if state is not None:
                odo.update(*state[:2])
                v, u = body_velocity(TWO_PI * state[2], TWO_PI * state[3], robot.wheel_radius,
                                     robot.wheel_base)
                assert (rb.v, rb.u) == (v, u)
            assert rb.pose == odo.pose                         # the same arcs, to the bit
    assert robots[3].pose != (3.0, -3.0, 0.0) and robots[3].drivers.k > 5
    truth = [TruthMsg.decode(d) for kind, _, d in sent if kind == "truth"]
    assert len(truth) == 20 * 4 and [t.robot_id for t in truth[-4:]] == [1, 2, 3, 4]
    assert (truth[-1].x, truth[-1].y, truth[-1].theta) == robots[3].pose
    obstacles = [ObstaclesMsg.decode(d) for kind, _, d in sent if kind == "obstacles"]
    assert len(obstacles) == 2 * 4                                  # 10 Hz over 0.2 s


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

    robots = [PlantRobot(rid, (0.0, 5.0 * rid, 0.0),
                         Counted(open_bus("udp_multicast", "ff11::b5:7", port=port), rid))
              for rid, port in ((1, ports[0]), (2, ports[1]))]
    host = open_bus("udp_multicast", "ff11::b5:7", port=ports[0])
    try:
        plant = SitlPlant(robots, RobotParams(), Obstacles(np.zeros((0, 2)), np.zeros(0)), 2.0,
                          lambda *_: None)
        plant.step(0.005, 0.0, 100.0)
        assert reads == {1: 0, 2: 0}                   # nothing waiting: no bus read
        host.send(encode(0, Cmd.SET_INPUT_VEL, Input_Vel=2.5, Input_Torque_FF=0.0))
        deadline = time.monotonic() + 2.0
        while robots[0].drivers.axes[0].setpoint != 2.5:
            assert time.monotonic() < deadline, "the command never reached robot 1"
            plant.step(0.005, 0.0, 100.0)
        assert reads[1] >= 1 and reads[2] == 0
        assert robots[1].drivers.axes[0].setpoint == 0.0
    finally:
        host.shutdown()
        plant.close()
