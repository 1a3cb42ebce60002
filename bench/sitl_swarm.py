"""SITL swarm timing at 50 Hz for growing swarms (prints a table).

    .venv/bin/python bench/sitl_swarm.py [--sizes 9 18 30 50] [--duration 15] [--near-radius 9]
                                     [--realtime-priority 10] [--repeat 3]
                                     [--against REV | --against-python EXE]
                                     [--sitl-args "--router-threads 1"]

Each size runs ``boundswarm sitl`` on a grid formation (spacing 5 m, no obstacles) whose robots
start scattered behind their places, with the agents laid out as ``boundswarm sitl`` does by
default (a process per robot up to 8 robots per core, beyond that shared processes in four tick
groups; ``--sitl-args "--agents-per-process 1"`` keeps one per robot), the plant in one
process, CAN over udp_multicast and Zenoh through the launcher's router, all on this machine.
Reported per run: deadline misses (all agents), period jitter p50/p99/max over the agents'
p50/p99/max, neighbour-state age (published -> used by the law): p50 over the agents' p50s, p99
over their p99s, and the worst agent's p99 with the stage that took most of its oldest 1 %
(``pub``: publish -> router, ``rtr``: router -> the agent's ring, ``held``: in the agent; ``-``
for a commit without the stages), steady CPU in the mission (from /proc, 3 s after the epoch
until 2 s before the end; % of one core) per agent, of the plant, of the launcher (recorder,
status, MAVLink router; and the router when the launcher hosts it), of the router process and
in all (the machine has 200 %), states missing from the recording (the agents' ticks, each
publishing one, less the states in ``run.mcap``), and the safety/convergence outcome. Misses
are the agents' overruns in the mission (t = 0 .. duration) and, apart, outside it (start-up
and shut-down).

``--against REV`` runs REV's launcher (a temporary git worktree) and this checkout's in turn,
and ``--against-python EXE`` this checkout under another interpreter (e.g. another venv's
``bin/python``; that venv needs the project installed) and under this one in turn,
``--repeat`` pairs per size, and ends with the medians of both and their ratios: on a shared
machine only figures measured interleaved compare. ``--sitl-args`` go to this checkout's
``boundswarm sitl`` only (e.g. a variant of its data path). The machine's load average is
printed before and after each run. A shared VM's host can change its speed by half within
minutes, and a small pure-Python loop does not show it (its time stays put while the swarm
slows); the plant's share does (the same work in every run of a size: at 30 robots 13 % of
a core in fast phases, 17–20 % in slow ones), so compare runs of similar plant shares.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from side_by_side import short, worktree  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
STAGE_SHORT = {"publish_to_router": "pub", "router_to_agent": "rtr", "in_agent": "held"}


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


def load() -> str:
    """The 1-minute load average."""
    return f"{os.getloadavg()[0]:.1f}"


def process_cpu(out: Path) -> dict[str, float]:
    """CPU seconds so far of this run's processes (agents, plant, launcher), from /proc."""
    tick = os.sysconf("SC_CLK_TCK")
    total: dict[str, float] = {"agents": 0.0, "plant": 0.0, "launcher": 0.0, "router": 0.0}
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
            stat = Path(f"/proc/{pid}/stat").read_text()
        except OSError:
            continue
        if str(out).encode() not in b" ".join(cmd) or b"hil.cli" not in cmd:
            continue
        kind = {b"agent": "agents", b"plant": "plant", b"sitl": "launcher",
                b"router": "router"}.get(
            cmd[cmd.index(b"hil.cli") + 1])
        if kind:
            fields = stat[stat.rindex(")") + 2:].split()
            total[kind] += (int(fields[11]) + int(fields[12])) / tick
    return total


def interpreter(python: str) -> str:
    """``python``'s version and whether it runs with a shared libpython (slower: docs/
    performance.md, "The interpreter")."""
    probe = ("import platform, sys; maps = open('/proc/self/maps').read(); "
             "print(platform.python_version(), sys._base_executable, "
             "'shared' if 'libpython' in maps else 'static')")
    try:
        out = subprocess.run([python, "-c", probe], capture_output=True, text=True, timeout=30,
                             check=True).stdout.split()
    except (OSError, subprocess.SubprocessError) as exc:
        sys.exit(f"cannot run the interpreter {python}: {exc}")
    return f"Python {out[0]} ({out[1]}, {out[2]} libpython)"


