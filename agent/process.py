"""The agent process: what runs on a robot computer (``boundswarm agent --config FILE``).

The one place where an agent is wired to the world: builds the real ports from the
validated settings (the robot's CAN bus with its two ODrive drivers, a Zenoh session), the
MAVLink link with the parameter table it serves, runs the agent's fixed-period loop until
SIGINT/SIGTERM, then shuts down cleanly: zero velocity, drivers IDLE, liveliness token
dropped, bus and session closed. Loop and agent statistics are written as JSON when asked.

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
from pathlib import Path

from agent.config import CONTROL_PARAMS
from agent.impairment import ImpairedSwarm
from agent.loop import FixedRateLoop, SystemClock, use_normal_scheduling, use_realtime
from agent.node import Agent
from agent.settings import AgentSettings
from agent.systemd import Notifier
from common.ports import SwarmPort
from common.vocabulary import AgentMode
from transport.canbus import open_bus
from transport.mavlink_link import VehicleState, open_link
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


def run_agent(settings: AgentSettings, stats_path: Path | None = None,
              max_ticks: int | None = None) -> dict:
    """Run one agent until a signal (or ``max_ticks``); returns its statistics."""
    s = settings
    clock = SystemClock()
    t0 = time.monotonic()
    # Zenoh's threads, started with the session below, inherit this: one step under the
    # loop. Never starved by normally scheduled work, they never hold up the loop on the
    # locks it shares with them (the receive rings); never above it, a burst of samples
    # never delays a period. Not granted (one warning): everything runs normally
    rt = (s.realtime_priority if s.realtime_priority > 0
          and use_realtime(max(s.realtime_priority - 1, 1)) else 0)
    bus = open_bus(s.can.interface, s.can.channel, port=s.can.port, bitrate=s.can.bitrate)
    session = swarm = link = fixes = None
    try:
        motor = WheelDrivers(bus, s.can.left_node, s.can.right_node,
                             vel_limit=s.robot.wheel_speed_limit, clock=clock.monotonic)
        conf = (config_from_file(s.zenoh.config) if s.zenoh.config else
                session_config(s.zenoh.mode, s.zenoh.listen, s.zenoh.connect))
        session = open_session(conf, f"agent {s.robot_id}")
        swarm = SwarmLink(session, Keys(s.swarm), s.robot_id, clock.wall,
                          near_radius=s.zenoh.near_radius,
                          # the near-set thread takes the interpreter lock the loop needs:
                          # scheduled as the loop, it is never starved while holding it
                          thread_setup=(lambda: use_realtime(rt)) if rt > 0 else None)
        port: SwarmPort = swarm
        impaired = None
        if s.impairment is not None:
            port = impaired = ImpairedSwarm(swarm, s.robot_id, s.impairment, clock.wall)
            log.critical("robot %d: SIMULATION ONLY: neighbour states pass an impaired link "
                         "(%s); a real robot's config has no [impairment] section",
                         s.robot_id, s.impairment.describe())
        if s.pose is not None:
            fixes = FixLink(session, Keys(s.swarm), s.robot_id, clock.wall)
        agent = Agent(s, motor, port, clock, fixes)
        link = open_link(s.mavlink, AgentVehicle(agent), s.robot_id, clock.monotonic,
                         clock.wall, params=CONTROL_PARAMS)
        realtime = rt > 0 and use_realtime(rt)
        loop = FixedRateLoop(s.control.period, clock, s.tick_phase if s.align_ticks else None)
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: loop.stop())
        # autostart arms once the pose can be trusted (at once without a pose source)
        autostart = [s.autostart]
        if s.autostart and s.pose is not None:
            log.info("robot %d: autostart waits for a pose fix", s.robot_id)
        log.info("agent %d running at %g Hz", s.robot_id, 1.0 / s.control.period)
        notifier = Notifier()
        overruns = [0]

        def tick(k: int, deadline: float) -> None:
            if autostart[0] and agent.pose_problem() is None:
                autostart[0] = False
                agent.arm()
                agent.set_mode(AgentMode.FORMATION)
            agent.tick(k, deadline)
            link.poll(clock.monotonic())          # bounded, never blocks
            fb = agent.last_feedback
            if fb is not None and fb.closed_loop and agent.failsafe is None:
                notifier.ready(f"robot {s.robot_id} armed")
            on_time = loop.stats.overruns == overruns[0]
            overruns[0] = loop.stats.overruns
            notifier.watchdog(clock.monotonic(), on_time and agent.failsafe is None)

        gc.freeze()       # start-up objects are never scanned again: no long GC pause in a tick
        try:
            loop.run(tick, max_ticks=max_ticks)
        finally:
            notifier.stopping()
            agent.shutdown()
            if realtime:
                use_normal_scheduling()     # what is left is bookkeeping
        stats = {"robot_id": s.robot_id, "loop": loop.stats.summary(),
                 "cpu_seconds": time.process_time(), "wall_seconds": time.monotonic() - t0,
                 "agent": agent.counters.summary(), "zenoh": swarm.counters(),
                 "can": {"sent": motor.sent, "ignored": dict(motor.ignored)},
                 "mavlink": link.counter_summary(),
                 "failsafe": agent.failsafe, "realtime": realtime}
        if impaired is not None:
            stats["impairment"] = impaired.counters()
        if fixes is not None and agent.fusion is not None:
            stats["pose"] = {"fixes": fixes.counters(), "applied": agent.fusion.applied,
                             "dropped_late": agent.fusion.dropped_late,
                             "dropped_future": agent.fusion.dropped_future}
        if stats_path is not None:
            stats_path.write_text(json.dumps(stats, indent=2) + "\n")
        return stats
    finally:
        if link is not None:
            link.close()
        if fixes is not None:
            fixes.close()
        if swarm is not None:
            swarm.close()
        if session is not None:
            session.close()
        bus.shutdown()
