"""Property tests: the law's outputs are finite and bounded for any finite input, and the
compiled law (the batch simulator's) returns exactly what the interpreted one (an agent's)
does."""
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.config import ControlParams
from agent.law import LawMemory, LawParams, law_step
from firmware_sim import compiled

P = ControlParams()
LP = LawParams.of(P)
coord = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False)
near = st.floats(-6.0, 6.0, allow_nan=False, allow_infinity=False)
angle = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
point = st.tuples(near, near)


@st.composite
def cases(draw):
    """(pose, ref, nbr_x, nbr_y, obs_x, obs_y, obs_r, memory) around a random base point;
    references and neighbours may coincide with the robot (D = 0, r = 0)."""
    bx, by = draw(coord), draw(coord)
    dx, dy = draw(point)
    pose = (bx + dx, by + dy, draw(angle))
    on_robot = st.just((pose[0], pose[1]))
    around = point.map(lambda q: (bx + q[0], by + q[1]))
    ref = draw(st.one_of(on_robot, around))
    nbrs = draw(st.lists(st.one_of(on_robot, around), max_size=4))
    obs = draw(st.lists(st.tuples(around, st.floats(0.1, 5.0)), max_size=3))
    mem = LawMemory()
    if draw(st.booleans()):
        centre = obs[0] if obs else ((0.0, 0.0), 0.0)
        mem = LawMemory(*draw(point), True, draw(st.booleans()),
                        draw(st.sampled_from([-1, 0, 1])), *centre[0], centre[1])
    return (pose, ref, [q[0] for q in nbrs], [q[1] for q in nbrs],
            [o[0][0] for o in obs], [o[0][1] for o in obs], [o[1] for o in obs], mem)


def run(law, case, columns=list):
    pose, ref, *cols, mem = case
    return law(*pose, *ref, *(columns(c) for c in cols), mem, LP, P.period)


@settings(max_examples=300, deadline=None)
@given(cases())
def test_outputs_finite_and_bounded(case):
    v, u, mode, mem = run(law_step, case)
    assert math.isfinite(v) and math.isfinite(u)
    assert abs(u) <= P.u_max and abs(v) <= P.K * P.D_max + 1e-9
    assert mode in (0, 1, 2)
    assert math.isfinite(mem.prev_ex) and math.isfinite(mem.prev_ey)
    # the memory it returns can be fed back in
    v2, u2, _, _ = run(law_step, (*case[:-1], mem))
    assert math.isfinite(v2) and math.isfinite(u2)


@settings(max_examples=300, deadline=None)
@given(cases())
def test_compiled_law_equals_the_interpreted_one(case):
    want = run(law_step, case)
    got = run(compiled.kernels().law_step, case, lambda c: np.array(c, dtype=float))
    assert got == want                       # bit for bit, memory included


@settings(max_examples=100, deadline=None)
@given(st.floats(0.0, 1e-12), angle)
def test_reference_at_the_robot(offset, theta):
    v, u, _, _ = law_step(1.0, 2.0, theta, 1.0 + offset, 2.0, [], [], [], [], [], LawMemory(),
                          LP, P.period)
    assert math.isfinite(u) and abs(v) <= P.K * 1e-12 + 1e-15
