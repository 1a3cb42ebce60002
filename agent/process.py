"""The agent process: what runs on a robot computer (``boundswarm agent --config FILE``).

The one place where an agent is wired to the world: builds the real ports from the
validated settings (the robot's CAN bus with its two ODrive drivers, a Zenoh session), the
MAVLink link with the parameter table it serves, runs the agent's fixed-period loop until
SIGINT/SIGTERM, then shuts down cleanly: zero velocity, drivers IDLE, liveliness token
dropped, bus and session closed. Loop and agent statistics are written as JSON when asked.
A simulated swarm may run several agents in one process (:func:`run_agents`).

SIMULATION ONLY: with an ``[impairment]`` section (written by ``boundswarm sitl`` alone),
the Zenoh port is wrapped in :class:`agent.impairment.ImpairedSwarm` and a CRITICAL line
says so at start.
"""
from __future__ import annotations

import gc
import json
import logging
import signal
import time
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from agent.config import CONTROL_PARAMS
from agent.impairment import ImpairedSwarm
from agent.loop import FixedRateLoop, LoopStats, SystemClock, use_normal_scheduling, use_realtime
from agent.node import Agent
from agent.period_log import PeriodLog
from agent.settings import AgentSettings
from agent.systemd import Notifier
from common.ports import SwarmPort
from common.vocabulary import AgentMode
from transport.canbus import open_bus
from transport.mavlink_link import MavlinkLink, VehicleState, open_link
from transport.wheel_drivers import WheelDrivers
from transport.zenoh_link import (
    FixLink,
    Keys,
    SwarmLink,
    config_from_file,
    open_session,
    session_config,
)

log = logging.getLogger(__name__)


class AgentVehicle:
    """The agent as the vehicle a ground station commands (transport.mavlink_link's
    VehicleControl): commands and parameter writes (Agent.set_param) apply at the next
    period."""

    def __init__(self, agent: Agent):
        self.agent = agent

    def state(self) -> VehicleState:
        a = self.agent
        x, y, theta = a.pose
        return VehicleState(a.mode, a.failsafe, x, y, theta, *a.command, a.deadlock)

    def arm(self) -> str | None:
        return self.agent.arm()

    def disarm(self) -> str | None:
        self.agent.disarm()
        return None

    def set_mode(self, mode: AgentMode) -> str | None:
        return self.agent.set_mode(mode)

    def param(self, name: str) -> float:
        return self.agent.param(name)

    def set_param(self, name: str, value: float) -> str | None:
        return self.agent.set_param(name, value)


def check_group(group: Sequence[AgentSettings]) -> None:
    """Agents share one process only where they share its loop and its Zenoh session: the
    same period, tick grid, scheduling and Zenoh settings, and distinct robot IDs."""
    if not group:
        raise ValueError("no agent config given")
    first = group[0]
    same = {"[control] period": lambda s: s.control.period,
            "align_ticks": lambda s: s.align_ticks, "tick_phase": lambda s: s.tick_phase,
            "realtime_priority": lambda s: s.realtime_priority, "[zenoh]": lambda s: s.zenoh}
    for s in group[1:]:
        for name, get in same.items():
            if get(s) != get(first):
                raise ValueError(f"robots {first.robot_id} and {s.robot_id} cannot share a "
                                 f"process: their {name} differ ({get(first)!r}, {get(s)!r})")
    ids = [s.robot_id for s in group]
    if len(set(ids)) != len(ids):
        raise ValueError(f"a robot ID appears twice among the configs: {ids}")
    buses = [(s.can.interface, s.can.channel, s.can.port) for s in group]
    if len(set(buses)) != len(buses):
        raise ValueError(f"two robots on one CAN bus (interface, channel, port): {buses}")


@dataclass
class _Hosted:
    """One agent of a process, with the ports it was given and its own tick timing."""

    settings: AgentSettings
    agent: Agent
    motor: WheelDrivers
    swarm: SwarmLink
    link: MavlinkLink
    impaired: ImpairedSwarm | None
    fixes: FixLink | None
    stats: LoopStats
    autostart: bool


def _open_agent(s: AgentSettings, session, clock: SystemClock, rt: int,
                stack: ExitStack) -> _Hosted:
    """Build one agent and its ports (its CAN bus, its links on ``session``); every port is
    closed by ``stack``."""
    bus = open_bus(s.can.interface, s.can.channel, port=s.can.port, bitrate=s.can.bitrate)
    stack.callback(bus.shutdown)
    motor = WheelDrivers(bus, s.can.left_node, s.can.right_node,
                         vel_limit=s.robot.wheel_speed_limit, clock=clock.monotonic)
    swarm = SwarmLink(session, Keys(s.swarm), s.robot_id, clock.wall,
                      near_radius=s.zenoh.near_radius,
                      # the near-set thread takes the interpreter lock the loop needs:
                      # scheduled as the loop, it is never starved while holding it
                      thread_setup=(lambda: use_realtime(rt)) if rt > 0 else None)
    stack.callback(swarm.close)
    port: SwarmPort = swarm
    impaired = None
    if s.impairment is not None:
        port = impaired = ImpairedSwarm(swarm, s.robot_id, s.impairment, clock.wall)
        log.critical("robot %d: SIMULATION ONLY: neighbour states pass an impaired link "
                     "(%s); a real robot's config has no [impairment] section",
                     s.robot_id, s.impairment.describe())
    fixes = None
    if s.pose is not None:
        fixes = FixLink(session, Keys(s.swarm), s.robot_id, clock.wall)
        stack.callback(fixes.close)
    periods = None
    if s.record_periods is not None:
        periods = PeriodLog(s.record_periods)
        stack.callback(periods.close)
    agent = Agent(s, motor, port, clock, fixes, periods)
    link = open_link(s.mavlink, AgentVehicle(agent), s.robot_id, clock.monotonic,
                     clock.wall, params=CONTROL_PARAMS)
    stack.callback(link.close)
    # autostart arms once the pose can be trusted (at once without a pose source)
    if s.autostart and s.pose is not None:
        log.info("robot %d: autostart waits for a pose fix", s.robot_id)
    return _Hosted(s, agent, motor, swarm, link, impaired, fixes, LoopStats(s.control.period),
                   s.autostart)


