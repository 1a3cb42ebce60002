"""The compiled cost of one neighbour's governor disc, on discs recorded in a real swarm.

    .venv/bin/python bench/disc_replay.py [--robots 300] [--periods 150]
                                          [--robot robots/cart.toml] [--link-delay 0.2]

Runs the world of ``bench/batch_scaling.py`` (a grid at 5 m spacing through obstacles, the
profile on the wheels plant, every state ``--link-delay`` late) interpreted for
``--periods`` periods, recording the arguments of every call of
``agent.discs.neighbour_radii`` (by the period), then times the compiled function over the recorded
calls, in their order (best of 7 passes), and once more with each recorded disc repeated
a thousand times in a row (where branches are always predicted). The figure is what a
disc costs where the batch simulator spends it, unlike a disc of made-up arguments.
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np
from batch_scaling import swarm

import agent.period as period
from agent.config import ControlParams
from agent.params import NeighbourModel
from agent.trail import Splits
from firmware_sim import compiled
from firmware_sim.batch import SimOptions, simulate
from firmware_sim.plant import PlantKind
from firmware_sim.world import WorldParams
from hil.files.robot_profile import load_robot_profile


def record(robots: int, periods: int, robot_file: str, delay: float
           ) -> tuple[np.ndarray, np.ndarray, NeighbourModel]:
    """(arguments (C, 6) but the trail and the model, trails (C, rows, splits), the model)
    of every disc built."""
    rows: list[list[float]] = []
    trails: list[np.ndarray] = []
    models: list[NeighbourModel] = []
    built = period.neighbour_radii

    def recorded(*args):
        rows.append([float(v) for v in args[:6]])
        trails.append(np.array(args[6], dtype=float))
        models.append(args[7])
        return built(*args)

    poses, form, obstacles = swarm(robots)
    control = ControlParams(governor=True)
    period.neighbour_radii = recorded
    try:
        simulate(np.arange(robots), poses, form, obstacles, control,
                 load_robot_profile(robot_file),
                 SimOptions(duration=periods * control.period, record_every=0,
                            compiled=False, plant=PlantKind.WHEELS),
                 world=WorldParams(link_delay=delay) if delay > 0.0 else None)
    finally:
        period.neighbour_radii = built
    if not rows:
        raise SystemExit("no disc was built: give more robots or periods")
    return np.array(rows), np.array(trails), models[0]


def best_ns(loop, rows: np.ndarray, trails: np.ndarray) -> float:
    """The best of 7 passes of ``loop`` over the calls [ns per call]."""
    loop(rows[:2], trails[:2])                   # compile
    best = math.inf
    for _ in range(7):
        t0 = time.perf_counter()
        loop(rows, trails)
        best = min(best, time.perf_counter() - t0)
    return best / len(rows) * 1e9


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", type=int, default=300)
    ap.add_argument("--periods", type=int, default=150)
    ap.add_argument("--robot", default="robots/cart.toml", metavar="FILE")
    ap.add_argument("--link-delay", type=float, default=0.2, metavar="S")
    args = ap.parse_args()
    import numba

    t0 = time.perf_counter()
    rows, trails, model = record(args.robots, args.periods, args.robot, args.link_delay)
    print(f"recorded {len(rows)} discs in {time.perf_counter() - t0:.0f} s "
          f"(median data age {np.median(rows[:, 5]) * 1e3:.0f} ms)", flush=True)
    disc = compiled.kernels().neighbour_radii

    @numba.njit
    def loop(rows, trails):
        total = 0.0
        for i in range(len(rows)):
            r, t = rows[i], trails[i]
            splits = Splits(t[0], t[1], t[2], t[3], t[4], t[5], t[6], t[7], t[8], t[9])
            out = disc(r[0], r[1], r[2], r[3], r[4], r[5], splits, model)
            total += out[1] + out[2] + out[3] + out[4]
        return total

    print(f"compiled neighbour_radii: {best_ns(loop, rows, trails):.0f} ns per disc")
    again = np.repeat(np.arange(0, len(rows), 1000), 1000)
    print(f"each disc a thousand times in a row: "
          f"{best_ns(loop, rows[again], trails[again]):.0f} ns per disc")


if __name__ == "__main__":
    main()
