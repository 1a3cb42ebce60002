"""Throughput of ``boundswarm campaign`` on campaigns/smoke.toml with 1 and 2 local workers.

    .venv/bin/python bench/campaign_smoke.py [--workers 1 2] [--rounds 2] [--spec FILE]

Each round runs the spec from scratch once per worker count, alternating, into a temporary
folder, and prints per run: the wall time of the whole command (cluster start, warm-up, runs,
report), the cluster's start-up with the kernels' warm-up, the runs' span and runs per minute
(from the folder's sessions.jsonl), and the CPU seconds per run on the workers (from
timings.jsonl), with the machine's load average.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--spec", default=str(ROOT / "campaigns" / "smoke.toml"))
    args = ap.parse_args()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p))
    for r in range(args.rounds):
        for workers in args.workers:
            with tempfile.TemporaryDirectory() as tmp:
                out = Path(tmp) / "campaign"
                started = time.monotonic()
                subprocess.run([sys.executable, "-m", "hil.cli", "campaign", args.spec,
                                "--out", str(out), "--workers", str(workers)], env=env,
                               check=True, stdout=subprocess.DEVNULL)
                total = time.monotonic() - started
                session = json.loads((out / "sessions.jsonl").read_text().splitlines()[-1])
                cpu = [json.loads(line)["cpu_seconds"] for line in
                       (out / "timings.jsonl").read_text().splitlines()]
                print(f"round {r + 1}, {workers} workers: {session['executed']} runs, "
                      f"total {total:.1f} s, start-up {session['startup_seconds']:.1f} s, "
                      f"runs {session['run_seconds']:.1f} s = "
                      f"{session['runs_per_minute']:.0f} runs/min, CPU per run "
                      f"{statistics.mean(cpu):.3f} s (sum {sum(cpu):.1f} s), load "
                      f"{os.getloadavg()[0]:.1f}", flush=True)


if __name__ == "__main__":
    main()
