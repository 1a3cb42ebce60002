"""Safety and convergence rates of the law over seeded random scenarios (prints one line).

    .venv/bin/python bench/seeded_campaign.py [--seeds 40] [--duration 40]

Each seed draws a swarm of 5-16 robots behind a band of obstacles, a formation (line,
wedge, grid or circle, 5 m spacing) that starts at the band and moves away at 2 m/s, and
either a sparse field (surface gaps >= 2c) or a cluttered one (gaps >= 1 m). The ideal plant,
the paper's gains. Safe: no pair closer than a and no robot centre within a of an obstacle
surface; converged: every robot within tolerance at the end. Uses only the batch
simulator's public API, so it runs unchanged on older commits (bench/side_by_side.py).
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

from agent.config import ControlParams, RobotParams
from agent.formation import Formation, FormationKind, formation_offsets
from firmware_sim.batch import SimOptions, simulate
from firmware_sim.world import Obstacles

KINDS = (FormationKind.LINE, FormationKind.WEDGE, FormationKind.GRID, FormationKind.CIRCLE)


def scenario(seed: int, c: float = 4.0, b: float = 2.0):
    rng = np.random.default_rng(seed)
    cluttered = seed % 2 == 1
    min_gap = 1.0 if cluttered else 2 * c
    obstacles: list[tuple[np.ndarray, float]] = []
    for _ in range(2000):
        if len(obstacles) == (12 if cluttered else 6):
            break
        centre, r = rng.uniform([-10, -25], [25, 25]), rng.uniform(1.0, 3.0)
        if all(np.linalg.norm(centre - oc) - r - orr >= min_gap for oc, orr in obstacles):
            obstacles.append((centre, r))
    n = int(rng.integers(5, 17))
    poses: list[np.ndarray] = []
    while len(poses) < n:
        p = rng.uniform([-75, -30], [-35, 30])
        if all(np.linalg.norm(p - q[:2]) >= b for q in poses):
            poses.append(np.array([*p, rng.uniform(-math.pi, math.pi)]))
    kind = KINDS[seed % len(KINDS)]
    form = Formation(formation_offsets(kind, n, 5.0), (-35.0, 0.0), (2.0, 0.0))
    obs = Obstacles(np.array([o[0] for o in obstacles]), np.array([o[1] for o in obstacles]))
    return np.arange(1, n + 1), np.array(poses), form, obs, cluttered


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=40)
    ap.add_argument("--duration", type=float, default=40.0)
    args = ap.parse_args()
    control = ControlParams()
    tally = {False: [0, 0, 0], True: [0, 0, 0]}        # cluttered -> runs, safe, converged
    dmin, cmin = math.inf, math.inf
    t0 = time.perf_counter()
    for seed in range(args.seeds):
        ids, poses, form, obs, cluttered = scenario(seed)
        m = simulate(ids, poses, form, obs, control, RobotParams(),
                     SimOptions(duration=args.duration, record_every=0)
                     ).metrics.summary("seeded", args.duration)
        d = m["min_pair_distance"] if m["min_pair_distance"] is not None else math.inf
        c = m["min_obstacle_clearance"] if m["min_obstacle_clearance"] is not None else math.inf
        dmin, cmin = min(dmin, d), min(cmin, c)
        row = tally[cluttered]
        row[0] += 1
        row[1] += d > control.a and c > control.a
        row[2] += bool(m["converged"])
    for cluttered, (runs, safe, conv) in tally.items():
        print(f"{'cluttered' if cluttered else 'sparse':>9}: {runs} runs, safe {safe}, "
              f"converged {conv}")
    print(f"closest pair {dmin:.3f} m, smallest clearance {cmin:.3f} m, "
          f"{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
