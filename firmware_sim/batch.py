"""The batch simulator: every robot of a swarm stepped in one process.

Each control period: references at t, per-robot sensing (neighbours and obstacles inside the
sensing range only), the one law of the agents for every robot, then the plant integrated
over ``substeps`` physics steps with distances and clearances checked at each. The period
is :mod:`firmware_sim.swarm_step`, compiled with numba together with the law when numba is
installed (:mod:`firmware_sim.compiled`), interpreted otherwise: the same source either way.
Time is simulated: a run is deterministic and as fast as the CPU allows.
"""
from __future__ import annotations

import logging
import math
import types
from dataclasses import dataclass
from typing import Callable

import numpy as np

from agent.config import ControlParams, RobotParams
from agent.formation import Formation
from agent.law import LawParams
from firmware_sim import compiled, swarm_step
from firmware_sim.metrics import TOLERANCE_MARGIN, RunMetrics
from firmware_sim.plant import PlantKind
from firmware_sim.world import Obstacles

log = logging.getLogger(__name__)

TRAJECTORY_COLUMNS = ("t", "id", "x", "y", "theta", "v", "u", "mode", "x_d", "y_d")


@dataclass(frozen=True)
class SimOptions:
    """How to run a batch simulation (not what to simulate)."""

    duration: float                      # s
    sensing_range: float = 8.0           # m, neighbour centre / obstacle surface distance
    substeps: int = 4                    # physics steps per control period
    plant: PlantKind = PlantKind.IDEAL
    record_every: int = 1                # record one control period in this many; 0: none
    compiled: bool | None = None         # numba; None: when it is installed

    def __post_init__(self) -> None:
        if not (self.duration > 0 and math.isfinite(self.duration)):
            raise ValueError(f"duration must be a positive number of seconds, "
                             f"got {self.duration!r}")
        if self.sensing_range <= 0:
            raise ValueError(f"sensing_range must be > 0 m, got {self.sensing_range!r}")
        if self.substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {self.substeps!r}")
        if self.record_every < 0:
            raise ValueError(f"record_every must be >= 0, got {self.record_every!r}")


@dataclass
class SimResult:
    """Recorded trajectories (R records x N robots) and the run's metrics."""

    ids: np.ndarray
    t: np.ndarray            # (R,) s
    pose: np.ndarray         # (R, N, 3)
    v: np.ndarray            # (R, N) m/s, commanded
    u: np.ndarray            # (R, N) rad/s, commanded
    mode: np.ndarray         # (R, N) int8, agent.law.Mode
    ref: np.ndarray          # (R, N, 2) m
    metrics: RunMetrics
    law_seconds: float = 0.0  # wall time spent in the law (for benchmarks)


def _engine(options: SimOptions) -> types.SimpleNamespace | types.ModuleType:
    """The compiled kernels, or the interpreted module when numba is absent or not wanted."""
    want = options.compiled
    if want is None:
        want = compiled.available()
        if not want:
            log.warning("numba is not installed (pip install 'boundswarm[sim]'): the batch "
                        "simulator runs the law interpreted, far slower")
    elif want and not compiled.available():
        raise RuntimeError("SimOptions.compiled: numba is not installed "
                           "(pip install 'boundswarm[sim]')")
    return compiled.kernels() if want else swarm_step


PARALLEL_MIN = 500   # robots; below, waking threads costs more than it saves


