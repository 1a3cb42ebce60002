"""Cost of one robot's law step as an agent runs it (agent.law, interpreted).

Median over repeated steps of a robot that sees three neighbours and an obstacle, run back
to back (hot caches) and after sweeping 16 MB of memory between steps (cold caches, as on a
robot computer or a SITL host running many processes).

    .venv/bin/python bench/law_step.py
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

from agent.avoidance import Surroundings
from agent.config import ControlParams, RobotParams
from agent.governor import NO_GAPS, braking_of, fold_hazard, frame_limits, limit_frame
from agent.law import LawMemory, Reference, last_velocity, law_step
from agent.params import LawParams

POSE, REF = (0.0, 0.0, 0.3), Reference(5.0, 1.0, 2.0, 0.0)   # m, rad; reference m and m/s
NBR_X, NBR_Y, NBR_H = [2.0, 3.0, -1.0], [1.0, -2.0, 4.0], [1.0, 0.0, 0.0]
NBR_G = [0.0, 0.5, 1.0]          # m, the neighbours' governor discs beyond a
OBS_X, OBS_Y, OBS_R = [6.0], [0.0], [1.0]
AROUND = Surroundings(NBR_X, NBR_Y, NBR_H, NBR_G, len(NBR_X), OBS_X, OBS_Y, OBS_R, len(OBS_R))


HAZ_X, HAZ_Y = NBR_X + OBS_X, NBR_Y + OBS_Y
HAZ_R = [-math.inf] * len(NBR_X) + [r + 1.0 for r in OBS_R]
HAZ_S = [1.0 + g for g in NBR_G] + [-math.inf] * len(OBS_R)
HAZ_M = [1.0] * len(NBR_X) + [0.0] * len(OBS_R)


def law(p: ControlParams):
    """The governor's limits among the hazards (agent.governor, as the period folds them)
    and the law step."""
    lp = LawParams.of(p, RobotParams())

    def step(mem: LawMemory) -> LawMemory:
        frame = limit_frame(POSE[2], *last_velocity(mem, lp), braking_of(lp, p.period))
        gaps = NO_GAPS
        for h in range(len(HAZ_R)):
            gaps = fold_hazard(gaps, frame, HAZ_X[h] - POSE[0], HAZ_Y[h] - POSE[1], HAZ_R[h],
                               HAZ_S[h], HAZ_M[h])
        return law_step(*POSE, REF, AROUND, frame_limits(gaps, frame), mem, lp,
                        p.period).memory
    return LawMemory(), step


def median_us(setup, p: ControlParams, steps: int, sweep: np.ndarray | None) -> float:
    mem, step = setup(p)
    times = []
    for _ in range(steps):
        if sweep is not None:
            sweep += 1.0
        t0 = time.perf_counter_ns()
        mem = step(mem)
        times.append(time.perf_counter_ns() - t0)
    return float(np.median(times)) / 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=2000)
    args = ap.parse_args()
    p = ControlParams()
    sweep = np.ones(16 * 2**20 // 8)
    print(f"{'law step':<22} {'hot [us]':>9} {'cold [us]':>10}")
    for name, setup in (("agent.law.law_step", law),):
        hot = median_us(setup, p, args.steps, None)
        cold = median_us(setup, p, args.steps // 4, sweep)
        print(f"{name:<22} {hot:9.1f} {cold:10.1f}")


if __name__ == "__main__":
    main()