def run_once(n: int, args: argparse.Namespace, tmp: Path, checkout: Path,
             extra: list[str], python: str) -> tuple[dict, dict] | str:
    """One SITL run of ``n`` robots with ``checkout``'s code, ``extra`` arguments and the
    interpreter ``python``: (metrics, steady CPU shares in the mission) or why not."""
    sc = tmp / f"bench{n}.toml"
    sc.write_text(scenario_text(n, args.duration))
    out = tmp / "run"
    cmd = [python, "-m", "hil.cli", "sitl", str(sc), "--out", str(out), "--no-live",
           "--near-radius", str(args.near_radius),
           "--realtime-priority", str(args.realtime_priority), *extra]
    proc = subprocess.Popen(cmd, cwd=checkout, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, env={**os.environ, "PYTHONUNBUFFERED": "1",
                                            "PYTHONPATH": str(checkout)})
    assert proc.stdout is not None                 # (stdout=PIPE)
    lines, cpu = [], {}
    try:
        for line in proc.stdout:
            lines.append(line)
            if line.startswith("mission published"):    # steady state: 3 s in .. 2 s before end
                time.sleep(args.lead + 3.0)
                t0, c0 = time.monotonic(), process_cpu(out)
                time.sleep(max(args.duration - 5.0, 1.0))
                t1, c1 = time.monotonic(), process_cpu(out)
                cpu = {k: (c1[k] - c0[k]) / (t1 - t0) for k in c0}
        proc.wait(timeout=600)
    finally:
        if proc.poll() is None:         # Ctrl-C first: the launcher ends its children
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=120)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    if not (out / "metrics.json").exists():
        return f"failed (exit {proc.returncode}): {''.join(lines)[-500:]}"
    m = json.loads((out / "metrics.json").read_text())
    m["unrecorded"] = unrecorded(out)
    return m, cpu


