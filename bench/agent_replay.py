"""Record what agents read in a closed loop, replay it into agents, hash their commands.

``record`` runs the agents of a scenario (agent.node.Agent, interpreted, as on robots) in one
process on simulated time: each ticks at its own phase with a jitter, its wheels ramp and
lag as the profile says, its neighbours' states arrive late (delay and jitter drawn per
state) or not at all, and its obstacle detections come at 10 Hz from its true position;
every message passes its wire encoding. What each agent's ports and clock gave it in each
tick (feedback, mission, neighbours, detections, the clock's readings) and when it was
armed are written to a pickle.

``replay`` hands each recorded agent exactly those readings again, tick by tick (open
loop: its commands move nothing), and prints the SHA-256 of every wheel command it sent,
in order, as float64 bytes; ``--out`` keeps the commands, ``--against`` compares them with
another replay's, tick by tick. The replay uses only the agent's public API, so a recording
made on one commit replays on another: the agent's commands are unchanged exactly when the
hashes are equal.

    .venv/bin/python bench/agent_replay.py record --scenario S.toml --robot robots/cart.toml
        [--seconds 20] [--delay 0.05] [--jitter 0.02] [--loss 0.1] --out rec.pickle
    .venv/bin/python bench/agent_replay.py replay rec.pickle [--out cmds.npz]
        [--against other.npz]
"""
from __future__ import annotations

import argparse
import hashlib
import heapq
import math
import pickle
import sys
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from helpers import SimClock  # noqa: E402

from agent.config import RobotParams  # noqa: E402
from agent.kinematics import TWO_PI, arc_step, body_velocity  # noqa: E402
from agent.node import Agent  # noqa: E402
from agent.settings import AgentSettings, SensingSettings  # noqa: E402
from common.payloads import MissionMsg, ObstaclesMsg, Received, StateMsg  # noqa: E402
from common.vocabulary import AgentMode, WheelFeedback  # noqa: E402
from hil.files.robot_profile import load_robot_profile  # noqa: E402
from hil.files.scenario import load_scenario  # noqa: E402

DETECT_EVERY = 0.1     # s between obstacle detections (as the SITL's plant)


class Wheels:
    """A robot's two wheels: set-points applied ``latency`` [s] late, ramped and limited as
    the profile says; the robot moves on them (truth)."""

    def __init__(self, robot: RobotParams, pose: tuple[float, float, float]):
        self.r, self.pose = robot, pose
        self.speed = [0.0, 0.0]                  # rev/s, right, left
        self.pos = [0.0, 0.0]                    # rev
        self.queue: list[tuple[float, float, float]] = []   # (due, right, left)
        self.target = (0.0, 0.0)
        self.armed = False
        self.t = 0.0

    def advance(self, now: float) -> None:
        dt = now - self.t
        self.t = now
        if dt <= 0.0:
            return
        while self.queue and self.queue[0][0] <= now:
            _, right, left = self.queue.pop(0)
            self.target = (right, left) if self.armed else (0.0, 0.0)
        step, lim = self.r.wheel_ramp * dt, self.r.wheel_speed_limit
        for w in range(2):
            want = min(max(self.target[w], -lim), lim)
            self.speed[w] += min(max(want - self.speed[w], -step), step)
            self.pos[w] += self.speed[w] * dt
        v, u = body_velocity(TWO_PI * self.speed[0], TWO_PI * self.speed[1],
                             self.r.wheel_radius, self.r.wheel_base)
        self.pose = arc_step(*self.pose, v * dt, u * dt)


class RecordedMotor:
    """The motor port of one agent in the closed loop, recording what it returns."""

    def __init__(self, wheels: Wheels, clock: SimClock, log: dict):
        self.wheels, self.clock, self.log = wheels, clock, log

    def arm(self) -> None:
        self.wheels.armed = True

    def disarm(self) -> None:
        self.wheels.armed = False
        self.wheels.target = (0.0, 0.0)

    def command(self, right: float, left: float) -> None:
        self.wheels.queue.append((self.clock.monotonic() + self.wheels.r.drive_latency,
                                  right, left))

    def feedback(self) -> WheelFeedback:
        w = self.wheels
        w.advance(self.clock.monotonic())
        fb = WheelFeedback((w.pos[0], w.pos[1]), (w.speed[0], w.speed[1]), 0.0, w.armed, ())
        self.log["feedback"] = fb
        return fb

    def clear_errors(self) -> None:
        pass


