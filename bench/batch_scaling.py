"""Batch simulator cost per robot-step for growing swarms (prints a table).

    .venv/bin/python bench/batch_scaling.py [--sizes 9 100 1000 10000] [--repeats 3]
    .venv/bin/python bench/batch_scaling.py --governor-cost [--same-states] [--robot FILE]
                                            [--link-delay S]

Each size runs a grid formation (spacing 5 m) moving at 2 m/s through a field of obstacles,
robots starting scattered around their places, T = 0.02 s, 4 physics substeps, metrics on,
no trajectory recording. Reported: median wall time per control period, per robot-step, the
real-time factor (simulated / wall time) and the share spent in the control law. Also the
paper example end to end (20 s simulated). Medians over repeats: the machine is shared.

``--governor-cost``: the safety governor's share of that cost, each size run with the
governor on and off (``[control] governor``), alternating in one process, and the ratio of
the medians (issue 16 asks at most 1.5x). The two runs drive different paths; with
``--same-states`` the control step alone is timed instead, with and without the governor
on the very same states (each period of a run with it, the step without it first, its
results thrown away). ``--robot`` runs a robot profile on the wheels plant instead of the
ideal robot; ``--link-delay`` delays every state exchanged by that many seconds (the
robots otherwise see each other's current states, and the governor counts no data age).
"""
from __future__ import annotations

import argparse
import contextlib
import inspect
import statistics
import time
import types
from collections.abc import Iterator
from pathlib import Path
from unittest import mock

import numpy as np

from agent.config import ControlParams, RobotParams
from agent.formation import Formation, FormationKind, formation_offsets
from firmware_sim import compiled, swarm_step
from firmware_sim.batch import SimOptions, simulate
from firmware_sim.plant import PlantKind
from firmware_sim.world import Obstacles, WorldParams
from hil.files.robot_profile import load_robot_profile
from hil.files.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent


