"""Helpers shared by the tests: free loopback ports, simulated time, process checks, and
whether a wall-clock run had the CPU it needed."""
from __future__ import annotations

import math
import os
import socket

import pytest

from agent.params import NeighbourModel

# When a wall-clock swarm run had the machine it needed, so that its liveness (it converges,
# no failsafe or watchdog trip) says something about the swarm: the share of the CPU a VM's
# host stole during the mission (hil.sitl.host_cpu), and the share of the mission's periods the
# worst agent missed. A swarm of 9 agents with their drivers, world and router needs about
# 1.6 of this machine's 2 cores; at the 27-63 % steal seen here on 2026-12-03 every agent
# starves, and runs in which every robot's drivers tripped their watchdog at once missed
# 3-4 % of their periods (a healthy run misses none, a VM stall costs up to 2 %).
STEAL_LIMIT = 0.15
MISSED_LIMIT = 0.02

KINDS = {"tcp": (socket.AF_INET, socket.SOCK_STREAM, "127.0.0.1"),
         "udp": (socket.AF_INET, socket.SOCK_DGRAM, "127.0.0.1"),
         "udp6": (socket.AF_INET6, socket.SOCK_DGRAM, "::1")}


def free_port(kind: str = "tcp") -> int:
    """A port that is free on loopback now (``tcp``, ``udp`` on 127.0.0.1, ``udp6`` on ::1)."""
    family, type_, host = KINDS[kind]
    with socket.socket(family, type_) as s:
        s.bind((host, 0))
        port: int = s.getsockname()[1]
        return port


class SimClock:
    """Monotonic time that advances only when slept or set (``now``); wall time is a fixed
    offset from it."""

    def __init__(self, start: float = 1000.0, wall_offset: float = 1.7e9):
        self.now, self.offset = start, wall_offset

    def monotonic(self) -> float:
        return self.now

    def wall(self) -> float:
        return self.offset + self.now

    def sleep_until(self, deadline: float) -> None:
        self.now = max(self.now, deadline)


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie child of this process does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:
        done, _ = os.waitpid(pid, os.WNOHANG)
        return done == 0
    except ChildProcessError:              # not our child: it exists, so it runs
        return True


def judge_liveness(steal: float | None, missed: float = 0.0) -> None:
    """Call after a wall-clock run's safety assertions, before its liveness ones: an
    expected failure (xfail, with what was measured) when the host starved the run (CPU
    stolen) or its loops could not keep time (``missed``: the worst agent's share of the
    mission's periods missed), since what follows says nothing about the swarm then."""
    if steal is not None and steal > STEAL_LIMIT:
        pytest.xfail(f"the host stole {steal:.0%} of the CPU in the mission (limit "
                     f"{STEAL_LIMIT:.0%}): safety held; liveness not judged on a starved run")
    if missed > MISSED_LIMIT:
        pytest.xfail(f"an agent missed {missed:.1%} of the mission's periods (limit "
                     f"{MISSED_LIMIT:.0%}): safety held; liveness not judged on a machine "
                     f"that did not keep time")


def model(**changes: float) -> NeighbourModel:
    """A neighbour model (agent.params.NeighbourModel) for the governor's tests: a = 1 m,
    half a wheel base 0.4 m, and every other limit none (infinite ramp, speed-up, turn
    speed-up, top speeds; no lag, no stop time; never silent) unless ``changes`` sets it."""
    inf = math.inf
    return NeighbourModel(**{**dict(a=1.0, accel=inf, half_base=0.4, top_speed=inf,
                                    staleness=inf, stop_time=0.0, wheel_top=inf, speed_up=inf,
                                    lag=0.0, turn_up=inf), **changes})


def sensed(agent, obstacles=None, now=None) -> tuple[list[tuple[float, float]],
                                                     list[tuple[float, float, float]]]:
    """What the agent's period takes into account at its pose (agent.period.sense) among
    what it hears and the ``obstacles`` message, ``now`` (wall time [s], default its
    clock's): the law's neighbours (x, y) [m] and obstacles (x, y, radius) [m]."""
    import numpy as np

    import agent.period as period
    from agent.formation import Places
    from agent.node import _workspace
    now = agent.clock.wall() if now is None else now
    recs = [r for rid, r in agent.swarm.neighbours().items() if rid != agent.s.robot_id]
    places = agent._places or Places(np.zeros((1, 2)), np.zeros(5))
    inputs = agent.inputs(agent.pose, recs, obstacles, places, now, 0.0, 0.02)
    ws = _workspace(len(recs) + inputs.detections.n + 1)
    n_nbr, n_obs, _ = period.sense(inputs, agent._params, ws)
    return ([(ws.nbr_x[q], ws.nbr_y[q]) for q in range(n_nbr)],
            [(ws.obs_x[k], ws.obs_y[k], ws.obs_r[k]) for k in range(n_obs)])


def governor_discs(monkeypatch: pytest.MonkeyPatch, agent, obstacles=None, now=None,
                   dt: float = 0.02) -> tuple[list[tuple[float, ...]], dict[int, float]]:
    """The hazards the agent's safety governor folds (agent.governor.fold_hazard) at its
    pose among what it hears and the ``obstacles`` message, ``now`` (wall time [s],
    default its clock's), in its period (agent.period.governor_limits): (east, north,
    full, half, moving) per hazard, east and north [m] from the agent; and the half radius
    [m] of the claim of each of the law's neighbours, by robot id."""
    import numpy as np

    import agent.period as period
    from agent.formation import Places
    from agent.node import _workspace
    folded: list[tuple[float, ...]] = []
    fold = period.fold_hazard

    def spy(gaps, frame, dx, dy, radius, half, moving):
        folded.append((dx, dy, radius, half, moving))
        return fold(gaps, frame, dx, dy, radius, half, moving)

    monkeypatch.setattr(period, "fold_hazard", spy)
    now = agent.clock.wall() if now is None else now
    recs = [r for rid, r in agent.swarm.neighbours().items() if rid != agent.s.robot_id]
    places = agent._places or Places(np.zeros((1, 2)), np.zeros(5))
    inputs = agent.inputs(agent.pose, recs, obstacles, places, now, 0.0, dt)
    ws = _workspace(len(recs) + inputs.detections.n + 1)
    n_nbr, _, n_cand = period.sense(inputs, agent._params, ws)
    period.governor_limits(inputs, agent.memory, n_cand, agent._params, ws)
    monkeypatch.setattr(period, "fold_hazard", fold)
    a = agent.s.control.a
    return folded, {recs[ws.nbr_row[q]].msg.robot_id: ws.nbr_grow[q] + a
                    for q in range(n_nbr)}
