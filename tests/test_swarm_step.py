"""The swarm step's plant and sensing, interpreted (the compiled run is checked equal in
tests/test_compiled.py)."""
import math

import numpy as np
import pytest

from agent.config import RobotParams
from firmware_sim.swarm_step import advance, build_grid


def _advance(pose, first, second, wheels, ideal, robot, dt, substeps, slip=None, enc=None):
    """The plant over ``substeps`` of ``dt`` [s] on commands held throughout: (v [m/s],
    u [rad/s]) per robot with the ``ideal`` plant, else the wheels' set-points (right,
    left) [rev/s]."""
    pos = np.zeros((substeps + 1, len(pose), 2))
    cmd = np.repeat(np.column_stack([first, second])[None], substeps, axis=0)
    slip = np.zeros((len(pose), 2)) if slip is None else slip
    enc = np.zeros((len(pose), 2)) if enc is None else enc
    advance(pose, cmd, wheels, slip, enc, ideal, robot.wheel_radius, robot.wheel_base,
            robot.wheel_speed_limit, robot.wheel_ramp, dt, substeps,
            np.ones(len(pose), bool), pos)
    return pos


def test_ideal_plant_applies_commands_exactly():
    pose = np.zeros((1, 3))
    pos = _advance(pose, [2.0], [0.0], np.zeros((1, 2)), True, RobotParams(), 0.125, 4)
    assert pose[0] == pytest.approx([1.0, 0.0, 0.0])
    assert pos[:, 0, 0] == pytest.approx([0.0, 0.25, 0.5, 0.75, 1.0])


def test_ideal_plant_turns_on_an_exact_arc():
    pose = np.array([[0.0, 0.0, 0.0]])
    _advance(pose, [math.pi], [math.pi], np.zeros((1, 2)), True, RobotParams(), 0.25, 4)
    assert pose[0] == pytest.approx([0.0, 2.0, math.pi])          # half a circle of radius 1


def test_wheel_plant_ramps_and_limits():
    robot = RobotParams(wheel_ramp=100.0, wheel_speed_limit=5.0)
    pose, wheels = np.zeros((1, 3)), np.zeros((1, 2))
    _advance(pose, [50.0], [50.0], wheels, False, robot, 0.01, 1)
    assert wheels[0] == pytest.approx([1.0, 1.0])                  # 100 rev/s^2 * 0.01 s
    assert pose[0, 0] == pytest.approx(2 * math.pi * robot.wheel_radius * 1.0 * 0.01)
    for _ in range(100):
        _advance(pose, [50.0], [50.0], wheels, False, robot, 0.01, 1)
    assert wheels[0] == pytest.approx([5.0, 5.0])                  # velocity limit
    x = pose[0, 0]
    _advance(pose, [50.0], [50.0], wheels, False, robot, 0.01, 1)
    assert (pose[0, 0] - x) / 0.01 == pytest.approx(robot.v_wheel_max)
    assert pose[0, 1:] == pytest.approx([0.0, 0.0])


def test_each_wheel_is_clamped_to_the_limit_as_its_driver_clamps_it():
    """The drivers clamp each axis's set-point on its own (firmware_sim.odrive_sim): a
    set-point pair beyond the limit turns no longer on its curvature."""
    robot = RobotParams(wheel_ramp=1e6, wheel_speed_limit=5.0)
    pose, wheels = np.zeros((1, 3)), np.zeros((1, 2))
    _advance(pose, [8.0], [2.0], wheels, False, robot, 0.01, 1)
    assert wheels[0] == pytest.approx([5.0, 2.0])


def test_slipping_wheels_turn_more_than_the_ground_moves():
    """20 % slip on both wheels: the encoders count every turn, the robot moves 80 %."""
    robot = RobotParams(wheel_ramp=1e6)
    pose, wheels, enc = np.zeros((1, 3)), np.zeros((1, 2)), np.zeros((1, 2))
    rate = 1.0 / (2 * math.pi * robot.wheel_radius)             # rev/s for 1 m/s
    _advance(pose, [rate], [rate], wheels, False, robot, 0.01, 10, np.full((1, 2), 0.2), enc)
    turns = 1.0 * 0.1 / (2 * math.pi * robot.wheel_radius)      # 1 m/s for 0.1 s, in rev
    assert enc[0] == pytest.approx([turns, turns])
    assert pose[0] == pytest.approx([0.08, 0.0, 0.0])


def test_grid_holds_every_point_in_its_cell():
    rng = np.random.default_rng(1)
    px, py = rng.uniform(-30, 50, 200), rng.uniform(5, 20, 200)
    start, order, x0, y0, cell, nx, ny = build_grid(px, py, 8.0, 10_000)
    assert sorted(order.tolist()) == list(range(200)) and cell == 8.0
    for c in range(nx * ny):
        for i in order[start[c]:start[c + 1]]:
            assert int((px[i] - x0) / cell) * ny + int((py[i] - y0) / cell) == c


def test_grid_grows_its_cells_for_a_spread_out_swarm():
    *_, cell, nx, ny = build_grid(np.array([0.0, 1000.0]), np.array([0.0, 1000.0]), 8.0, 100)
    assert cell > 8.0 and nx * ny <= 100
