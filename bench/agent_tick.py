"""Cost of one agent tick (read, law, write) with 20 neighbours and 3 obstacles in range.

An agent (agent.node.Agent, interpreted as on a robot computer) on in-memory ports
(tests/fakes.py) ticks on simulated time among 20 neighbours whose states are refreshed every
period and 3 obstacle detections; prints the median and the 99th percentile of the tick's
wall time. Uses only the agent's public API, so it runs unchanged on older commits
(bench/side_by_side.py).

    .venv/bin/python bench/agent_tick.py [--ticks 3000]
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd() / "tests"))

from fakes import MirrorMotor, SharedSwarm  # noqa: E402
from helpers import SimClock  # noqa: E402

from agent.node import Agent  # noqa: E402
from agent.settings import AgentSettings  # noqa: E402
from common.payloads import MissionMsg, ObstaclesMsg, StateMsg  # noqa: E402
from common.vocabulary import AgentMode, StateFlags  # noqa: E402

NEIGHBOURS = 20


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=3000)
    args = ap.parse_args()
    clock = SimClock()
    net = SharedSwarm(clock)
    ids = np.arange(1, NEIGHBOURS + 2)
    offsets = np.column_stack([np.zeros(len(ids)), 3.0 * np.arange(len(ids))])
    net.mission_msg = MissionMsg(1, clock.wall(), clock.wall(), (40.0, 0.0), (2.0, 0.0), 0.0,
                                 ids, offsets)
    agent = Agent(AgentSettings(robot_id=1, swarm="b", initial_pose=(0.0, 0.0, 0.0),
                                autostart=True), MirrorMotor(clock), net.port(1), clock)
    others = [net.port(int(r)) for r in ids[1:]]
    angles = np.linspace(0.0, 2.0 * math.pi, NEIGHBOURS, endpoint=False)
    obstacles = ObstaclesMsg(1, 1, clock.wall(), np.array([[5.0, 5.0], [-5.0, 4.0], [6.0, -3.0]]),
                             np.array([1.0, 1.5, 0.8]))
    net.obstacle_msgs[1] = obstacles
    agent.arm()
    agent.set_mode(AgentMode.FORMATION)
    times = []
    for k in range(args.ticks):
        x, y = agent.odometry.pose[:2]
        for n, (port, a) in enumerate(zip(others, angles)):
            r = 3.0 + 0.2 * n
            port.publish(StateMsg(n + 2, k + 1, clock.wall(), x + r * math.cos(a),
                                  y + r * math.sin(a), a, 1.0, 0.1, 0.0, 0.0, 0,
                                  StateFlags.ARMED))
        t0 = time.perf_counter_ns()
        agent.tick()
        times.append(time.perf_counter_ns() - t0)
        clock.now += 0.02
    us = np.asarray(times[args.ticks // 10:]) / 1e3
    print(f"agent tick, {NEIGHBOURS} neighbours, 3 obstacles: median {np.median(us):.0f} us, "
          f"p99 {np.percentile(us, 99):.0f} us")


if __name__ == "__main__":
    main()
