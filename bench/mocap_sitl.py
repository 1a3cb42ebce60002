"""Pose-source acceptance under the SITL: odometry on slipping wheels, with and without
motion-capture fixes, and a robot whose fixes stop (prints a table, writes JSON).

    .venv/bin/python bench/mocap_sitl.py [--duration 120] [--slip 0.03] [--rate 100]
                                         [--outage-robot 5 --outage-at 60 --outage 1]
                                         [--runs fixes odometry outage] [--out runs/mocap]

Each run is ``boundswarm sitl`` on the paper's scenario (9 robots, two obstacles) on the
SITL's default robot (the cart, 3 m/s, 2 m/s^2) with ``[world] wheel_slip``:

* ``fixes``: a simulated motion-capture system at ``--rate`` Hz (1 mm noise, 10 ms latency,
  1 % dropouts);
* ``odometry``: no fixes, the agents' pose is odometry alone;
* ``outage``: as ``fixes``, with robot ``--outage-robot``'s fixes stopped for ``--outage``
  seconds from ``--outage-at`` (mission time).

Reported per run: each robot's pose error (where its agent believed it was against the
truth) p99 and max, collisions, closest pair, failsafes; for the outage, where the robot was
commanded to HOLD, its speed then, the distance it travelled to rest against its braking
distance (speed held for the drive latency and a period, then braking at the robot's
a_max), and the closest any other robot came to it afterwards.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
MOCAP = """
[mocap]
rate = {rate}
noise = 0.001
heading_noise = 0.002
latency = 0.01
dropout = 0.01
fix_timeout = 0.5
"""
OUTAGE = """[[mocap.outage]]
robot = {robot}
at = {at}
duration = {duration}
"""


def scenario(args: argparse.Namespace, kind: str) -> str:
    text = (ROOT / "scenarios" / "paper.toml").read_text()
    text += f"\n[world]\nseed = 1\nwheel_slip = {args.slip}\n"
    if kind in ("fixes", "outage"):
        text += MOCAP.format(rate=args.rate)
    if kind == "outage":
        text += OUTAGE.format(robot=args.outage_robot, at=args.outage_at,
                              duration=args.outage)
    return text


def outage_figures(run: Path, args: argparse.Namespace, a_max: float, latency: float,
                   period: float) -> dict:
    """Where the robot whose fixes stopped was commanded to HOLD, its travel to rest
    against its braking distance, and how close the others came to it afterwards."""
    traj = np.loadtxt(run / "trajectories.csv", delimiter=",", skiprows=1)
    me = traj[traj[:, 1] == args.outage_robot]          # t, id, x, y, theta, v, u, ...
    held = np.flatnonzero((me[:, 0] >= args.outage_at) & (me[:, 5] == 0.0))
    if not held.size:
        return {"held": False}
    k = held[0]
    if me[k - 1, 0] < args.outage_at:
        return {"held": False, "why": "it stood still already when its fixes stopped"}
    v = abs(me[k - 1, 5])
    rest = me[(me[:, 0] >= me[k, 0] + v / a_max + 1.0)]
    travel = math.hypot(rest[0, 2] - me[k, 2], rest[0, 3] - me[k, 3]) if len(rest) else None
    others = traj[(traj[:, 1] != args.outage_robot) & (traj[:, 0] >= me[k, 0])]
    closest = math.inf
    for t, x, y in others[:, [0, 2, 3]]:
        j = np.searchsorted(me[:, 0], t)
        if j < len(me):
            closest = min(closest, math.hypot(x - me[j, 2], y - me[j, 3]))
    return {"held": True, "hold_at": float(me[k, 0]), "speed": v,
            "travel_to_rest": travel,
            "braking_distance": v * (latency + period) + v * v / (2.0 * a_max),
            "closest_other_after": closest}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=120.0)
    p.add_argument("--slip", type=float, default=0.03)
    p.add_argument("--rate", type=float, default=100.0)
    p.add_argument("--outage-robot", type=int, default=5)
    p.add_argument("--outage-at", type=float, default=60.0)
    p.add_argument("--outage", type=float, default=1.0)
    p.add_argument("--runs", nargs="+", default=["fixes", "odometry", "outage"],
                   choices=["fixes", "odometry", "outage"])
    p.add_argument("--out", default="runs/mocap")
    args = p.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    for kind in args.runs:
        sc = out / f"{kind}.toml"
        sc.write_text(scenario(args, kind))
        run = out / kind
        started, load0 = time.monotonic(), os.getloadavg()[0]
        proc = subprocess.run([sys.executable, "-m", "hil.cli", "sitl", str(sc), "--out",
                               str(run), "--duration", str(args.duration), "--no-live",
                               "--gcs-port", "0"], cwd=ROOT, capture_output=True, text=True)
        m = json.loads((run / "metrics.json").read_text()) if (run / "metrics.json").exists() \
            else None
        if m is None:
            print(f"{kind}: no metrics (exit {proc.returncode})\n{proc.stdout[-2000:]}"
                  f"{proc.stderr[-2000:]}")
            results[kind] = {"exit": proc.returncode}
            continue
        r = m["robot"]
        res = {"exit": proc.returncode, "wall_s": round(time.monotonic() - started, 1),
               "load_1min": [round(load0, 1), round(os.getloadavg()[0], 1)],
               "pose_error": m["pose_error"], "collisions": m["collisions"],
               "min_pair_distance": m["min_pair_distance"],
               "min_clearance": m.get("min_obstacle_clearance"),
               "failsafes": m["sitl"]["failsafes"],
               "deadline_misses_in_mission": m["sitl"]["deadline_misses_in_mission"]}
        if kind == "outage":
            a_max = 2.0 * math.pi * r["wheel_radius"] * r["wheel_ramp"]
            res["outage"] = outage_figures(run, args, a_max, r["drive_latency"], 0.02)
        results[kind] = res
        p99 = [e["p99"] for e in res["pose_error"].values()]
        print(f"{kind}: exit {proc.returncode}, {res['wall_s']} s (load {res['load_1min']}); "
              f"pose error p99 per robot "
              f"[m]: " + " ".join(f"{x:.3f}" for x in p99)
              + f"; worst max {max(e['max'] for e in res['pose_error'].values()):.3f} m; "
              f"collisions {res['collisions']}, closest pair "
              f"{res['min_pair_distance'] or math.nan:.2f} m, "
              f"failsafes {res['failsafes'] or 'none'}, misses "
              f"{res['deadline_misses_in_mission']}")
        if "outage" in res:
            print(f"  outage: {json.dumps(res['outage'])}")
    (out / "results.json").write_text(json.dumps(results, indent=2) + "\n")
    print(f"results: {out / 'results.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
