"""The batch simulator: every robot of a swarm stepped in one process.

Each control period: references at t, per-robot sensing (neighbours and obstacles inside the
sensing range only), the one law of the agents for every robot, then the plant integrated
over ``substeps`` physics steps with distances and clearances checked at each. The period
is :mod:`firmware_sim.swarm_step`, compiled with numba together with the law when numba is
installed (:mod:`firmware_sim.compiled`), interpreted otherwise: the same source either way.
Time is simulated: a run is deterministic and as fast as the CPU allows.

In an imperfect world (:class:`firmware_sim.world.WorldParams`) the law sees what an agent
would (:mod:`firmware_sim.world_step`): its pose from odometry, its neighbours' states late,
lost or stale, noisy obstacle detections; dead agents stop commanding and their drivers'
watchdog stops their wheels. Safety and convergence are measured on the plant's truth.
"""
from __future__ import annotations

import logging
import math
import types
from dataclasses import dataclass
from typing import Callable

import numpy as np

from agent.config import ControlParams, RobotParams
from agent.exchange import NOBODY, Exchange
from agent.formation import Formation, Places
from agent.neighbours import Reports
from agent.params import PeriodParams
from agent.progress import TOLERANCE_MARGIN
from agent.settings import TimeoutSettings
from firmware_sim import compiled, swarm_step, world_step
from firmware_sim.batch_pose import BatchPoseSource
from firmware_sim.metrics import RunMetrics
from firmware_sim.mocap_sim import MocapParams
from firmware_sim.plant import PlantKind
from firmware_sim.swarm_step import MEMORY, Outputs, SwarmState, World
from firmware_sim.world import Obstacles, WorldParams

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
    governed: np.ndarray     # (R, N) m/s, the speed the governor allowed (inf: it did not act)
    ref: np.ndarray          # (R, N, 2) m
    metrics: RunMetrics
    law_seconds: float = 0.0  # wall time spent in the law (for benchmarks)


class _Interpreted(types.SimpleNamespace):
    """The kernels as plain Python, by name, as :func:`compiled.kernels` gives them."""


def _interpreted() -> _Interpreted:
    return _Interpreted(**{name: getattr(m, name) for m in (swarm_step, world_step)
                           for name in dir(m) if callable(getattr(m, name))})


def _engine(options: SimOptions) -> types.SimpleNamespace:
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
    return compiled.kernels() if want else _interpreted()


# the columns of a period's command (swarm_step.Outputs.cmd) that a robot's drivers hold
# should its agent die: v, u and the wheels' set-points
COMMAND = np.array([0, 1, 4, 5])
PARALLEL_MIN = 500   # robots; below, waking threads costs more than it saves


