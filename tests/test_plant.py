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

    def service(self, now):
        pass

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
    from firmware_sim.sitl_plant import PlantRobot, SitlPlant
    from firmware_sim.world import Obstacles
    from transport.payloads import ObstaclesMsg, TruthMsg

    robot = RobotParams()
    speeds = [(2.0, 2.0), (3.0, -1.0), (0.5, 1.5), (1.0, 2.0)]
    robots = [PlantRobot(i + 1, np.array([i, -i, 3.0 - i]), _Wheels(*s, silent=5 * (i == 3)))
              for i, s in enumerate(speeds)]
    odometry = [Odometry(robot.wheel_radius, robot.wheel_base, rb.pose.copy()) for rb in robots]
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
            assert rb.pose.tolist() == odo.pose.tolist()       # the same arcs, to the bit
    assert robots[3].pose.tolist() != [3.0, -3.0, 0.0] and robots[3].drivers.k > 5
    truth = [TruthMsg.decode(d) for kind, _, d in sent if kind == "truth"]
    assert len(truth) == 20 * 4 and [t.robot_id for t in truth[-4:]] == [1, 2, 3, 4]
    assert [truth[-1].x, truth[-1].y, truth[-1].theta] == robots[3].pose.tolist()
    obstacles = [ObstaclesMsg.decode(d) for kind, _, d in sent if kind == "obstacles"]
    assert len(obstacles) == 2 * 4                                  # 10 Hz over 0.2 s
