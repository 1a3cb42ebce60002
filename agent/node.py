"""One robot's agent: read -> update -> write, once per period.

Theory of operation. Every tick the agent

1. reads: drains the wheel drivers' feedback (odometry from the encoder positions), takes
   an immutable snapshot of its neighbours' states, its obstacle detections and the mission;
2. updates: decides its mode and, in FORMATION, runs its period (agent.period.robot_period:
   the one period the batch simulator runs for every robot) on what it read;
3. writes: the wheel set-points and its own state.

Modes: DISARMED (drivers IDLE, nothing commanded), HOLD (zero velocity, watchdog fed) and
FORMATION (the period). Bounds in layers, nearest the actuator last: the law (|u| clip, the
safety governor, the wheels' limit and ramp) -> non-finite guard -> stale feedback or
driver error means failsafe HOLD -> disarmed means no command at all. A failsafe is
sticky: it takes a new FORMATION request (ground station) to leave it.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from agent.config import CONTROL_PARAMS
from agent.exchange import NOBODY, Exchange
from agent.formation import Places
from agent.kinematics import TWO_PI, body_velocity
from agent.law import LawMemory
from agent.loop import Clock
from agent.neighbours import Reports
from agent.odometry import Odometry, Pose
from agent.params import PeriodParams
from agent.period import Detections, Inputs, Memory, Own, PeriodOut, Workspace, robot_period
from agent.period_log import PeriodLog
from agent.pose import PoseFusion
from agent.progress import PROGRESS, ProgressWatch, tolerance
from agent.trail import SPLITS, Splits, Trail
from common.payloads import MissionMsg, ObstaclesMsg, Received, StateMsg
from common.ports import FixPort, MotorPort, SwarmPort
from common.schema import ConfigError, Param
from common.vocabulary import AgentMode, Mode, StateFlags, WheelFeedback

if TYPE_CHECKING:               # the config reader knows the links' settings: not loaded here
    from agent.settings import AgentSettings

log = logging.getLogger(__name__)


ARM_RETRY = 0.25   # s between repeated arm requests while the drivers have not answered
_PARAMS: dict[str, Param] = {p.name: p for p in CONTROL_PARAMS}


AGE_STAGES = ("publish_to_router", "router_to_agent", "in_agent")
_NO_STAGES = (math.nan, math.nan, math.nan)


def _stages(rec: Received[StateMsg], now: float) -> tuple[float, float, float]:
    """Where a neighbour state used at ``now`` [s] spent its age [s] (AGE_STAGES): from its
    stamp to the router's timestamp, from there until this agent took it from its ring, and
    held in this agent until used; NaNs without a router timestamp."""
    if rec.routed is None:
        return _NO_STAGES
    return rec.routed - rec.msg.stamp, rec.received - rec.routed, now - rec.received


@dataclass
class AgentCounters:
    ticks: int = 0
    failsafes: int = 0
    nonfinite_commands: int = 0
    neighbour_age: deque = field(default_factory=lambda: deque(maxlen=20000))  # s
    age_stages: deque = field(default_factory=lambda: deque(maxlen=20000))  # s, AGE_STAGES
    law_steps: int = 0
    governed: int = 0                    # law steps in which the governor lowered the speed
    governor_min_allowed: float = math.inf   # m/s
    deadlocks: int = 0                   # times the robot became deadlocked
    deadlocked_periods: int = 0          # law steps while deadlocked
    place_changes: int = 0               # places taken (agent.exchange; two an exchange)

    def summary(self) -> dict:
        ages = np.asarray(self.neighbour_age) * 1e3
        return {"ticks": self.ticks, "failsafes": self.failsafes,
                "nonfinite_commands": self.nonfinite_commands,
                "law_steps": self.law_steps, "governed": self.governed,
                "governor_share": self.governed / self.law_steps if self.law_steps else 0.0,
                "governor_min_allowed": (self.governor_min_allowed
                                         if math.isfinite(self.governor_min_allowed) else None),
                "deadlocks": self.deadlocks,
                "place_changes": self.place_changes,
                "deadlocked_share": (self.deadlocked_periods / self.law_steps
                                     if self.law_steps else 0.0),
                "neighbour_age_ms": {
                    "p50": float(np.percentile(ages, 50)) if ages.size else None,
                    "p99": float(np.percentile(ages, 99)) if ages.size else None,
                    "count": int(ages.size)},
                "neighbour_age_stages_ms": self._stage_summary(ages)}

    def _stage_summary(self, ages: np.ndarray) -> dict | None:
        """Per stage of AGE_STAGES [ms]: p50, p99, and ``tail``, its mean over the uses
        whose age is at or above the age's p99 (what made the oldest data old). None
        without router timestamps."""
        stages = np.asarray(self.age_stages, dtype=float).reshape(-1, len(AGE_STAGES)) * 1e3
        known = ~np.isnan(stages[:, 0])
        if not known.any():
            return None
        tail = known & (ages >= np.percentile(ages, 99))
        return {name: {"p50": float(np.percentile(stages[known, k], 50)),
                       "p99": float(np.percentile(stages[known, k], 99)),
                       "tail": float(stages[tail, k].mean()) if tail.any() else None}
                for k, name in enumerate(AGE_STAGES)}


class Agent:
    """The agent of robot ``settings.robot_id`` over its injected ports."""

    def __init__(self, settings: AgentSettings, motor: MotorPort, swarm: SwarmPort,
                 clock: Clock, fixes: FixPort | None = None, periods: PeriodLog | None = None):
        """``fixes``: the robot's pose fixes, required when ``settings.pose`` is set;
        ``periods``: where to record every period it runs (None: nowhere)."""
        self.s = settings
        self._derive()
        self.motor, self.swarm, self.clock = motor, swarm, clock
        self.mode = AgentMode.DISARMED
        self.failsafe: str | None = None
        self.odometry = Odometry(settings.robot.wheel_radius, settings.robot.wheel_base,
                                 settings.initial_pose)
        # with a pose source: odometry fused with its fixes (agent.pose)
        self.fixes = fixes
        self.fusion = (PoseFusion(settings.pose, settings.robot.wheel_base)
                       if settings.pose is not None else None)
        if self.fusion is not None and fixes is None:
            raise ValueError("[pose] is configured: the agent needs the port of its fixes")
        self.pose: Pose = self.odometry.pose   # the estimate the agent acts on
        self.trail = Trail(settings.timeouts.staleness)   # its path, for the governor
        self.memory = LawMemory()
        self._held: list[int] = []         # neighbours whose pair was active (law.pair_active)
        self._jump = (0.0, 0.0)            # m, what pose fixes moved the estimate since the
                                           # last period
        self._ws = _workspace(0)
        self.periods = periods
        self._detected: tuple[ObstaclesMsg, Detections] | None = None   # the last message
        self._period: tuple[Inputs, Memory, PeriodOut] | None = None   # to record
        self.progress = ProgressWatch(settings.timeouts.deadlock)
        self.deadlock: str | None = None   # why the robot is deadlocked, if it is
        self.counters = AgentCounters()
        self.last_feedback: WheelFeedback | None = None
        self.command = (0.0, 0.0)          # (v [m/s], u [rad/s]) after saturation
        self.law_mode = Mode.TRACK
        self.governed = False              # the governor lowered the speed this period
        x0, y0, _ = settings.initial_pose
        self.reference = (float(x0), float(y0))   # m
        self._seq = 0
        self._last_law: float | None = None     # monotonic time of the last law step
        self._mission_key: tuple | None = None
        self._places: Places | None = None   # the mission's places
        self.exchange = Exchange(NOBODY)   # its place in the mission (agent.exchange)
        self._armed_at = -math.inf         # monotonic time of the last arm request
        self._arming = False               # waiting for both drivers to enter closed loop
        self._arm_sent = -math.inf

    # --- commands (from the process, a ground station or autostart) ---------------------
    def arm(self) -> str | None:
        """Clear the drivers' errors and request closed loop (an explicit request); the
        request alone is repeated until both drivers report it (they may boot after the
        robot computer), for at most ``[timeouts] arm``. Refused (the reason returned)
        with a pose source whose last fix is missing or too old."""
        if (why := self.pose_problem()) is not None:
            log.warning("robot %d: arming refused: %s", self.s.robot_id, why)
            return f"arming refused: {why}"
        self.motor.clear_errors()
        self.motor.arm()
        self.failsafe = None
        self._armed_at = self._arm_sent = self.clock.monotonic()
        self._arming = True
        if self.mode is AgentMode.DISARMED:
            self.mode = AgentMode.HOLD
        log.info("robot %d armed", self.s.robot_id)
        return None

    def disarm(self) -> None:
        self._arming = False
        self.motor.disarm()
        self.mode = AgentMode.DISARMED
        log.info("robot %d disarmed", self.s.robot_id)

    def set_mode(self, mode: AgentMode) -> str | None:
        """Switch HOLD <-> FORMATION; returns the reason when refused."""
        if mode is AgentMode.DISARMED:
            return "use disarm to disarm"
        if self.mode is AgentMode.DISARMED:
            return "not armed"
        if mode is AgentMode.FORMATION and (why := self.pose_problem()) is not None:
            return why
        self.mode = mode
        if mode is AgentMode.FORMATION:
            self.failsafe = None
            self._last_law = None
        return None

    # --- parameters (from a ground station, between two ticks) --------------------------
    def param(self, name: str) -> float:
        """The value of runtime parameter ``name`` (agent.config.CONTROL_PARAMS)."""
        return float(getattr(self.s.control, _PARAMS[name].field))

    def _derive(self) -> None:
        """What the period reads of the settings (agent.params.PeriodParams), derived at
        start and again when a parameter changes (:meth:`set_param`)."""
        s = self.s
        self._params = PeriodParams.of(s.control, s.robot, s.sensing_range,
                                       s.timeouts.staleness, s.robot.watchdog_timeout)

    def set_param(self, name: str, value: float) -> str | None:
        """Set runtime parameter ``name``; validated by the settings schema, in force from
        the next period. Returns why it was refused (the old value stays), or None. This is
        the only way the agent's settings change after start."""
        spec = _PARAMS.get(name)
        if spec is None:
            return f"no parameter {name}"
        if spec.read_only is not None:
            return f"{name} is {spec.read_only}"
        try:
            changes: dict[str, Any] = {spec.field: float(value)}
            control = dataclasses.replace(self.s.control, **changes)
            self.s = dataclasses.replace(self.s, control=control)
            self._derive()
        except ConfigError as exc:
            return f"{name} = {value:g} refused: {exc}"
        log.info("robot %d: %s = %g", self.s.robot_id, name, self.param(name))
        return None

    # --- the loop body ----------------------------------------------------------------------
    def tick(self, k: int = 0, deadline: float = 0.0) -> None:
        now_m, now_w = self.clock.monotonic(), self.clock.wall()
        self.counters.ticks += 1
        # read
        fb = self.motor.feedback()
        if fb is not None:
            self.odometry.update(*fb.pos_rev)
        self.last_feedback = fb
        pose = self._estimate(now_w)
        self.trail.record(now_w, pose[0], pose[1])
        mission = self.swarm.mission()
        # every period whatever the mode: the same work each tick (nothing piles up in the
        # rings until the mission starts, when every agent would drain them at once)
        neighbours = self.swarm.neighbours()
        detections = self.swarm.obstacles()

        # update
        right = left = 0.0
        self.law_mode = Mode.TRACK
        self.governed = False
        if self.mode is not AgentMode.DISARMED:
            self._check_feedback(fb, now_m)
            self._check_fix()
            if self.mode is AgentMode.FORMATION and self.failsafe is None and not self._arming:
                right, left = self._formation_step(pose, mission, neighbours, detections,
                                                   now_m, now_w)
            else:
                self._watch_progress(None)
        else:
            self._last_law = None
            self._watch_progress(None)

        # write (the period's set-points are within the wheels' limit and ramp already; a
        # HOLD's zero is ramped by the drivers)
        if self.mode is not AgentMode.DISARMED:
            r = self.s.robot
            if not (math.isfinite(right) and math.isfinite(left)):
                self.counters.nonfinite_commands += 1
                right = left = 0.0
            self.motor.command(right, left)
            v_sat, u_sat = body_velocity(TWO_PI * right, TWO_PI * left, r.wheel_radius,
                                         r.wheel_base)
            self.command = (v_sat, u_sat)
        else:
            right = left = 0.0
            self.command = (0.0, 0.0)
        self.memory = self.memory._replace(wheel_r=right, wheel_l=left)   # the law ramps on
        if self._period is not None and self.periods is not None:
            inputs, before, out = self._period
            self.periods.write(inputs, before, self._params, out, self._held, (right, left))
            self._period = None
        self._publish(pose, now_w)

    def _check_feedback(self, fb: WheelFeedback | None, now_m: float) -> None:
        """Failsafe on lost feedback, a driver error, or drivers that leave closed loop.

        While arming, the arm request is repeated every ``ARM_RETRY`` s until both drivers
        report closed loop; only a driver error, or ``[timeouts] arm`` without success, is a
        failsafe then."""
        reason = None
        fresh = fb if fb is not None and fb.age <= self.s.timeouts.feedback else None
        if fresh is not None and fresh.errors:
            reason = "driver error: " + ", ".join(fresh.errors)
        elif self._arming:
            if fresh is not None and fresh.closed_loop:
                self._arming = False
                log.info("robot %d: both drivers in closed loop", self.s.robot_id)
            elif now_m - self._armed_at > self.s.timeouts.arm:
                self._arming = False
                reason = (f"drivers not armed within {self.s.timeouts.arm:g} s"
                          + ("" if fresh is not None else " (no feedback)"))
            elif now_m - self._arm_sent >= ARM_RETRY:
                self.motor.arm()
                self._arm_sent = now_m
        elif fresh is None:
            reason = "driver feedback lost"
        elif not fresh.closed_loop:
            reason = "drivers not in closed loop control"
        if reason:
            self._enter_failsafe(reason)

    def _enter_failsafe(self, reason: str) -> None:
        """The first failsafe sticks: HOLD, say why."""
        if self.failsafe is None:
            self.failsafe = reason
            self.counters.failsafes += 1
            if self.mode is AgentMode.FORMATION:
                self.mode = AgentMode.HOLD
            log.critical("robot %d failsafe: %s; holding", self.s.robot_id, reason)

    # --- pose source (agent.pose) ---------------------------------------------------------
    def _estimate(self, now_w: float) -> Pose:
        """The pose to act on: odometry, corrected by the newest fix when there is a source."""
        if self.fusion is None or self.fixes is None:
            self.pose = self.odometry.pose
            return self.pose
        before = self.fusion.update(now_w, self.odometry.pose)
        if (fix := self.fixes.fix()) is not None and self.fusion.fix(fix):
            after = self.fusion.pose
            self._jump = (self._jump[0] + (after[0] - before[0]),
                          self._jump[1] + (after[1] - before[1]))
        self.pose = self.fusion.pose
        return self.pose

    def pose_problem(self) -> str | None:
        """Why the pose is not to be trusted (the source's last fix is missing or older than
        ``[pose] fix_timeout``), or None (also without a pose source)."""
        if self.fusion is None or self.s.pose is None:
            return None
        age, limit = self.fusion.age(self.clock.wall()), self.s.pose.fix_timeout
        if math.isinf(age):
            return "no pose fix yet"
        return f"pose fix {age:.2f} s old (limit {limit:g} s)" if age > limit else None

    def _check_fix(self) -> None:
        """Failsafe HOLD when the pose source's fix is missing or too old."""
        reason = self.pose_problem()
        if reason:
            self._enter_failsafe(reason)

    def _mission_places(self, mission: MissionMsg) -> Places | None:
        """The mission's places, None when this robot is not in it; a new mission gives
        the robot its own place again."""
        key = (mission.seq, mission.stamp)
        if key != self._mission_key:
            self._mission_key = key
            where = np.flatnonzero(mission.ids == self.s.robot_id)
            if where.size == 0:
                log.error("robot %d is not in the mission's formation", self.s.robot_id)
                self._places, self.exchange = None, Exchange(NOBODY)
            else:
                self._places = Places(np.ascontiguousarray(mission.offsets, dtype=float),
                                      np.array([*mission.center0, *mission.velocity,
                                                mission.omega], dtype=float))
                self.exchange = Exchange(int(where[0]))
        return self._places

    def _formation_step(self, pose: tuple[float, float, float], mission: MissionMsg | None,
                        neighbours: Mapping[int, Received[StateMsg]],
                        detections: ObstaclesMsg | None, now_m: float, now_w: float
                        ) -> tuple[float, float]:
        """The period (agent.period.robot_period) on what the agent read; the wheels'
        set-points [rev/s]."""
        if mission is None or now_w < mission.epoch:
            self._last_law = None
            self._watch_progress(None)
            return 0.0, 0.0
        places = self._mission_places(mission)
        if places is None:
            self._watch_progress(None)
            return 0.0, 0.0
        dt = self.s.control.period if self._last_law is None else now_m - self._last_law
        dt = max(dt, 1e-6)
        self._last_law = now_m
        recs = [r for rid, r in neighbours.items() if rid != self.s.robot_id]
        inputs = self.inputs(pose, recs, detections, places, now_w, now_w - mission.epoch, dt)
        if len(recs) + inputs.detections.n > len(self._ws.obs_x):
            self._ws = _workspace(2 * (len(recs) + inputs.detections.n))
        before = Memory(self.memory, self.exchange)
        out = robot_period(inputs, before, self._params, self._ws)
        if self.periods is not None:
            self._period = (inputs, before, out)
        self._jump = (0.0, 0.0)
        was = self.exchange.slot
        self.memory, self.exchange = out.memory
        if self.exchange.slot != was:
            self.counters.place_changes += 1
            log.info("robot %d takes place %d (it had place %d)", self.s.robot_id,
                     self.exchange.slot, was)
        self._held = list(self._ws.held[:out.n_held])
        ref = out.reference
        self.reference = (ref.x, ref.y)
        for q in range(out.n_nbr):        # the age of the data the law acted on
            rec = recs[self._ws.nbr_row[q]]
            self.counters.neighbour_age.append(now_w - rec.msg.stamp)
            self.counters.age_stages.append(_stages(rec, now_w))
        self._watch_progress((now_m, math.hypot(pose[0] - ref.x, pose[1] - ref.y),
                              tolerance(math.hypot(ref.vx, ref.vy), self.s.control.K)))
        self.law_mode = Mode(out.mode)
        self.counters.law_steps += 1
        self.governed = math.isfinite(out.governed)
        if self.governed:
            self.counters.governed += 1
            self.counters.governor_min_allowed = min(self.counters.governor_min_allowed,
                                                     out.governed)
        return out.right, out.left

    def inputs(self, pose: tuple[float, float, float], recs: list[Received[StateMsg]],
               detections: ObstaclesMsg | None, places: Places, now_w: float, t: float,
               dt: float) -> Inputs:
        """What this robot knows in a period (agent.period.Inputs), at UNIX time ``now_w``
        [s], mission time ``t`` [s], ``dt`` [s] after the last period: its pose, its
        neighbours' newest states ``recs``, its ``detections`` (None: none), the mission's
        ``places``, its path and the pairs it avoided."""
        msgs = [r.msg for r in recs]
        n = len(msgs)
        reports = Reports([m.robot_id for m in msgs], [m.stamp for m in msgs],
                          [m.x for m in msgs], [m.y for m in msgs], [m.theta for m in msgs],
                          [m.v for m in msgs], [m.u for m in msgs], [m.slot for m in msgs],
                          [m.partner for m in msgs], [m.other for m in msgs])
        if detections is None:
            seen = Detections([], [], [], 0)
        elif self._detected is not None and self._detected[0] is detections:
            seen = self._detected[1]            # the same message: converted once
        else:
            seen = Detections(detections.centers[:, 0].tolist(),
                              detections.centers[:, 1].tolist(), detections.radii.tolist(),
                              len(detections.radii))
            self._detected = (detections, seen)
        grow = self.fusion.uncertainty if self.fusion is not None else 0.0    # m
        own = Own(self.s.robot_id, pose[0], pose[1], pose[2], grow, *self._jump)
        return Inputs(own, now_w, t, dt, reports, list(range(n)), n, seen, places,
                      self.trail.path(), self._held, len(self._held))

    def _watch_progress(self, sample: tuple[float, float, float] | None) -> None:
        """The deadlock detector (agent.progress) on (monotonic time [s], tracking error [m],
        tolerance [m]) of a period that followed the reference; None: the robot did not
        follow it (the detector starts again)."""
        if sample is None:
            self.progress.reset()
            self.deadlock = None
            return
        t, error, tol = sample
        if self.progress.update(t, error, tol):
            self.counters.deadlocked_periods += 1
            if self.deadlock is None:
                self.counters.deadlocks += 1
                log.warning("robot %d deadlocked: %.1f m from its place, less than %.1f m "
                            "closer in %g s", self.s.robot_id, error, PROGRESS,
                            self.progress.window)
            self.deadlock = (f"{error:.1f} m off, <{PROGRESS:g} m closer in "
                             f"{self.progress.window:g} s")
        else:
            if self.deadlock is not None:
                log.info("robot %d progressing again", self.s.robot_id)
            self.deadlock = None

    def flags(self) -> StateFlags:
        f = StateFlags(0)
        if self.mode is not AgentMode.DISARMED:
            f |= StateFlags.ARMED
        if self.mode is AgentMode.HOLD:
            f |= StateFlags.HOLD
        if self.failsafe:
            f |= StateFlags.FAILSAFE
        if self.governed:
            f |= StateFlags.GOVERNED
        if self.deadlock:
            f |= StateFlags.DEADLOCKED
        return f

    def _publish(self, pose: tuple[float, float, float], now_w: float) -> None:
        self._seq += 1
        v, u = self.command
        ex = self.exchange
        self.swarm.publish(StateMsg(self.s.robot_id, self._seq, now_w, *pose, v, u,
                                    *self.reference, int(self.law_mode), self.flags(),
                                    ex.slot, ex.partner, ex.other))

    def shutdown(self) -> None:
        """Zero velocity, then IDLE."""
        if self.mode is not AgentMode.DISARMED:
            self.motor.command(0.0, 0.0)
            self.disarm()


def _workspace(size: int) -> Workspace:
    """Scratch columns for the period (agent.period.Workspace) of ``size`` entries."""
    def floats() -> list[float]:
        return [0.0] * size

    def ints() -> list[int]:
        return [0] * size

    splits = Splits(*([0.0] * SPLITS for _ in range(len(Splits._fields))))
    return Workspace(floats(), floats(), floats(), floats(), ints(), floats(), floats(),
                     floats(), ints(), ints(), floats(), ints(), splits, [-1] * (2 * SPLITS),
                     ints())
