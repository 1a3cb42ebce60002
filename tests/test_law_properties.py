"""Property tests: the law's outputs are finite and bounded for any finite input."""
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.config import ControlParams
from agent.law import LawInput, LawMemory, control_step

P = ControlParams()
coord = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False)
near = st.floats(-6.0, 6.0, allow_nan=False, allow_infinity=False)
angle = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
point = st.tuples(near, near)


@st.composite
def cases(draw):
    n = draw(st.integers(1, 4))
    m = draw(st.integers(0, 3))
    k = draw(st.integers(0, 3))
    base = np.array([draw(coord), draw(coord)])
    pose = np.array([[*(base + draw(point)), draw(angle)] for _ in range(n)])
    # references may coincide with the robot (D = 0), neighbours with it (r = 0)
    ref = np.array([pose[i, :2] if draw(st.booleans()) else base + draw(point)
                    for i in range(n)])
    nbr = np.array([[pose[i, :2] if draw(st.booleans()) else base + draw(point)
                     for _ in range(m)] for i in range(n)]).reshape(n, m, 2)
    obs_c = np.array([[base + draw(point) for _ in range(k)] for _ in range(n)]).reshape(n, k, 2)
    obs_r = np.array([[draw(st.floats(0.1, 5.0)) for _ in range(k)] for _ in range(n)]
                     ).reshape(n, k)
    valid_n = np.array([[draw(st.booleans()) for _ in range(m)] for _ in range(n)]
                       , dtype=bool).reshape(n, m)
    valid_o = np.array([[draw(st.booleans()) for _ in range(k)] for _ in range(n)]
                       , dtype=bool).reshape(n, k)
    mem = LawMemory.initial(n)
    if draw(st.booleans()):
        mem = LawMemory(prev_error=np.array([draw(point) for _ in range(n)]),
                        has_prev=np.ones(n, bool),
                        avoiding=np.array([draw(st.booleans()) for _ in range(n)]),
                        side=np.array([draw(st.sampled_from([-1, 0, 1])) for _ in range(n)],
                                      np.int8),
                        followed_center=obs_c[:, 0] if k else np.zeros((n, 2)),
                        followed_radius=obs_r[:, 0] if k else np.zeros(n))
    return LawInput(pose, ref, nbr, valid_n, obs_c, obs_r, valid_o), mem


@settings(max_examples=300, deadline=None)
@given(cases())
def test_outputs_finite_and_bounded(case):
    inp, mem = case
    out = control_step(inp, mem, P)
    assert np.all(np.isfinite(out.v)) and np.all(np.isfinite(out.u))
    assert np.all(np.abs(out.u) <= P.u_max + 1e-12)
    assert np.all(np.abs(out.v) <= P.K * P.D_max + 1e-9)
    assert set(np.unique(out.mode)) <= {0, 1, 2}
    assert np.all(np.isfinite(out.memory.prev_error))
    # the memory it returns can be fed back in
    again = control_step(inp, out.memory, P)
    assert np.all(np.isfinite(again.v)) and np.all(np.isfinite(again.u))


@settings(max_examples=100, deadline=None)
@given(st.floats(0.0, 1e-12), angle)
def test_reference_at_the_robot(offset, theta):
    inp = LawInput(np.array([[1.0, 2.0, theta]]), np.array([[1.0 + offset, 2.0]]),
                   np.zeros((1, 0, 2)), np.zeros((1, 0), bool), np.zeros((1, 0, 2)),
                   np.zeros((1, 0)), np.zeros((1, 0), bool))
    out = control_step(inp, LawMemory.initial(1), P)
    assert math.isfinite(out.u[0]) and abs(out.v[0]) <= P.K * 1e-12 + 1e-15
