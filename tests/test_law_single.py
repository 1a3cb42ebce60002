"""agent.law_single (one robot, floats) computes what agent.law (vectorised) computes."""
import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings

from agent.config import ControlParams
from agent.law import LawMemory, control_step
from lawcase import single, single_row, step
from test_law_properties import cases

P = ControlParams()


def assert_same_row(out, i, got):
    """Row ``i`` of a vectorised LawOutput equals single_step's (v, u, mode, memory)."""
    v, u, mode, mem = got
    assert mode == out.mode[i]
    assert v == pytest.approx(out.v[i], rel=1e-9, abs=1e-12)
    assert u == pytest.approx(out.u[i], rel=1e-9, abs=1e-12)
    assert mem.prev_error == pytest.approx(tuple(out.memory.prev_error[i]), rel=1e-12)
    assert mem.avoiding == out.memory.avoiding[i]
    assert mem.side == out.memory.side[i]
    assert mem.followed_center == pytest.approx(tuple(out.memory.followed_center[i]))
    assert mem.followed_radius == pytest.approx(out.memory.followed_radius[i])


@settings(max_examples=600, deadline=None, derandomize=True)
@given(cases())
def test_single_robot_law_equals_each_row_of_the_vectorised_law(case):
    inp, mem = case
    out = control_step(inp, mem, P)
    for i in range(len(inp.pose)):
        assert_same_row(out, i, single_row(inp, mem, P, i))


def test_closed_loop_around_obstacles_and_neighbours_agree_step_by_step():
    """A robot driving past two obstacles and a crowd, memory fed back, on both laws:
    every mode (ROTATE latches and hand-overs included) on the way."""
    obstacles = [((4.0, 0.3), 1.5), ((7.5, 2.8), 1.2)]
    crowd = np.array([[6.0, -2.0], [9.0, 0.5], [2.0, 2.5]])
    pose = np.array([0.0, 0.0, 0.4])
    mem = LawMemory.initial(1)
    modes = set()
    for k in range(600):
        t = k * P.period
        ref = (12.0 + 0.3 * t, 1.0)
        nbrs = crowd + 0.4 * np.sin(t + np.arange(3))[:, None]
        inp = single(list(pose), ref, nbrs=nbrs, obstacles=obstacles)
        out = control_step(inp, mem, P)
        assert_same_row(out, 0, single_row(inp, mem, P, 0))
        modes.add(int(out.mode[0]))
        mem = out.memory
        v, u = out.v[0], out.u[0]
        pose = pose + P.period * np.array([v * np.cos(pose[2]), v * np.sin(pose[2]), u])
    assert modes == {0, 1, 2}, modes


def test_the_law_is_vectorised_row_by_row():
    rng = np.random.default_rng(3)
    cases_ = [single([*rng.uniform(-5, 5, 2), rng.uniform(-3, 3)], rng.uniform(-9, 9, 2),
                     nbrs=[rng.uniform(-3, 3, 2)], obstacles=[((0.0, 0.0), 1.5)])
              for _ in range(6)]
    stacked = dataclasses.replace(
        cases_[0], **{f.name: np.concatenate([getattr(c, f.name) for c in cases_])
                      for f in dataclasses.fields(cases_[0])})
    together = step(stacked)
    for i, c in enumerate(cases_):
        alone = step(c)
        assert together.v[i] == pytest.approx(alone.v[0])
        assert together.u[i] == pytest.approx(alone.u[0])
        assert together.mode[i] == alone.mode[0]
