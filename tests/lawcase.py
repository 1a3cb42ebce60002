"""Build law inputs for a single robot (N = 1) from plain lists, for the law's tests.

:func:`step` runs :data:`IMPL`: ``vectorised`` (agent.law) or ``single`` (agent.law_single,
for one robot, through :func:`single_as_output`); ``tests/test_law.py`` runs every test on
both.
"""
from __future__ import annotations

import numpy as np

from agent.config import ControlParams
from agent.law import LawInput, LawMemory, LawOutput, control_step
from agent.law_single import SingleMemory, single_step

IMPLS = ("vectorised", "single")
IMPL = "vectorised"


def single(pose, ref, nbrs=(), obstacles=()) -> LawInput:
    """One robot at ``pose`` with reference ``ref``, neighbours [(x, y)], obstacles
    [((cx, cy), r)]."""
    nb = np.array(nbrs, dtype=float).reshape(1, -1, 2)
    oc = np.array([c for c, _ in obstacles], dtype=float).reshape(1, -1, 2)
    orad = np.array([r for _, r in obstacles], dtype=float).reshape(1, -1)
    return LawInput(pose=np.array([pose], dtype=float), ref=np.array([ref], dtype=float),
                    nbr_pos=nb, nbr_valid=np.ones(nb.shape[:2], bool),
                    obs_center=oc, obs_radius=orad, obs_valid=np.ones(orad.shape, bool))


def single_memory(mem: LawMemory, i: int) -> SingleMemory:
    """Row ``i`` of a :class:`LawMemory`."""
    return SingleMemory(tuple(map(float, mem.prev_error[i])) if mem.has_prev[i] else None,
                        bool(mem.avoiding[i]), int(mem.side[i]),
                        tuple(map(float, mem.followed_center[i])),
                        float(mem.followed_radius[i]))


def single_row(inp: LawInput, mem: LawMemory, params: ControlParams, i: int,
               dt: float | None = None) -> tuple:
    """agent.law_single's step on row ``i`` (its valid neighbours and obstacles)."""
    nbrs = [tuple(map(float, q)) for q, ok in zip(inp.nbr_pos[i], inp.nbr_valid[i]) if ok]
    obs = [(float(c[0]), float(c[1]), float(r))
           for c, r, ok in zip(inp.obs_center[i], inp.obs_radius[i], inp.obs_valid[i]) if ok]
    return single_step(tuple(map(float, inp.pose[i])), tuple(map(float, inp.ref[i])), nbrs,
                       obs, single_memory(mem, i), params,
                       params.period if dt is None else dt)


def single_as_output(inp: LawInput, mem: LawMemory, params: ControlParams) -> LawOutput:
    """agent.law_single for a one-robot input, in agent.law's output types."""
    v, u, mode, m = single_row(inp, mem, params, 0)
    memory = LawMemory(prev_error=np.array([m.prev_error]), has_prev=np.array([True]),
                       avoiding=np.array([m.avoiding]), side=np.array([m.side], np.int8),
                       followed_center=np.array([m.followed_center]),
                       followed_radius=np.array([m.followed_radius]))
    return LawOutput(v=np.array([v]), u=np.array([u]), mode=np.array([mode], np.int8),
                     memory=memory)


def step(inp: LawInput, mem: LawMemory | None = None, params: ControlParams | None = None
         ) -> LawOutput:
    mem = mem or LawMemory.initial(len(inp.pose))
    params = params or ControlParams()
    if IMPL == "single" and len(inp.pose) == 1:
        return single_as_output(inp, mem, params)
    return control_step(inp, mem, params)
