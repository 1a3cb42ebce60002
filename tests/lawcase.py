"""Run the one law for a single robot from plain lists, for the law's tests.

:func:`step` runs :data:`IMPL`: ``interpreted`` (agent.law as an agent runs it) or
``compiled`` (the same source through numba, as the batch simulator runs it);
``tests/test_law.py`` runs every test on both.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from agent.avoidance import Surroundings
from agent.config import ControlParams, RobotParams
from agent.governor import NO_GAPS, Limits, braking_of, fold_hazard, frame_limits, limit_frame
from agent.law import LawMemory, Reference, last_velocity, law_step
from agent.params import LawParams
from firmware_sim import compiled

IMPLS = ("interpreted", "compiled")
IMPL = "interpreted"


class Case(NamedTuple):
    pose: tuple[float, float, float]
    ref: tuple[float, float]
    nbrs: list[tuple[float, float]]
    obstacles: list[tuple[float, float, float]]
    hazards: list[tuple[float, float, float, float, float]] = []  # x, y, full, half, moving
    held: list[float] | None = None   # per neighbour, pair active last period (None: all
    #                                   as the memory's avoiding flag)
    grow: list[float] | None = None   # per neighbour, its governor's disc beyond a [m]
    #                                   (None: 0 for all)


class Output(NamedTuple):
    v: list[float]          # one robot: v[0] [m/s]
    u: list[float]          # rad/s
    mode: list[int]
    memory: LawMemory
    governed: float = float("inf")   # m/s the governor allowed when it acted


def single(pose, ref, nbrs=(), obstacles=()) -> Case:
    """One robot at ``pose`` with reference ``ref``, neighbours [(x, y)], obstacles
    [((cx, cy), r)]."""
    x, y, theta = map(float, pose)
    ref_x, ref_y = map(float, ref)
    return Case((x, y, theta), (ref_x, ref_y),
                [(float(qx), float(qy)) for qx, qy in nbrs],
                [(float(c[0]), float(c[1]), float(r)) for c, r in obstacles])


def step(case: Case, mem: LawMemory | None = None, params: ControlParams | None = None,
         robot: RobotParams | None = None) -> Output:
    """One law step; ``robot`` None: the ideal robot (no wheel limits, infinite braking)."""
    params = params or ControlParams()
    mem = mem or LawMemory()
    held = case.held if case.held is not None else [float(mem.avoiding)] * len(case.nbrs)
    grow = case.grow if case.grow is not None else [0.0] * len(case.nbrs)
    around = Surroundings([q[0] for q in case.nbrs], [q[1] for q in case.nbrs], held, grow,
                          len(case.nbrs), [o[0] for o in case.obstacles],
                          [o[1] for o in case.obstacles], [o[2] for o in case.obstacles],
                          len(case.obstacles))
    lp = LawParams.of(params, robot)
    law = law_step
    if IMPL == "compiled":            # arrays, as the batch simulator passes them
        law = compiled.kernels().law_step
        nx, ny, nh, ng, ox, oy, orad = (np.array(c, dtype=float) for c in (
            around.nbr_x, around.nbr_y, around.nbr_held, around.nbr_grow, around.obs_x,
            around.obs_y, around.obs_r))
        around = Surroundings(nx, ny, nh, ng, around.n_nbr, ox, oy, orad, around.n_obs)
    out = law(*case.pose, Reference(*case.ref, 0.0, 0.0), around,
              limits(case, mem, lp, params.period), mem, lp, params.period)
    return Output([out.v], [out.u], [out.mode], out.memory, out.governed)


def limits(case: Case, mem: LawMemory, lp: LawParams, dt: float) -> Limits:
    """The governor's limits among ``case``'s hazards, for the robot in ``mem``'s motion."""
    frame = limit_frame(case.pose[2], *last_velocity(mem, lp), braking_of(lp, dt))
    gaps = NO_GAPS
    for hx, hy, full, half, moving in case.hazards:
        gaps = fold_hazard(gaps, frame, hx - case.pose[0], hy - case.pose[1], full, half,
                           moving)
    return frame_limits(gaps, frame)
