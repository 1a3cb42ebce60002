"""Turn a SITL recording (MCAP) into the run data and metrics that ``sim`` produces.

Ground truth (``truth`` messages from the plant) gives the robots' poses; the agents' own
``state`` messages give the commanded (v, u), the mode and the reference they used. Both are
resampled on the control period from the mission epoch (latest message at or before each
instant). Distances and collisions are checked at every truth sample, tracking and
convergence at every control period, with the same :class:`RunMetrics` as the batch
simulator. A robot whose agent was killed (``[[world.kill]]``) counts for safety all along
and for convergence only before its death, as in the batch simulator.
"""
from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from agent.progress import TOLERANCE_MARGIN
from firmware_sim.metrics import RunMetrics
from firmware_sim.swarm_step import period_summary
from firmware_sim.world import Obstacles
from hil.files.run_folder import RunData, finite_or_nan
from hil.files.scenario import Scenario
from hil.ground.recorder import read_messages


class RecordingError(ValueError):
    """The recording lacks what a report needs (mission, truth or states of a robot)."""


def _series(rows: list[tuple[float, list[float]]]) -> tuple[np.ndarray, np.ndarray]:
    rows.sort(key=lambda r: r[0])
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows])


def _at(times: np.ndarray, values: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Latest value at or before each t (the first one before the first sample)."""
    idx = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1)
    return values[idx]


def _pose_at(times: np.ndarray, values: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Truth (x, y, theta) at each t: positions interpolated between the samples stamped
    before and after t (held before the first and after the last), heading of the sample
    at or before t. A truth sample is stamped when the robot was there, which may be well
    before it is received (a multi-host world hears remote wheels late): holding the last
    one would show a robot behind where it was."""
    out = _at(times, values, t)[:, :3].copy()
    out[:, 0] = np.interp(t, times, values[:, 0])
    out[:, 1] = np.interp(t, times, values[:, 1])
    return out


def _pose_error(truth_t: np.ndarray, truth: np.ndarray, state_t: np.ndarray,
                state: np.ndarray, duration: float) -> np.ndarray:
    """Distances [m] in the mission between where a robot's agent said it was (its states'
    x, y, columns 5 and 6) and its truth (interpolated) at the states' stamps."""
    inside = (state_t >= 0.0) & (state_t <= duration)
    ts, xy = state_t[inside], state[inside][:, 5:7]
    return np.hypot(xy[:, 0] - np.interp(ts, truth_t, truth[:, 0]),
                    xy[:, 1] - np.interp(ts, truth_t, truth[:, 1]))


def pose_error_summary(errors: np.ndarray) -> dict[str, float]:
    """p50, p99 and max [m] of a robot's pose errors (0 without any)."""
    if not errors.size:
        return {"p50": 0.0, "p99": 0.0, "max": 0.0}
    return {"p50": float(np.percentile(errors, 50)), "p99": float(np.percentile(errors, 99)),
            "max": float(errors.max())}


def missed_in(loop_stats: dict, start: float, end: float) -> int:
    """Periods a loop skipped (its ``overrun_events``, UNIX times) between ``start`` and
    ``end`` [s]: the deadline misses of a mission, apart from start-up and shut-down. Those
    past the loop's event log (``overruns_unlogged``) are counted in, as they may be."""
    return (sum(n for t, n in loop_stats["overrun_events"] if start <= t <= end)
            + loop_stats.get("overruns_unlogged", 0))


def analyse_recording(path: Path, sc: Scenario, killed: Mapping[int, float] | None = None
                      ) -> tuple[RunData, RunMetrics, dict]:
    """(run data on the control period, metrics, extras: the epoch, and each robot's pose
    error p50/p99/max [m] by id) of a recording.
    ``killed``: robot id -> mission time [s] its agent was killed (default: the scenario's
    ``[[world.kill]]`` within its duration)."""
    if killed is None:
        killed = {k.robot: k.at for k in sc.world.kill if k.at <= sc.duration}
    truth, states = defaultdict(list), defaultdict(list)
    epoch = None
    for _topic, kind, _log_t, msg in read_messages(path):
        if kind == "mission" and epoch is None:
            epoch = msg["epoch"]
        elif kind == "truth":
            truth[msg["robot_id"]].append((msg["stamp"], [msg["x"], msg["y"], msg["theta"],
                                                          msg["v"], msg["u"]]))
        elif kind == "state":
            states[msg["robot_id"]].append((msg["stamp"], [msg["v"], msg["u"], msg["mode"],
                                                           msg["x_d"], msg["y_d"], msg["x"],
                                                           msg["y"], msg.get("slot", -1)]))
    if epoch is None:
        raise RecordingError(f"{path}: no mission message; was the mission started?")
    missing = [int(i) for i in sc.ids if not truth.get(int(i)) or not states.get(int(i))]
    if missing:
        raise RecordingError(f"{path}: no truth or no state messages for robot(s) {missing}")

    T = sc.control.period
    t = np.arange(int(round(sc.duration / T)) + 1) * T
    n = len(sc.ids)
    pose = np.zeros((len(t), n, 3))
    v, u = np.zeros((len(t), n)), np.zeros((len(t), n))
    mode = np.zeros((len(t), n), dtype=int)
    slots = np.zeros((len(t), n), dtype=int)   # each robot's place (agent.exchange)
    truth_t = []
    truth_series = {}
    pose_errors: dict[int, dict[str, float]] = {}
    for j, rid in enumerate(sc.ids):
        tt, tv = _series(truth[int(rid)])
        st, sv = _series(states[int(rid)])
        truth_series[j] = (tt - epoch, tv)
        truth_t.append(tt - epoch)
        pose[:, j] = _pose_at(tt - epoch, tv, t)
        s = _at(st - epoch, sv, t)
        v[:, j], u[:, j], mode[:, j] = s[:, 0], s[:, 1], s[:, 2].astype(int)
        slots[:, j] = np.where(s[:, 7] >= 0, s[:, 7], j)    # none published: its own
        pose_errors[int(rid)] = pose_error_summary(
            _pose_error(tt - epoch, tv, st - epoch, sv, sc.duration))
    refs = [sc.formation.reference(tk) for tk in t]
    ref = np.stack([r[0][slots[k]] for k, r in enumerate(refs)])
    ref_vel = np.stack([r[1][slots[k]] for k, r in enumerate(refs)])

    metrics = RunMetrics(ids=sc.ids, a=sc.control.a)
    metrics.killed = sorted(int(rid) for rid in killed)
    metrics.max_pose_error = max(e["max"] for e in pose_errors.values())
    death = np.array([killed.get(int(rid), np.inf) for rid in sc.ids])     # mission time [s]
    # geometry at every truth sample of any robot, all pairs, all obstacles
    samples = np.unique(np.concatenate(truth_t))
    samples = samples[(samples >= 0.0) & (samples <= sc.duration)]
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)], dtype=int
                     ).reshape(-1, 2)
    obstacles: Obstacles = sc.obstacles
    robots = np.arange(n)
    for ts in samples:
        pos = np.stack([_at(*truth_series[j], np.array([ts]))[0, :2] for j in range(n)])
        metrics.observe_geometry(float(ts), pos, pairs, robots, obstacles.clearance(pos))
    last_mode, alive = np.zeros(n), np.ones(n, bool)
    for k, tk in enumerate(t):
        np.less(tk, death, out=alive)
        cmd = np.column_stack([v[k], u[k], mode[k]]).astype(float)
        err, within = np.zeros(n), np.zeros(n, bool)
        max_v, max_u, switches, all_within = period_summary(
            pose[k], cmd, np.column_stack([ref[k], ref_vel[k]]), sc.control.K,
            TOLERANCE_MARGIN, k == 0, alive, last_mode, err, within)
        metrics.observe_places(slots[k], slots[max(k - 1, 0)], alive)
        metrics.observe_period(float(tk), max_v, max_u, switches, err, within, all_within)
    data = RunData(ids=sc.ids, t=t, pose=pose, v=v, u=u, mode=mode, ref=ref,
                   dist_t=np.asarray(metrics.geometry_t),
                   d_min=finite_or_nan(metrics.geometry_dmin),
                   clearance_min=finite_or_nan(metrics.geometry_clear))
    return data, metrics, {"epoch": epoch, "pose_error": pose_errors,
                           "truth_gap": truth_gap(samples, sc.duration)}


def truth_gap(samples: np.ndarray, duration: float) -> dict[str, float]:
    """The longest time [s] without a truth sample in the mission [0, duration] (the plant
    publishes every 10 ms), and its start ``at`` [s]: a stall of the machine, or its wall
    clock jumping (a VM paused and resumed), during which the robots stood still while the
    formation's reference, set on the wall clock, moved on. The mission's start and end
    count as samples: a stall at the end leaves the last truth well before it."""
    edges = np.concatenate([[0.0], samples, [duration]])
    gaps = np.diff(edges)
    k = int(np.argmax(gaps))
    return {"seconds": float(gaps[k]), "at": float(edges[k])}