def simulate(ids: np.ndarray, poses0: np.ndarray, formation: Formation, obstacles: Obstacles,
             control: ControlParams, robot: RobotParams, options: SimOptions,
             world: WorldParams | None = None,
             mocap: MocapParams | None = None,
             progress: Callable[[float], None] | None = None,
             clock: Callable[[], float] | None = None) -> SimResult:
    """Run the swarm from ``poses0`` (N, 3) for ``options.duration`` seconds in ``world``
    (None: the ideal world). ``mocap``: the robots' pose is their odometry fused with
    simulated motion-capture fixes (:mod:`firmware_sim.batch_pose`; only where the world
    makes odometry wrong: wheel slip or encoder noise).

    ``progress`` is called with the completed fraction about a hundred times; ``clock``
    (e.g. ``time.perf_counter``) is used, when given, to time sensing and the law for
    benchmarks.
    """
    ids = np.asarray(ids)
    pose = np.array(poses0, dtype=float).reshape(-1, 3)
    n = len(pose)
    if len(formation.offsets) != n:
        raise ValueError(f"formation has {len(formation.offsets)} places for {n} robots")
    world = world or WorldParams()
    ideal = options.plant is PlantKind.IDEAL
    if world.odometry and ideal:
        raise ValueError("the world's wheel_slip and encoder_noise need the wheels plant")
    unknown = sorted(set(k.robot for k in world.kill) - set(ids.tolist()))
    if unknown:
        raise ValueError(f"world kills robots that are not in the swarm: {unknown}")
    k = _engine(options)
    if not isinstance(k, _Interpreted):
        compiled.use_threads(n >= PARALLEL_MIN)
    T = control.period
    steps = int(round(options.duration / T))
    offsets = np.ascontiguousarray(formation.offsets, dtype=float).reshape(n, 2)
    places = Places(offsets, np.array([*formation.center0, *formation.velocity,
                                       formation.omega], dtype=float))
    obs = np.column_stack([obstacles.centers.reshape(-1, 2), obstacles.radii]).astype(float)
    metrics = RunMetrics(ids=ids, a=control.a)
    every = options.record_every
    n_rec = (steps // every + 1) if every else 0
    rec_t = np.zeros(n_rec)
    rec_pose = np.zeros((n_rec, n, 3))
    rec_v, rec_u = np.zeros((n_rec, n)), np.zeros((n_rec, n))
    rec_mode = np.zeros((n_rec, n), np.int8)
    rec_gov = np.zeros((n_rec, n))
    rec_ref = np.zeros((n_rec, n, 2))
    S = options.substeps
    dt = T / S
    report_every = max(1, steps // 100)
    law_seconds = 0.0
    reach = max(control.v_max, robot.v_wheel_max) * T   # m, farthest move per period

    mem = np.zeros(n, MEMORY)
    # each robot's place exchange (agent.exchange.Exchange): its own place, no partner
    mem["slot"], mem["partner"], mem["other"], mem["since"] = np.arange(n), NOBODY, NOBODY, \
        -np.inf
    new_mem = mem.copy()
    cap, watch_cap = 32, 8      # sensed per robot, watched per robot (grown when needed)
    held, new_held = np.full((n, cap + 1), -1, np.int64), np.full((n, cap + 1), -1, np.int64)
    cmd, ref, near = np.zeros((n, 6)), np.zeros((n, 4)), np.zeros((n, 2))
    last_mode, err, within = np.zeros(n), np.zeros(n), np.zeros(n, bool)
    # wheels plant: drive latency in whole substeps; the commands of the last substeps, at
    # rest before the first period
    lag = 0 if ideal else int(round(robot.drive_latency / dt))
    issued = np.zeros((S + lag, n, 2))
    wheels, enc = np.zeros((n, 2)), np.zeros((n, 2))
    pos = np.zeros((S + 1, n, 2))
    dmin, cmin, who = np.zeros(S + 1), np.zeros(S + 1), np.zeros((S + 1, 4), np.int64)
    watch_j, watch_k = np.empty((n, watch_cap), np.int64), np.empty((n, watch_cap), np.int64)
    hit_j, hit_k = np.zeros((n, watch_cap), bool), np.zeros((n, watch_cap), bool)
    w = _WorldState(world, n, ids, pose, T, control, robot, ideal, k, mocap)
    # the ideal plant's robot follows any command at once; the wheels' limits are the law's
    params = PeriodParams.of(control, None if ideal else robot, options.sensing_range,
                             w.staleness, robot.watchdog_timeout)
    top = params.model.top_speed
    for step in range(steps + 1):
        t = step * T
        t0 = clock() if clock else 0.0
        state = w.before_control(step, t, pose, cmd, mem, held)
        own = state.own
        if own is not pose:
            metrics.max_pose_error = max(metrics.max_pose_error, float(
                np.hypot(own[:, 0] - pose[:, 0], own[:, 1] - pose[:, 1]).max(initial=0.0)))
        # the reports that may put a robot within the sensing range: their robots may be
        # nearer than their reports by what the fastest robot travels in their age, and
        # where the reports put them now is that far from the reports
        age = min(t - float(np.min(w.reports.stamp, initial=t)), w.staleness)
        query = options.sensing_range + 2.0 * top * max(age, 0.0)
        period_world = World(t, T, step, w.truth, world.seed, world.detection_noise,
                             world.detection_dropout, query, reach)
        while True:
            outs = Outputs(cmd, ref, new_mem, new_held, near, watch_j, watch_k)
            need, need_watch = k.control(pose, state, w.reports, outs, places, obs, params,
                                         period_world, cap, watch_cap)
            if need <= cap and need_watch <= watch_cap:
                break
            if need > cap:
                grown = np.full((n, int(need) + 1), -1, np.int64)
                grown[:, :cap + 1] = held
                held, new_held = grown, np.full((n, int(need) + 1), -1, np.int64)
                state = state._replace(held=held)
            cap, watch_cap = max(cap, int(need)), max(watch_cap, int(need_watch))
            watch_j = np.empty((n, watch_cap), np.int64)
            watch_k = np.empty((n, watch_cap), np.int64)
            hit_j, hit_k = np.zeros((n, watch_cap), bool), np.zeros((n, watch_cap), bool)
        if clock:
            law_seconds += clock() - t0
        mem, new_mem = new_mem, mem
        held, new_held = new_held, held
        if not w.alive.all():         # a dead agent's exchange state stays as it left it
            dead = ~w.alive
            for name in Exchange._fields:
                mem[name][dead] = new_mem[name][dead]
        metrics.observe_places(mem["slot"], new_mem["slot"], w.alive)
        w.after_control(step, t, own, cmd, _places(mem))
        v, u, mode = cmd[:, 0], cmd[:, 1], cmd[:, 2]       # views, overwritten next period
        max_v, max_u, switches, all_within = k.period_summary(
            pose, cmd, ref, control.K, TOLERANCE_MARGIN, step == 0, w.alive, last_mode, err,
            within)
        metrics.observe_period(t, max_v, max_u, switches, err, within, all_within)
        metrics.observe_governor(cmd[:, 3], w.alive)
        if every and step % every == 0:
            r = step // every
            rec_t[r], rec_pose[r], rec_v[r], rec_u[r] = t, pose, v, u
            rec_mode[r], rec_ref[r], rec_gov[r] = mode, ref[:, :2], cmd[:, 3]
        last = step == steps
        first = 0 if step == 0 else 1
        # the pairs and obstacles that could be the closest or closer than a this period
        pair_limit = max(float(near[:, 0].min(initial=np.inf)), control.a) + 4.0 * reach
        clear_limit = max(float(near[:, 1].min(initial=np.inf)), 0.0) + 2.0 * reach
        watched = (near[:, 0] <= pair_limit) | (near[:, 1] <= clear_limit)
        # the commands the drivers follow in each substep (issued a drive latency earlier)
        issued[:-S] = issued[S:]
        issued[-S:] = cmd[:, :2] if ideal else cmd[:, 4:6]
        if last:
            pos[0] = pose[:, :2]
        else:
            w.before_plant(step)
            k.advance(pose, issued[len(issued) - S - lag:len(issued) - lag], wheels, w.slip,
                      enc, ideal, robot.wheel_radius, robot.wheel_base,
                      robot.wheel_speed_limit, robot.wheel_ramp, dt, S, watched, pos)
            w.after_plant(step, enc, robot)
        n_sub = 1 if last else S + 1
        hits = k.geometry(pos[:n_sub], watch_j, watch_k, obs, control.a, first, pair_limit,
                          clear_limit, watched, dmin, cmin, who, hit_j, hit_k)
        pairs: list[tuple[int, int]] = []
        inside: list[int] = []
        if hits:
            pairs = [(int(ids[i]), int(ids[watch_j[i, w]])) for i, w in zip(*np.nonzero(hit_j))]
            inside = [int(ids[i]) for i in np.flatnonzero(hit_k.any(axis=1))]
            hit_j[:], hit_k[:] = False, False
        for s in range(first, n_sub):
            metrics.observe_extremes(t + s * dt, float(dmin[s]), float(cmin[s]), pairs, inside,
                                     who[s])
        if last:
            break
        if progress and step % report_every == 0:
            progress(step / steps)
    if progress:
        progress(1.0)
    metrics.killed = sorted(k_.robot for k_ in world.kill if k_.at <= options.duration)
    if w.pose_source is not None:
        metrics.pose_holds = sorted(int(r) for r in ids[w.pose_source.held])
    return SimResult(ids=ids, t=rec_t, pose=rec_pose, v=rec_v, u=rec_u, mode=rec_mode,
                     governed=rec_gov,
                     ref=rec_ref, metrics=metrics, law_seconds=law_seconds)


def _places(mem: np.ndarray) -> np.ndarray:
    """(N, 3) each robot's place exchange as it publishes it: slot, partner, other."""
    return np.column_stack([mem["slot"], mem["partner"], mem["other"]])


class _WorldState:
    """The imperfect world's state through a run: what the robots know, the slip of their
    wheels, their encoder readings and who is dead (:mod:`firmware_sim.world_step`)."""

    def __init__(self, world: WorldParams, n: int, ids: np.ndarray, pose: np.ndarray,
                 period: float, control: ControlParams, robot: RobotParams, ideal: bool,
                 k: types.SimpleNamespace, mocap: MocapParams | None = None):
        self.world, self.period, self.k = world, period, k
        self.pose_source = (BatchPoseSource(mocap, ids, pose, period, robot.wheel_base,
                                            world.seed)
                            if mocap is not None and world.odometry else None)
        self.truth = world.ideal
        self.watchdog = robot.watchdog_timeout
        self.staleness = world.staleness(TimeoutSettings().staleness)
        self.alive = np.ones(n, bool)
        index = {int(r): i for i, r in enumerate(ids)}
        self.kill_at = np.full(n, np.inf)
        for kill in world.kill:
            self.kill_at[index[kill.robot]] = kill.at
        self.held = np.zeros((n, len(COMMAND)))   # the last command of each agent alive
        self.est = pose.copy()                 # odometry
        self.last_read = np.zeros((n, 2))
        if world.odometry:                     # the first reading sets the origin
            k.odometry(0, world.seed, world.encoder_noise, np.zeros((n, 2)), self.last_read,
                       1.0, 1.0, pose.copy())
        depth = int(math.ceil((world.link_delay + 4.0 * world.link_jitter) / period)) + 3
        self.hist = np.zeros((depth, n, 9))
        self.arrive = np.full((depth, n), np.inf)
        # the robots exchanged their states at rest before the mission started (robot i
        # is row i: the batch's robot ids are their indices)
        self.reports = Reports(np.arange(n), np.zeros(n), pose[:, 0].copy(),
                               pose[:, 1].copy(), pose[:, 2].copy(), np.zeros(n), np.zeros(n),
                               np.arange(n), np.full(n, NOBODY), np.full(n, NOBODY))
        self.bad = np.zeros(n, np.int64)
        self.slip = np.zeros((n, 2))
        self.seen = np.zeros((n, 3))
        # each robot's believed position (x, y) [m] and the cumulative path [m] through
        # them, a ring over its last periods, with their times (at rest before)
        ring = 1 if self.truth else int(math.ceil(self.staleness / period)) + 2
        self.path = np.zeros((n, 3, ring))
        self.path[:, 0], self.path[:, 1] = pose[:, :1], pose[:, 1:2]
        self.path_t = np.zeros(ring)
        self.no_jump = np.zeros((n, 2))

    def before_control(self, step: int, t: float, pose: np.ndarray, cmd: np.ndarray,
                       mem: np.ndarray, held: np.ndarray) -> SwarmState:
        """What the robots know at t [s] (:class:`swarm_step.SwarmState`); ``cmd`` holds the
        last period's commands, ``mem`` their memories (swarm_step.MEMORY), ``held`` their
        pairs active last period."""
        np.less(t, self.kill_at, out=self.alive)
        rep = self.reports
        if self.truth:              # everyone knows everyone's current state (no age)
            rep.x[:], rep.y[:], rep.theta[:] = pose[:, 0], pose[:, 1], pose[:, 2]
            rep.v[:], rep.u[:], rep.stamp[:] = cmd[:, 0], cmd[:, 1], np.full(len(pose), t)
            rep.slot[:], rep.partner[:], rep.other[:] = mem["slot"], mem["partner"], \
                mem["other"]
            return SwarmState(pose, self.no_jump, pose, self.path, self.path_t, 0, 1, mem, held)
        self.k.deliver(t, self.hist, self.arrive, rep, self.staleness, self.seen)
        own = self.est if self.world.odometry else pose
        jump = self.no_jump
        if self.pose_source is not None:
            own = self.pose_source.step(step, t, self.est, pose)
            jump = self.pose_source.jump
        ring = self.path.shape[2]
        last, now = (step - 1) % ring, step % ring
        self.path[:, 0, now], self.path[:, 1, now] = own[:, 0], own[:, 1]
        np.add(self.path[:, 2, last], np.hypot(own[:, 0] - self.path[:, 0, last],
                                               own[:, 1] - self.path[:, 1, last]),
               out=self.path[:, 2, now])
        self.path_t[now] = t
        count = min(step + 1, ring)
        return SwarmState(own, jump, self.seen, self.path, self.path_t,
                          (step + 1 - count) % ring, count, mem, held)

    def after_control(self, step: int, t: float, own: np.ndarray, cmd: np.ndarray,
                      places: np.ndarray) -> None:
        """Dead agents command nothing new (their drivers hold the last command until
        their watchdog stops them); the live ones publish their state (``places``: their
        exchange states, slot, partner and other)."""
        if self.pose_source is not None:          # failsafe HOLD: no fix for too long
            cmd[self.pose_source.held, :2] = cmd[self.pose_source.held, 4:] = 0.0
        if self.world.kill:
            alive, dead = self.alive, ~self.alive
            self.held[alive] = cmd[alive][:, COMMAND]
            tripped = t >= self.kill_at + self.watchdog
            cmd[np.ix_(dead, COMMAND)] = np.where(tripped[dead, None], 0.0, self.held[dead])
        if not self.truth:
            w = self.world
            self.k.publish(step, self.period, own, cmd, places, self.alive, w.seed,
                           w.link_delay, w.link_jitter, w.link_loss, w.loss_burst, self.bad,
                           self.hist, self.arrive)

    def before_plant(self, step: int) -> None:
        """The wheels' slip for the coming period."""
        if self.world.wheel_slip > 0:
            self.k.slip_update(step, self.period, self.world.seed, self.world.wheel_slip,
                               self.slip)

    def after_plant(self, step: int, enc: np.ndarray, robot: RobotParams) -> None:
        if self.world.odometry:
            self.k.odometry(step + 1, self.world.seed, self.world.encoder_noise, enc,
                            self.last_read, robot.wheel_radius, robot.wheel_base, self.est)
