"""Build law inputs for a single robot (N = 1) from plain lists, for the law's tests."""
from __future__ import annotations

import numpy as np

from agent.config import ControlParams
from agent.law import LawInput, LawMemory, LawOutput, control_step


def single(pose, ref, nbrs=(), obstacles=()) -> LawInput:
    """One robot at ``pose`` with reference ``ref``, neighbours [(x, y)], obstacles
    [((cx, cy), r)]."""
    nb = np.array(nbrs, dtype=float).reshape(1, -1, 2)
    oc = np.array([c for c, _ in obstacles], dtype=float).reshape(1, -1, 2)
    orad = np.array([r for _, r in obstacles], dtype=float).reshape(1, -1)
    return LawInput(pose=np.array([pose], dtype=float), ref=np.array([ref], dtype=float),
                    nbr_pos=nb, nbr_valid=np.ones(nb.shape[:2], bool),
                    obs_center=oc, obs_radius=orad, obs_valid=np.ones(orad.shape, bool))


def step(inp: LawInput, mem: LawMemory | None = None, params: ControlParams | None = None
         ) -> LawOutput:
    return control_step(inp, mem or LawMemory.initial(len(inp.pose)),
                        params or ControlParams())