class Net:
    """States on a link with delay, jitter and loss; detections at 10 Hz; the mission."""

    def __init__(self, rng: np.random.Generator, delay: float, jitter: float, loss: float):
        self.rng, self.delay, self.jitter, self.loss = rng, delay, jitter, loss
        self.flight: list[tuple[float, int, StateMsg]] = []     # (arrival, seq, state)
        self.states: dict[int, Received[StateMsg]] = {}
        self.mission: MissionMsg | None = None
        self.detections: dict[int, ObstaclesMsg] = {}
        self.count = 0

    def send(self, state: StateMsg, now: float) -> None:
        if self.rng.random() < self.loss:
            return
        self.count += 1
        age = max(self.delay + self.jitter * self.rng.standard_normal(), 0.0)
        wire = StateMsg.decode(state.encode())
        heapq.heappush(self.flight, (now + age, self.count, wire))

    def deliver(self, now: float) -> None:
        while self.flight and self.flight[0][0] <= now:
            arrived, _, msg = heapq.heappop(self.flight)
            old = self.states.get(msg.robot_id)
            if old is None or msg.stamp > old.msg.stamp:
                self.states[msg.robot_id] = Received(msg, arrived)


class RecordedSwarm:
    def __init__(self, net: Net, robot_id: int, clock: SimClock, log: dict):
        self.net, self.robot_id, self.clock, self.log = net, robot_id, clock, log

    def publish(self, state: StateMsg) -> None:
        self.net.send(state, self.clock.wall())

    def neighbours(self):
        self.net.deliver(self.clock.wall())
        out = {k: v for k, v in self.net.states.items() if k != self.robot_id}
        self.log["neighbours"] = out
        return MappingProxyType(out)

    def obstacles(self) -> ObstaclesMsg | None:
        self.log["obstacles"] = msg = self.net.detections.get(self.robot_id)
        return msg

    def mission(self) -> MissionMsg | None:
        self.log["mission"] = self.net.mission
        return self.net.mission


def record(args: argparse.Namespace) -> None:
    sc = load_scenario(Path(args.scenario))
    robot = load_robot_profile(args.robot) if args.robot else sc.robot
    rng = np.random.default_rng(args.seed)
    period = sc.control.period
    clock = SimClock()
    net = Net(rng, args.delay, args.jitter, args.loss)
    wall0 = clock.wall()
    f = sc.formation
    net.mission = MissionMsg(1, wall0, wall0 + 0.5, (f.center0[0], f.center0[1]),
                             (f.velocity[0], f.velocity[1]), f.omega, np.asarray(sc.ids),
                             np.asarray(f.offsets, dtype=float))
    net.mission = MissionMsg.decode(net.mission.encode())
    agents, logs, wheels = [], [], []
    for rid, pose in zip(sc.ids, sc.poses):
        settings = AgentSettings(robot_id=int(rid), swarm="rec", initial_pose=tuple(pose),
                                 autostart=True, robot=robot, control=sc.control,
                                 sensing=SensingSettings(range=sc.sensing_range))
        log: dict[str, Any] = {"settings": settings, "ticks": []}
        w = Wheels(robot, (float(pose[0]), float(pose[1]), float(pose[2])))
        tick_log: dict[str, Any] = {}
        agent = Agent(settings, RecordedMotor(w, clock, tick_log),
                      RecordedSwarm(net, int(rid), clock, tick_log), clock)
        agents.append((agent, tick_log))
        logs.append(log)
        wheels.append(w)
    phases = rng.uniform(0.0, period, len(agents))
    centers, radii = sc.obstacles.centers, sc.obstacles.radii
    next_detect = -math.inf
    steps = int(round(args.seconds / period))
    for k in range(steps):
        order = sorted(range(len(agents)), key=lambda i: phases[i])
        for i in order:
            agent, tick_log = agents[i]
            clock.now = 1000.0 + k * period + phases[i] + rng.uniform(0.0, 0.3 * period)
            tick_log.clear()
            if k == 0:
                agent.arm()
                agent.set_mode(AgentMode.FORMATION)
            agent.tick(k)
            logs[i]["ticks"].append((clock.monotonic(), clock.wall(), dict(tick_log),
                                     k == 0))
        now = clock.wall()
        if now >= next_detect and len(radii):
            next_detect = now + DETECT_EVERY
            for (agent, _), w in zip(agents, wheels):
                w.advance(clock.monotonic())
                d = np.hypot(centers[:, 0] - w.pose[0], centers[:, 1] - w.pose[1]) - radii
                seen = d <= sc.sensing_range
                msg = ObstaclesMsg(agent.s.robot_id, k, now, centers[seen], radii[seen])
                net.detections[agent.s.robot_id] = ObstaclesMsg.decode(msg.encode())
    governed = sum(a.counters.governed for a, _ in agents)
    law = sum(a.counters.law_steps for a, _ in agents)
    with open(args.out, "wb") as fh:
        pickle.dump(logs, fh)
    print(f"recorded {len(agents)} agents x {steps} ticks into {args.out}; governor acted in "
          f"{governed / max(law, 1):.0%} of the law's periods")


