"""SITL swarm timing at 50 Hz for growing swarms (prints a table).

    .venv/bin/python bench/sitl_swarm.py [--sizes 9 18 30 50] [--duration 15] [--near-radius 12]
                                     [--realtime-priority 10]

Each size runs ``boundswarm sitl`` on a grid formation (spacing 5 m, no obstacles) whose
robots start scattered behind their places, with every agent a separate process, the plant
in one process, CAN over udp_multicast and Zenoh through the launcher's router, all on this
machine. Reported per run: deadline misses (all agents), period jitter p50/p99/max over the
agents' p50/p99/max, neighbour-state age (published -> used by the law) p50/p99, mean CPU
share per agent and the plant's, and the safety/convergence outcome. Misses are counted in
the mission (t = 0 .. duration, from the recorded states) and, apart, outside it (start-up
and shut-down).
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def scenario_text(n: int, duration: float, seed: int = 0) -> str:
    rng = np.random.default_rng(seed)
    cols = math.ceil(math.sqrt(n))
    lines = [f'name = "bench{n}"', f"duration = {duration}", "", "[formation]",
             'kind = "grid"', "spacing = 5.0", "center0 = [0.0, 0.0]", "velocity = [1.0, 0.0]",
             ""]
    for i in range(n):
        x = -5.0 * (i // cols) - 8.0 + rng.uniform(-0.8, 0.8)
        y = 5.0 * (i % cols) - 2.5 * (cols - 1) + rng.uniform(-0.8, 0.8)
        lines += ["[[robots]]", f"id = {i + 1}", f"pose = [{x:.2f}, {y:.2f}, 0.0]", ""]
    return "\n".join(lines)


def pct(values, q):
    v = [x for x in values if x is not None]
    return float(np.percentile(v, q)) if v else float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[9, 18, 30, 50])
    parser.add_argument("--duration", type=float, default=15.0)
    parser.add_argument("--realtime-priority", type=int, default=10,
                        help="agents' SCHED_FIFO loop priority (0: normal scheduling)")
    parser.add_argument("--near-radius", type=float, default=0.0,
                        help="agents' near radius [m] (0: full-rate states of every robot)")
    args = parser.parse_args()
    print(f"{'robots':>6} {'misses':>7} {'outside':>7} {'jit p50':>8} {'jit p99':>8} {'jit max':>8} "
          f"{'age p50':>8} {'age p99':>8} {'cpu/agent':>9} {'cpu plant':>9} {'collis.':>7} "
          f"{'converged':>9}")
    for n in args.sizes:
        with tempfile.TemporaryDirectory() as tmp:
            sc = Path(tmp) / f"bench{n}.toml"
            sc.write_text(scenario_text(n, args.duration))
            out = Path(tmp) / "run"
            cmd = [sys.executable, "-m", "hil.cli", "sitl", str(sc), "--out", str(out),
                   "--no-live", "--near-radius", str(args.near_radius),
                   "--realtime-priority", str(args.realtime_priority)]
            proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
            if not (out / "metrics.json").exists():
                print(f"{n:>6} failed (exit {proc.returncode}): {proc.stdout[-500:]}")
                continue
            m = json.loads((out / "metrics.json").read_text())
            s = m["sitl"]
            ages = s["neighbour_age_ms"].values()
            cpu = s["cpu_share"]
            agents = [v for k, v in cpu.items() if k.startswith("agent")]
            plant = sum(v for k, v in cpu.items() if k.startswith("plant"))
            print(f"{n:>6} {s['deadline_misses_in_mission']:>7} "
                  f"{s['deadline_misses'] - s['deadline_misses_in_mission']:>7} "
                  f"{pct(s['jitter_p50_ms_per_agent'].values(), 50):>8.2f} "
                  f"{pct(s['jitter_p99_ms_per_agent'].values(), 50):>8.2f} "
                  f"{max(s['jitter_max_ms_per_agent'].values()):>8.2f} "
                  f"{pct([a['p50'] for a in ages], 50):>8.1f} "
                  f"{pct([a['p99'] for a in ages], 50):>8.1f} "
                  f"{np.mean(agents):>9.1%} {plant:>9.1%} {m['collisions']:>7} "
                  f"{str(m['converged']):>9}", flush=True)


if __name__ == "__main__":
    main()
