"""Cost of the governor's disc of one neighbour (agent.discs.neighbour_radii, interpreted,
as an agent runs it for every neighbour every period), by the age of the neighbour's data.

20 neighbours round this robot at 3-7 m, each driving away from it at the places' pace
(this robot behind every one: the dearest case, A10's stop strip) while this robot drives
on at the same pace; the best of several timings of 200 rounds, in µs per neighbour.

    .venv/bin/python bench/neighbour_radii.py [--robot robots/cart.toml] [--pace 1.5]
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agent.config import ControlParams, RobotParams  # noqa: E402
from agent.discs import neighbour_radii  # noqa: E402
from agent.params import LawParams, NeighbourModel  # noqa: E402
from agent.trail import SPLITS, straight  # noqa: E402
from hil.files.robot_profile import load_robot_profile  # noqa: E402

NEIGHBOURS, ROUNDS, REPEATS = 20, 200, 7
AGES = (0.0, 0.05, 0.2, 0.5)     # s


def per_neighbour_us(robot_file: str | None, pace: float, age: float) -> float:
    """The best time [µs] of one neighbour_radii call over REPEATS timings."""
    control = ControlParams()
    robot = load_robot_profile(robot_file) if robot_file else RobotParams()
    model = NeighbourModel.of(LawParams.of(control, robot), control.a, control.period, 1.0,
                              robot.watchdog_timeout)
    trail = straight(pace, 0.0, 1.0, age, SPLITS)   # this robot, along y at the pace
    calls = []
    for n in range(NEIGHBOURS):
        bearing, r = 2.0 * math.pi * n / NEIGHBOURS, 3.0 + 0.2 * n
        calls.append((-r * math.cos(bearing), -r * math.sin(bearing), bearing))
    best = math.inf
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        for _ in range(ROUNDS):
            for rel_x, rel_y, heading in calls:
                neighbour_radii(rel_x, rel_y, heading, pace, 0.1, age, trail, model)
        best = min(best, (time.perf_counter() - t0) / (ROUNDS * NEIGHBOURS))
    return best * 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", help="robot profile (robots/*.toml); default the SITL robot")
    ap.add_argument("--pace", type=float, default=1.5, help="the robots' speed [m/s]")
    args = ap.parse_args()
    for age in AGES:
        us = per_neighbour_us(args.robot, args.pace, age)
        print(f"neighbour_radii, data {age * 1e3:.0f} ms old, {NEIGHBOURS} neighbours "
              f"driving away: {us:.2f} us per neighbour")


if __name__ == "__main__":
    main()