def run_agents(group: Sequence[AgentSettings], stats_paths: Sequence[Path | None],
               max_ticks: int | None = None) -> list[dict]:
    """Run the agents of ``group`` in this process until a signal (or ``max_ticks``), one
    after the other in each tick of one loop, on one Zenoh session; returns each one's
    statistics (written to its ``stats_paths`` entry unless None).

    A robot computer runs one agent. Several in one process serve a simulated swarm on a
    machine with fewer cores than robots (``boundswarm sitl --agents-per-process``): the
    same agent code and ports, with one process's loop, session and interpreter warmed by
    all of them instead of one each. Each agent's jitter and compute time are its own (its
    tick's start against the deadline); missed periods are the process's, so every agent
    of it misses them."""
    check_group(group)
    if len(stats_paths) != len(group):
        raise ValueError(f"{len(group)} agent configs but {len(stats_paths)} stats paths")
    s0 = group[0]
    clock = SystemClock()
    t0 = time.monotonic()
    # Zenoh's threads, started with the session below, inherit this: one step under the
    # loop. Never starved by normally scheduled work, they never hold up the loop on the
    # locks it shares with them (the receive rings); never above it, a burst of samples
    # never delays a period. Not granted (one warning): everything runs normally
    rt = (s0.realtime_priority if s0.realtime_priority > 0
          and use_realtime(max(s0.realtime_priority - 1, 1)) else 0)
    ids = " ".join(str(s.robot_id) for s in group)
    with ExitStack() as stack:
        conf = (config_from_file(s0.zenoh.config) if s0.zenoh.config else
                session_config(s0.zenoh.mode, s0.zenoh.listen, s0.zenoh.connect))
        session = open_session(conf, f"agent {ids}")
        stack.callback(session.close)
        hosted = [_open_agent(s, session, clock, rt, stack) for s in group]
        realtime = rt > 0 and use_realtime(rt)
        loop = FixedRateLoop(s0.control.period, clock,
                             s0.tick_phase if s0.align_ticks else None)
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: loop.stop())
        for h in hosted:
            log.info("agent %d running at %g Hz", h.settings.robot_id,
                     1.0 / s0.control.period)
        notifier = Notifier()
        overruns = [0]

        def tick(k: int, deadline: float) -> None:
            for h in hosted:
                start = clock.monotonic()
                agent = h.agent
                if h.autostart and agent.pose_problem() is None:
                    h.autostart = False
                    agent.arm()
                    agent.set_mode(AgentMode.FORMATION)
                agent.tick(k, deadline)
                h.link.poll(clock.monotonic())          # bounded, never blocks
                h.stats.record(start - deadline, clock.monotonic() - start)
            if not notifier.enabled:            # not under systemd: nothing to tell it
                return
            if not notifier.ready_sent and all(
                    (fb := h.agent.last_feedback) is not None and fb.closed_loop
                    and h.agent.failsafe is None for h in hosted):
                notifier.ready(f"robot {ids} armed")
            on_time = loop.stats.overruns == overruns[0]
            overruns[0] = loop.stats.overruns
            notifier.watchdog(clock.monotonic(),
                              on_time and all(h.agent.failsafe is None for h in hosted))

        gc.freeze()       # start-up objects are never scanned again: no long GC pause in a tick
        try:
            with ExitStack() as stops:      # every agent stops, whatever another one raises
                for h in hosted:
                    stops.callback(h.agent.shutdown)
                stops.callback(notifier.stopping)       # first
                loop.run(tick, max_ticks=max_ticks)
        finally:
            if realtime:
                use_normal_scheduling()     # what is left is bookkeeping
        cpu, wall = time.process_time(), time.monotonic() - t0
        return [_statistics(h, loop.stats, cpu / len(hosted), wall, realtime, len(hosted), path)
                for h, path in zip(hosted, stats_paths)]


def _statistics(h: _Hosted, process_loop: LoopStats, cpu: float, wall: float, realtime: bool,
                hosted: int, path: Path | None) -> dict:
    """One agent's statistics: its ticks' timing with the process's missed periods, its
    share of the process's CPU time [s] (an equal share when it has company), its links."""
    h.stats.overruns = process_loop.overruns
    h.stats.overrun_events = process_loop.overrun_events
    h.stats.unlogged = process_loop.unlogged
    agent, s = h.agent, h.settings
    stats = {"robot_id": s.robot_id, "loop": h.stats.summary(),
             "cpu_seconds": cpu, "wall_seconds": wall, "agents_in_process": hosted,
             "agent": agent.counters.summary(), "zenoh": h.swarm.counters(),
             "can": {"sent": h.motor.sent, "ignored": dict(h.motor.ignored)},
             "mavlink": h.link.counter_summary(),
             "failsafe": agent.failsafe, "realtime": realtime}
    if h.impaired is not None:
        stats["impairment"] = h.impaired.counters()
    if h.fixes is not None and agent.fusion is not None:
        stats["pose"] = {"fixes": h.fixes.counters(), "applied": agent.fusion.applied,
                         "dropped_late": agent.fusion.dropped_late,
                         "dropped_future": agent.fusion.dropped_future}
    if path is not None:
        path.write_text(json.dumps(stats, indent=2) + "\n")
    return stats
