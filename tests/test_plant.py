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
