import math

import numpy as np
import pytest

from agent.config import RobotParams
from agent.odometry import Odometry
from firmware_sim.swarm_step import advance


def test_odometry_from_encoders_matches_the_plant_truth():
    robot = RobotParams()
    wheels = np.zeros((1, 2))                            # actual (right, left) [rev/s]
    truth = np.array([[1.0, -2.0, 0.4]])
    odo = Odometry(robot.wheel_radius, robot.wheel_base, truth[0].copy())
    enc = np.zeros((1, 2))                # encoder positions [rev], counted by the plant
    odo.update(*enc[0])
    dt = 0.005
    rng = np.random.default_rng(0)
    for k in range(2000):
        if k % 200 == 0:
            v, u = rng.uniform(-8, 8), rng.uniform(-4, 4)
        advance(truth, np.array([[[v, u]]]), wheels, np.zeros((1, 2)), enc, False,
                robot.wheel_radius, robot.wheel_base, robot.wheel_speed_limit,
                robot.wheel_ramp, dt, 1, np.ones(1, bool), np.zeros((2, 1, 2)))
        est = odo.update(*enc[0])
    assert est[:2] == pytest.approx(truth[0, :2], abs=1e-6)
    assert math.cos(est[2] - truth[0, 2]) == pytest.approx(1.0, abs=1e-9)


def test_the_pose_stays_plain_floats_whatever_numbers_the_drivers_give():
    """A port that hands numpy scalars (the fake drivers of the tests) must not turn the
    pose into them: every operation of the law and the governor would then run through
    numpy's scalar type, several times slower than on a robot's decoded CAN frames."""
    odo = Odometry(0.05, 0.3, (0.0, 0.0, 0.0))
    # np.float32 is no float: passed on purpose, as such a port would
    odo.update(np.float64(0.0), np.float32(0.0))  # type: ignore[arg-type]
    pose = odo.update(np.float64(1.25), np.float32(0.5))  # type: ignore[arg-type]
    assert [type(v) for v in pose] == [float, float, float]
    plain = Odometry(0.05, 0.3, (0.0, 0.0, 0.0))
    plain.update(0.0, 0.0)
    assert pose == plain.update(1.25, 0.5)              # the same values, bit for bit