def unrecorded(out: Path) -> int:
    """States the agents published (one per tick, from their statistics) that ``run.mcap``
    lacks: the same count for any commit's run folder."""
    from mcap.reader import make_reader
    with open(out / "run.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    if summary is None or summary.statistics is None:
        return -1
    counts = summary.statistics.channel_message_counts
    recorded = {c.topic: counts.get(cid, 0) for cid, c in summary.channels.items()}
    missing = 0
    for path in (out / "logs").glob("agent_*.json"):
        st = json.loads(path.read_text())
        got = sum(n for topic, n in recorded.items()
                  if topic.endswith(f"/robot/{st['robot_id']}/state"))
        missing += max(st["agent"]["ticks"] - got, 0)
    return missing


HEADER = (f"{'commit':>9} {'robots':>6} {'misses':>7} {'outside':>7} {'jit p50':>8} "
          f"{'jit p99':>8} {'jit max':>8} {'age p50':>8} {'age p99':>8} {'worst':>7} "
          f"{'stage':>11} {'cpu/agent':>9} {'plant':>6} {'launch':>6} {'router':>6} "
          f"{'total':>6} {'unrec.':>6} {'collis.':>7} {'converged':>9} {'load':>9}")


def row(label: str, n: int, m: dict, cpu: dict, loads: str) -> tuple[str, float]:
    """One table row of a run's metrics, and its worst agent's age p99 [ms]."""
    s = m["sitl"]
    ages = s["neighbour_age_ms"]
    worst = max((a["p99"] for a in ages.values() if a["p99"] is not None), default=math.nan)
    w = s.get("neighbour_age_worst")
    stage = (f"{STAGE_SHORT[w['stage']]} {w['stage_tail_ms'][w['stage']]:.0f}"
             if w and w["stage"] else "-")
    unrec = str(m["unrecorded"])
    return (f"{label:>9} {n:>6} {s['deadline_misses_in_mission']:>7} "
            f"{s['deadline_misses'] - s['deadline_misses_in_mission']:>7} "
            f"{pct(s['jitter_p50_ms_per_agent'].values(), 50):>8.2f} "
            f"{pct(s['jitter_p99_ms_per_agent'].values(), 50):>8.2f} "
            f"{max(s['jitter_max_ms_per_agent'].values()):>8.2f} "
            f"{pct([a['p50'] for a in ages.values()], 50):>8.1f} "
            f"{pct([a['p99'] for a in ages.values()], 50):>8.1f} {worst:>7.1f} {stage:>11} "
            f"{cpu.get('agents', math.nan) / n:>9.1%} {cpu.get('plant', math.nan):>6.0%} "
            f"{cpu.get('launcher', math.nan):>6.0%} {cpu.get('router', math.nan):>6.0%} "
            f"{sum(cpu.values()) if cpu else math.nan:>6.0%} {unrec:>6} "
            f"{m['collisions']:>7} {str(m['converged']):>9} {loads:>9}"), worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[9, 18, 30, 50])
    parser.add_argument("--duration", type=float, default=15.0)
    parser.add_argument("--repeat", type=int, default=1, help="runs (pairs) per size")
    parser.add_argument("--realtime-priority", type=int, default=10,
                        help="agents' SCHED_FIFO loop priority (0: normal scheduling)")
    parser.add_argument("--near-radius", type=float, default=0.0,
                        help="agents' near radius [m] (0: full-rate states of every robot)")
    parser.add_argument("--against", metavar="REV",
                        help="also run REV's launcher, alternately with this checkout's")
    parser.add_argument("--against-python", metavar="EXE",
                        help="also run this checkout under the interpreter EXE, alternately")
    parser.add_argument("--sitl-args", default="",
                        help="further arguments of this checkout's boundswarm sitl")
    args = parser.parse_args()
    args.lead = 1.5                        # s, the launcher's mission lead time
    # SIGTERM as Ctrl-C: the run in progress and REV's worktree are ended on the way out
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    if args.against and args.against_python:
        parser.error("--against and --against-python compare one thing at a time")
    print(f"this: {interpreter(sys.executable)}", flush=True)
    if args.against_python:
        print(f"python: {interpreter(args.against_python)}", flush=True)
    print(HEADER, flush=True)
    with (worktree(args.against) if args.against else contextlib.nullcontext()) as other:
        runs = [("this", ROOT, shlex.split(args.sitl_args), sys.executable)]
        if other is not None:
            runs.insert(0, (short(args.against), other, [], sys.executable))
        if args.against_python:
            runs.insert(0, ("python", ROOT, shlex.split(args.sitl_args), args.against_python))
        for n in args.sizes:
            worst: dict[str, list[float]] = {label: [] for label, *_ in runs}
            clean = dict.fromkeys(worst, 0)
            for _ in range(args.repeat):
                for label, checkout, extra, python in runs:
                    before = load()
                    with tempfile.TemporaryDirectory() as tmp:
                        got = run_once(n, args, Path(tmp), checkout, extra, python)
                    loads = f"{before}/{load()}"
                    if isinstance(got, str):
                        print(f"{label:>9} {n:>6} {got} (load {loads})", flush=True)
                        continue
                    line, w = row(label, n, *got, loads)
                    print(line, flush=True)
                    worst[label].append(w)
                    clean[label] += got[0]["sitl"]["deadline_misses_in_mission"] == 0
            for label in worst:
                print(f"{label:>9} {n:>6} robots: {clean[label]} of {args.repeat} runs without "
                      f"a missed period in the mission; worst agent's age p99, median "
                      f"{pct(worst[label], 50):.1f} ms of {worst[label]}", flush=True)
            if len(runs) > 1 and worst["this"] and worst[runs[0][0]]:
                print(f"{'':>9} {n:>6} robots: worst age p99, this / {runs[0][0]}: "
                      f"{pct(worst['this'], 50) / pct(worst[runs[0][0]], 50):.2f}", flush=True)


if __name__ == "__main__":
    main()