def simulate(ids: np.ndarray, poses0: np.ndarray, formation: Formation, obstacles: Obstacles,
             control: ControlParams, robot: RobotParams, options: SimOptions,
             progress: Callable[[float], None] | None = None,
             clock: Callable[[], float] | None = None) -> SimResult:
    """Run the swarm from ``poses0`` (N, 3) for ``options.duration`` seconds.

    ``progress`` is called with the completed fraction about a hundred times; ``clock``
    (e.g. ``time.perf_counter``) is used, when given, to time sensing and the law for
    benchmarks.
    """
    ids = np.asarray(ids)
    pose = np.array(poses0, dtype=float).reshape(-1, 3)
    n = len(pose)
    if len(formation.offsets) != n:
        raise ValueError(f"formation has {len(formation.offsets)} places for {n} robots")
    k = _engine(options)
    if k is not swarm_step:
        compiled.use_threads(n >= PARALLEL_MIN)
    T = control.period
    steps = int(round(options.duration / T))
    params = LawParams.of(control)
    offsets = np.ascontiguousarray(formation.offsets, dtype=float).reshape(n, 2)
    motion = np.array([*formation.center0, *formation.velocity, formation.omega], dtype=float)
    obs = np.column_stack([obstacles.centers.reshape(-1, 2), obstacles.radii]).astype(float)
    ideal = options.plant is PlantKind.IDEAL
    metrics = RunMetrics(ids=ids, a=control.a)
    every = options.record_every
    n_rec = (steps // every + 1) if every else 0
    rec_t = np.zeros(n_rec)
    rec_pose = np.zeros((n_rec, n, 3))
    rec_v, rec_u = np.zeros((n_rec, n)), np.zeros((n_rec, n))
    rec_mode = np.zeros((n_rec, n), np.int8)
    rec_ref = np.zeros((n_rec, n, 2))
    S = options.substeps
    dt = T / S
    report_every = max(1, steps // 100)
    law_seconds = 0.0
    reach = max(control.v_max, robot.v_wheel_max) * T   # m, farthest move per period

    mem_f, mem_i = np.zeros((n, 5)), np.zeros((n, 3), np.int64)
    new_f, new_i = np.zeros((n, 5)), np.zeros((n, 3), np.int64)
    cmd, ref, near = np.zeros((n, 3)), np.zeros((n, 4)), np.zeros((n, 2))
    last_mode, err, within = np.zeros(n), np.zeros(n), np.zeros(n, bool)
    # wheels plant: drive latency in whole substeps; the commands of the last substeps, at
    # rest before the first period
    lag = 0 if ideal else int(round(robot.drive_latency / dt))
    issued = np.zeros((S + lag, n, 2))
    wheels = np.zeros((n, 2))
    pos = np.zeros((S + 1, n, 2))
    dmin, cmin = np.zeros(S + 1), np.zeros(S + 1)
    cap, watch_cap = 32, 8      # sensed per robot, watched per robot (grown when needed)
    watch_j, watch_k = np.empty((n, watch_cap), np.int64), np.empty((n, watch_cap), np.int64)
    hit_j, hit_k = np.zeros((n, watch_cap), bool), np.zeros((n, watch_cap), bool)
    for step in range(steps + 1):
        t = step * T
        t0 = clock() if clock else 0.0
        while True:
            need, need_watch = k.control(pose, mem_f, mem_i, offsets, motion, t, obs, params, T,
                                         options.sensing_range, control.a, reach, cap,
                                         watch_cap, cmd, ref, new_f, new_i, near, watch_j,
                                         watch_k)
            if need <= cap and need_watch <= watch_cap:
                break
            cap, watch_cap = max(cap, int(need)), max(watch_cap, int(need_watch))
            watch_j = np.empty((n, watch_cap), np.int64)
            watch_k = np.empty((n, watch_cap), np.int64)
            hit_j, hit_k = np.zeros((n, watch_cap), bool), np.zeros((n, watch_cap), bool)
        if clock:
            law_seconds += clock() - t0
        mem_f, new_f, mem_i, new_i = new_f, mem_f, new_i, mem_i
        v, u, mode = cmd[:, 0], cmd[:, 1], cmd[:, 2]       # views, overwritten next period
        max_v, max_u, switches, all_within = k.period_summary(
            pose, cmd, ref, control.K, TOLERANCE_MARGIN, step == 0, last_mode, err, within)
        metrics.observe_period(t, max_v, max_u, switches, err, within, all_within)
        if every and step % every == 0:
            r = step // every
            rec_t[r], rec_pose[r], rec_v[r], rec_u[r] = t, pose, v, u
            rec_mode[r], rec_ref[r] = mode, ref[:, :2]
        last = step == steps
        first = 0 if step == 0 else 1
        # the pairs and obstacles that could be the closest or closer than a this period
        pair_limit = max(float(near[:, 0].min(initial=np.inf)), control.a) + 4.0 * reach
        clear_limit = max(float(near[:, 1].min(initial=np.inf)), 0.0) + 2.0 * reach
        watched = (near[:, 0] <= pair_limit) | (near[:, 1] <= clear_limit)
        # the commands the drivers follow in each substep (issued a drive latency earlier)
        issued[:-S] = issued[S:]
        issued[-S:] = cmd[:, :2]
        if last:
            pos[0] = pose[:, :2]
        else:
            k.advance(pose, issued[len(issued) - S - lag:len(issued) - lag], wheels, ideal,
                      robot.wheel_radius, robot.wheel_base, robot.wheel_speed_limit,
                      robot.wheel_ramp, dt, S, watched, pos)
        n_sub = 1 if last else S + 1
        hits = k.geometry(pos[:n_sub], watch_j, watch_k, obs, control.a, first, pair_limit,
                          clear_limit, watched, dmin, cmin, hit_j, hit_k)
        pairs: list[tuple[int, int]] = []
        inside: list[int] = []
        if hits:
            pairs = [(int(ids[i]), int(ids[watch_j[i, w]])) for i, w in zip(*np.nonzero(hit_j))]
            inside = [int(ids[i]) for i in np.flatnonzero(hit_k.any(axis=1))]
            hit_j[:], hit_k[:] = False, False
        for s in range(first, n_sub):
            metrics.observe_extremes(t + s * dt, float(dmin[s]), float(cmin[s]), pairs, inside)
        if last:
            break
        if progress and step % report_every == 0:
            progress(step / steps)
    if progress:
        progress(1.0)
    return SimResult(ids=ids, t=rec_t, pose=rec_pose, v=rec_v, u=rec_u, mode=rec_mode,
                     ref=rec_ref, metrics=metrics, law_seconds=law_seconds)