class ReplayClock:
    def __init__(self) -> None:
        self.mono = self.wall_time = 0.0

    def monotonic(self) -> float:
        return self.mono

    def wall(self) -> float:
        return self.wall_time

    def sleep_until(self, deadline: float) -> None: ...


class ReplayMotor:
    def __init__(self) -> None:
        self.tick: dict = {}
        self.commands: list[tuple[float, float]] = []

    def arm(self) -> None: ...
    def disarm(self) -> None: ...
    def clear_errors(self) -> None: ...

    def command(self, right: float, left: float) -> None:
        self.commands.append((float(right), float(left)))

    def feedback(self) -> WheelFeedback | None:
        fb: WheelFeedback | None = self.tick.get("feedback")
        return fb


class ReplaySwarm:
    def __init__(self) -> None:
        self.tick: dict = {}

    def publish(self, state: StateMsg) -> None: ...

    def neighbours(self):
        return MappingProxyType(self.tick.get("neighbours", {}))

    def obstacles(self) -> ObstaclesMsg | None:
        msg: ObstaclesMsg | None = self.tick.get("obstacles")
        return msg

    def mission(self) -> MissionMsg | None:
        msg: MissionMsg | None = self.tick.get("mission")
        return msg


def replay(args: argparse.Namespace) -> None:
    with open(args.recording, "rb") as fh:
        logs = pickle.load(fh)
    digest = hashlib.sha256()
    commands = []
    for log in logs:
        clock, motor, swarm = ReplayClock(), ReplayMotor(), ReplaySwarm()
        agent = Agent(log["settings"], motor, swarm, clock)
        for mono, wall, tick, start in log["ticks"]:
            clock.mono, clock.wall_time = mono, wall
            motor.tick = swarm.tick = tick
            if start:
                agent.arm()
                agent.set_mode(AgentMode.FORMATION)
            before = len(motor.commands)
            agent.tick()
            if len(motor.commands) == before:
                motor.commands.append((math.nan, math.nan))
        cmds = np.asarray(motor.commands, dtype=np.float64)
        digest.update(cmds.tobytes())
        commands.append(cmds)
    print(f"{sum(len(c) for c in commands)} commands of {len(commands)} agents: "
          f"sha256 {digest.hexdigest()}")
    if args.out:
        np.savez(args.out, *commands)
    if args.against:
        other = np.load(args.against)
        for n, mine in enumerate(commands):
            theirs = other[f"arr_{n}"]
            differ = ~((mine == theirs) | (np.isnan(mine) & np.isnan(theirs))).all(axis=1)
            if differ.any():
                first = int(np.flatnonzero(differ)[0])
                worst = float(np.nanmax(np.abs(mine - theirs)))
                print(f"agent {n}: {int(differ.sum())} of {len(mine)} ticks differ, the first "
                      f"at tick {first}, at most {worst:.3g} rev/s")
            else:
                print(f"agent {n}: all {len(mine)} ticks equal")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="what", required=True)
    rec = sub.add_parser("record")
    rec.add_argument("--scenario", required=True)
    rec.add_argument("--robot", help="robot profile (default: the scenario's [robot])")
    rec.add_argument("--seconds", type=float, default=20.0)
    rec.add_argument("--delay", type=float, default=0.05, help="s, the states' mean age")
    rec.add_argument("--jitter", type=float, default=0.02, help="s, its standard deviation")
    rec.add_argument("--loss", type=float, default=0.1, help="share of states lost")
    rec.add_argument("--seed", type=int, default=0)
    rec.add_argument("--out", required=True)
    rep = sub.add_parser("replay")
    rep.add_argument("recording")
    rep.add_argument("--out", help="keep the commands (.npz)")
    rep.add_argument("--against", help="compare with another replay's --out")
    args = ap.parse_args()
    record(args) if args.what == "record" else replay(args)


if __name__ == "__main__":
    main()
