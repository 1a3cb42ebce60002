"""Cost of one agent tick (read, law, write) with 20 neighbours and 3 obstacles in range.

An agent (agent.node.Agent, interpreted as on a robot computer) on in-memory ports
(tests/fakes.py) ticks on simulated time among 20 neighbours whose states are refreshed every
period and 3 obstacle detections; prints the median and the 99th percentile of the tick's
wall time. Uses only the agent's public API, so it runs unchanged on older commits
(bench/side_by_side.py --this-script). The start-up objects are frozen out of the garbage
collector's reach before the ticks, as the agent process does.

With ``--governor-cost`` a second agent, the same but with the safety governor off
(``[control] governor = false``), ticks among the same neighbours in alternation, so both
see the same machine; the differences of the medians and of the 99th percentiles are what
the governor adds to a tick. ``--robot`` takes a robot profile (default: the SITL's
defaults). ``--data-age`` stamps the neighbours' states that many seconds before the tick
(default 0: stamped at the tick, where the governor has no data age to count and its
discs take their quickest path; on a network they are some milliseconds old), and
``--stamp-spread`` spreads the stamps over that many seconds more (robots stamp at their own
tick's start: on a network no two stamps are alike, and the governor then splits its own
motion for each neighbour it computes a disc for).

    .venv/bin/python bench/agent_tick.py [--ticks 3000] [--governor-cost] [--robot FILE]
                                         [--data-age S] [--stamp-spread S]
"""
from __future__ import annotations

import argparse
import gc
import logging
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd() / "tests"))

from fakes import MirrorMotor, SharedSwarm  # noqa: E402
from helpers import SimClock  # noqa: E402

from agent.config import ControlParams, RobotParams  # noqa: E402
from agent.node import Agent  # noqa: E402
from agent.settings import AgentSettings, TimeoutSettings  # noqa: E402
from common.payloads import MissionMsg, ObstaclesMsg, StateMsg  # noqa: E402
from common.vocabulary import AgentMode, StateFlags  # noqa: E402

NEIGHBOURS = 20


def make_agent(clock: SimClock, net: SharedSwarm, governor: bool,
               robot: RobotParams) -> Agent:
    """Robot 1, armed and in formation, on ``net``."""
    agent = Agent(AgentSettings(robot_id=1, swarm="b", initial_pose=(0.0, 0.0, 0.0),
                                autostart=True, robot=robot,
                                control=ControlParams(governor=governor)),
                  MirrorMotor(clock), net.port(1), clock)
    agent.arm()
    agent.set_mode(AgentMode.FORMATION)
    return agent


def timed_tick(agent: Agent, others: list, angles: list[float], k: int,
               clock: SimClock, age: float, spread: float = 0.0) -> int:
    """Publish the neighbours round ``agent``, their states stamped ``age`` [s] ago (the
    n-th of N ``spread`` n / N [s] more), tick it; the tick's wall time [ns]."""
    x, y = agent.odometry.pose[:2]
    for n, (port, a) in enumerate(zip(others, angles)):
        r = 3.0 + 0.2 * n
        stamp = clock.wall() - age - spread * n / len(others)
        port.publish(StateMsg(n + 2, k + 1, stamp, x + r * math.cos(a),
                              y + r * math.sin(a), a, 1.0, 0.1, 0.0, 0.0, 0,
                              StateFlags.ARMED))
    t0 = time.perf_counter_ns()
    agent.tick()
    return time.perf_counter_ns() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=3000)
    ap.add_argument("--governor-cost", action="store_true",
                    help="also tick an agent with the governor off, in alternation")
    ap.add_argument("--robot", metavar="FILE", help="robot profile (robots/*.toml)")
    ap.add_argument("--data-age", type=float, default=0.0, metavar="S",
                    help="the neighbours' states this old when the agent ticks [s]")
    ap.add_argument("--stamp-spread", type=float, default=0.0, metavar="S",
                    help="the neighbours' stamps spread over S [s] more age (robots stamp "
                         "at their own tick's start: on a LAN no two stamps are alike)")
    args = ap.parse_args()
    staleness = TimeoutSettings().staleness
    if not 0.0 <= args.data_age < staleness:
        ap.error(f"--data-age: from 0 up to the staleness limit, {staleness:g} s")
    robot = RobotParams()
    if args.robot:
        from hil.files.robot_profile import load_robot_profile
        robot = load_robot_profile(args.robot)
    # the bench's agent ticks in place among neighbours that do not move: the deadlock
    # watch would warn every 10 s of simulated time, which says nothing here
    logging.getLogger("agent.node").setLevel(logging.ERROR)
    clock = SimClock()
    net = SharedSwarm(clock)
    ids = np.arange(1, NEIGHBOURS + 2)
    offsets = np.column_stack([np.zeros(len(ids)), 3.0 * np.arange(len(ids))])
    net.mission_msg = MissionMsg(1, clock.wall(), clock.wall(), (40.0, 0.0), (2.0, 0.0), 0.0,
                                 ids, offsets)
    others = [net.port(int(r)) for r in ids[1:]]
    # plain floats, as a robot decodes them from the network
    angles = np.linspace(0.0, 2.0 * math.pi, NEIGHBOURS, endpoint=False).tolist()
    net.obstacle_msgs[1] = ObstaclesMsg(1, 1, clock.wall(),
                                        np.array([[5.0, 5.0], [-5.0, 4.0], [6.0, -3.0]]),
                                        np.array([1.0, 1.5, 0.8]))
    agents = {"with the governor": make_agent(clock, net, True, robot)}
    if args.governor_cost:
        agents["governor off"] = make_agent(clock, net, False, robot)
    times: dict[str, list[int]] = {name: [] for name in agents}
    order = list(agents)
    gc.freeze()          # as the agent process does after start-up (agent.process)
    for k in range(args.ticks):
        order.reverse()                  # neither agent always ticks first
        for name in order:
            times[name].append(timed_tick(agents[name], others, angles, k, clock,
                                          args.data_age, args.stamp_spread))
        clock.now += 0.02
    stats = {}
    for name, t in times.items():
        us = np.asarray(t[args.ticks // 10:]) / 1e3
        stats[name] = (float(np.median(us)), float(np.percentile(us, 99)))
        print(f"agent tick, {NEIGHBOURS} neighbours, 3 obstacles, {name}: "
              f"median {stats[name][0]:.0f} us, p99 {stats[name][1]:.0f} us")
    if args.governor_cost:
        (m1, p1), (m0, p0) = stats["with the governor"], stats["governor off"]
        print(f"the governor adds: median {m1 - m0:.0f} us, p99 {p1 - p0:.0f} us")


if __name__ == "__main__":
    main()