def swarm(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    offsets = formation_offsets(FormationKind.GRID, n, 5.0)
    form = Formation(offsets, (0.0, 0.0), (2.0, 0.0))
    poses = np.column_stack([offsets + rng.uniform(-1.0, 1.0, offsets.shape) - [6.0, 0.0],
                             rng.uniform(-np.pi, np.pi, n)])
    half = np.abs(offsets).max() + 10.0
    k = max(2, n // 20)
    obstacles = Obstacles(rng.uniform([-half + 20, -half], [half + 40, half], (k, 2)),
                          rng.uniform(0.5, 1.5, k))
    return poses, form, obstacles


def run_once(n: int, steps: int, control: ControlParams, robot: RobotParams | None,
             delay: float = 0.0) -> tuple[float, float]:
    """(wall seconds per period, share of time in the law) of one run of the ideal robot
    (``robot`` None) or of ``robot`` on the wheels plant, the robots' states ``delay`` [s]
    late (0: each sees the others' current ones)."""
    poses, form, obstacles = swarm(n)
    world = WorldParams(link_delay=delay) if delay > 0.0 else None
    plant = PlantKind.IDEAL if robot is None else PlantKind.WHEELS
    params = robot if robot is not None else RobotParams()
    t0 = time.perf_counter()
    res = simulate(np.arange(n), poses, form, obstacles, control, params,
                   SimOptions(duration=steps * control.period, record_every=0, plant=plant),
                   clock=time.perf_counter, world=world)
    wall = time.perf_counter() - t0
    return wall / (steps + 1), res.law_seconds / wall


def time_run(n: int, steps: int, repeats: int, robot: RobotParams | None
             ) -> tuple[float, float]:
    """(median wall seconds per period, median share of time in the law)."""
    runs = [run_once(n, steps, ControlParams(), robot) for _ in range(repeats)]
    return statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)


def governor_cost(sizes: list[int], repeats: int, robot: RobotParams | None,
                  same_states: bool = False, delay: float = 0.0) -> None:
    """Print, per size, the cost per robot-step with the governor on and off and the ratio
    of the medians: of whole runs, alternating, or (``same_states``) of the control step
    alone on the states of runs with it (:func:`control_timed`)."""
    print(f"{'robots':>7} {'on us/robot-step':>17} {'off us/robot-step':>18} {'ratio':>6}")
    for n in sizes:
        steps = 500 if n <= 1000 else 100
        on: list[float] = []
        off: list[float] = []
        for _ in range(repeats):
            if same_states:
                spent = {"on": 0.0, "off": 0.0}
                with control_timed(spent):
                    run_once(n, steps, ControlParams(governor=True), robot, delay)
                on.append(spent["on"] / (steps + 1) / n)
                off.append(spent["off"] / (steps + 1) / n)
            else:
                on.append(run_once(n, steps, ControlParams(governor=True), robot, delay)[0] / n)
                off.append(run_once(n, steps, ControlParams(governor=False), robot, delay)[0]
                           / n)
        m_on, m_off = statistics.median(on), statistics.median(off)
        print(f"{n:>7} {m_on * 1e6:>17.2f} {m_off * 1e6:>18.2f} {m_on / m_off:>6.2f}",
              flush=True)


@contextlib.contextmanager
def control_timed(spent: dict[str, float]) -> Iterator[None]:
    """While inside, the batch simulator's compiled control step also runs with the
    governor off on the same inputs (into copies of its outputs), each timed: seconds
    added to ``spent["on"]`` and ``spent["off"]``."""
    kernels = compiled.kernels()
    names = list(inspect.signature(swarm_step.control).parameters)
    law_at = names.index("p")
    outputs = [i for i, name in enumerate(names)
               if name.startswith("out_") or name in ("watch_j", "watch_k")]

    def control(*args):
        off = list(args)
        off[law_at] = args[law_at]._replace(governor=False)
        for i in outputs:
            off[i] = args[i].copy()
        t0 = time.perf_counter()
        kernels.control(*off)
        t1 = time.perf_counter()
        need = kernels.control(*args)
        spent["off"] += t1 - t0
        spent["on"] += time.perf_counter() - t1
        return need

    timed = types.SimpleNamespace(**vars(kernels))
    timed.control = control
    with mock.patch.object(compiled, "kernels", lambda: timed):   # what simulate() looks up
        yield


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[9, 100, 1000, 10000])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--governor-cost", action="store_true",
                        help="time each size with the safety governor on and off")
    parser.add_argument("--same-states", action="store_true",
                        help="with --governor-cost: time the control step alone, with and "
                             "without the governor on the same states")
    parser.add_argument("--robot", metavar="FILE",
                        help="robot profile (robots/*.toml; default: the ideal robot)")
    parser.add_argument("--link-delay", type=float, default=0.0, metavar="S",
                        help="with --governor-cost: the robots' states this late [s]")
    args = parser.parse_args()
    if args.same_states and not args.governor_cost:
        parser.error("--same-states times the governor's cost: give --governor-cost too")
    robot = load_robot_profile(args.robot) if args.robot else None
    if args.governor_cost:
        run_once(9, 10, ControlParams(), robot)        # compile before timing
        governor_cost(args.sizes, args.repeats, robot, args.same_states, args.link_delay)
        return

    sc = load_scenario(ROOT / "scenarios" / "paper.toml")
    paper = []
    for _ in range(max(args.repeats, 3)):
        t0 = time.perf_counter()
        simulate(sc.ids, sc.poses, sc.formation, sc.obstacles, sc.control, sc.robot,
                 SimOptions(duration=sc.duration, record_every=0))
        paper.append(time.perf_counter() - t0)
    print(f"paper example (9 robots, 20 s, T = 0.02 s): median {statistics.median(paper):.3f} s "
          f"compute (target < 0.5 s)\n")

    period = ControlParams().period
    print(f"{'robots':>7} {'ms/period':>10} {'us/robot-step':>14} {'x real time':>12} "
          f"{'law share':>10}")
    for n in args.sizes:
        steps = 500 if n <= 1000 else 100
        wall, share = time_run(n, steps, args.repeats, robot)
        print(f"{n:>7} {wall * 1e3:>10.3f} {wall / n * 1e6:>14.2f} {period / wall:>12.1f} "
              f"{share:>10.0%}")


if __name__ == "__main__":
    main()
