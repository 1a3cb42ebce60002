"""The batch simulator: every robot of a swarm stepped in one process, vectorised.

Each control period: references at t, per-robot sensing (neighbours and obstacles inside the
sensing range only), one call of the same pure law the agent process runs, then the plant
integrated over ``substeps`` physics steps with distances and clearances checked at each.
Time is simulated: a run is deterministic and as fast as the CPU allows.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from agent.config import ControlParams, RobotParams
from agent.formation import Formation
from agent.law import LawInput, LawMemory, control_step
from firmware_sim.metrics import RunMetrics, tolerance
from agent.kinematics import integrate_arc
from firmware_sim.plant import IdealPlant, PlantKind, make_plant
from firmware_sim.world import Obstacles, Sensed, Sensing

TRAJECTORY_COLUMNS = ("t", "id", "x", "y", "theta", "v", "u", "mode", "x_d", "y_d")


@dataclass(frozen=True)
class SimOptions:
    """How to run a batch simulation (not what to simulate)."""

    duration: float                      # s
    sensing_range: float = 8.0           # m, neighbour centre / obstacle surface distance
    substeps: int = 4                    # physics steps per control period
    plant: PlantKind = PlantKind.IDEAL
    record_every: int = 1                # record one control period in this many; 0: none

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


def simulate(ids: np.ndarray, poses0: np.ndarray, formation: Formation, obstacles: Obstacles,
             control: ControlParams, robot: RobotParams, options: SimOptions,
             progress: Callable[[float], None] | None = None,
             clock: Callable[[], float] | None = None) -> SimResult:
    """Run the swarm from ``poses0`` (N, 3) for ``options.duration`` seconds.

    ``progress`` is called with the completed fraction about a hundred times; ``clock``
    (e.g. ``time.perf_counter``) is used, when given, to time the law for benchmarks.
    """
    ids = np.asarray(ids)
    pose = np.array(poses0, dtype=float)
    n = len(pose)
    if len(formation.offsets) != n:
        raise ValueError(f"formation has {len(formation.offsets)} places for {n} robots")
    T = control.period
    steps = int(round(options.duration / T))
    plant = make_plant(options.plant, robot, n)
    memory = LawMemory.initial(n)
    metrics = RunMetrics(ids=ids, a=control.a)
    every = options.record_every
    n_rec = (steps // every + 1) if every else 0
    rec_t = np.zeros(n_rec)
    rec_pose = np.zeros((n_rec, n, 3))
    rec_v, rec_u = np.zeros((n_rec, n)), np.zeros((n_rec, n))
    rec_mode = np.zeros((n_rec, n), np.int8)
    rec_ref = np.zeros((n_rec, n, 2))
    dt = T / options.substeps
    report_every = max(1, steps // 100)
    law_seconds = 0.0
    sensing = Sensing(obstacles, options.sensing_range)
    step_reach = max(control.v_max, robot.v_wheel_max) * T   # m, farthest move per period

    for k in range(steps + 1):
        t = k * T
        ref, ref_vel = formation.reference(t)
        seen = sensing(pose[:, :2])
        inp = LawInput(pose=pose, ref=ref,
                       nbr_pos=np.take(np.ascontiguousarray(pose[:, :2]), seen.nbr_idx, axis=0),
                       nbr_valid=seen.nbr_valid,
                       obs_center=obstacles.centers[seen.obs_idx],
                       obs_radius=obstacles.radii[seen.obs_idx], obs_valid=seen.obs_valid)
        t0 = clock() if clock else 0.0
        out = control_step(inp, memory, control)
        if clock:
            law_seconds += clock() - t0
        memory = out.memory
        err = np.hypot(pose[:, 0] - ref[:, 0], pose[:, 1] - ref[:, 1])
        metrics.observe_control(t, err, tolerance(ref_vel, control.K), out.v, out.u, out.mode)
        if every and k % every == 0:
            r = k // every
            rec_t[r], rec_pose[r], rec_v[r], rec_u[r] = t, pose, out.v, out.u
            rec_mode[r], rec_ref[r] = out.mode, ref
        watch = _Watch(pose[:, :2], seen, obstacles, control.a, step_reach)
        if k == 0:
            watch.observe(metrics, t, pose)
        if k == steps:
            break
        if isinstance(plant, IdealPlant):
            # exact arcs: the substeps are needed only for the watched robots
            m = watch.members
            for s in range(1, options.substeps):
                sub = integrate_arc(pose[m], out.v[m], out.u[m], s * dt)
                watch.observe_members(metrics, t + s * dt, sub[:, :2])
            pose = integrate_arc(pose, out.v, out.u, T)
            watch.observe(metrics, t + T, pose)
        else:
            for s in range(1, options.substeps + 1):
                pose, _, _ = plant.step(pose, out.v, out.u, dt)
                watch.observe(metrics, t + s * dt, pose)
        if progress and k % report_every == 0:
            progress(k / steps)
    if progress:
        progress(1.0)
    return SimResult(ids=ids, t=rec_t, pose=rec_pose, v=rec_v, u=rec_u, mode=rec_mode,
                     ref=rec_ref, metrics=metrics, law_seconds=law_seconds)


class _Watch:
    """The pairs and robot-obstacle entries worth checking during one control period.

    Robots move at most ``v_bound * T`` per period, so a pair farther apart at the start than
    max(closest pair, a) + 4 v_bound T can be neither the closest pair nor closer than a during
    the period (likewise for obstacles with 2 v_bound T): the minimum and the collisions found
    on the watched subset at every physics step are exact.
    """

    def __init__(self, pos: np.ndarray, seen: Sensed, obstacles: Obstacles, a: float,
                 step_reach: float):
        d = seen.pair_dist
        keep = d <= max(float(d.min(initial=np.inf)), a) + 4.0 * step_reach
        self.pairs = seen.pairs[keep]
        clear = self._clear(pos, seen.obs_idx, seen.obs_valid, obstacles)
        low = clear.min(axis=1, initial=np.inf)
        self.robots = np.flatnonzero(low <= max(float(low.min(initial=np.inf)), 0.0)
                                     + 2.0 * step_reach)
        self.obs_idx = seen.obs_idx[self.robots]
        self.obs_valid = seen.obs_valid[self.robots]
        self.obstacles = obstacles
        # the robots involved, and the pairs and robots in their local numbering
        self.members = np.unique(np.concatenate([self.pairs.ravel(), self.robots]))
        self._pairs = np.searchsorted(self.members, self.pairs)
        self._robots = np.searchsorted(self.members, self.robots)

    @staticmethod
    def _clear(pos, idx, valid, obstacles) -> np.ndarray:
        rel = pos[:, None, :] - obstacles.centers[idx]
        return np.where(valid, np.hypot(rel[..., 0], rel[..., 1]) - obstacles.radii[idx],
                        np.inf)

    def observe(self, metrics: RunMetrics, t: float, pose: np.ndarray) -> None:
        """Check the swarm's poses (N, 3) at time t."""
        self.observe_members(metrics, t, pose[self.members, :2])

    def observe_members(self, metrics: RunMetrics, t: float, pos: np.ndarray) -> None:
        """Check the positions (M, 2) of :attr:`members` only at time t."""
        clear = self._clear(pos[self._robots], self.obs_idx, self.obs_valid, self.obstacles)
        metrics.observe_geometry(t, pos, self._pairs.reshape(-1, 2), self._robots, clear,
                                 index=self.members)
