"""The plant as a process: emulated drivers (and, in SITL, the robots' motion) in real time.

* :func:`run_drivers_only` serves one robot's two emulated drivers on a bus: the HIL bench
  where a PC with a CAN adapter stands in for the motor drivers of a real robot computer.
* :func:`run_sitl_plant` hosts several robots of a scenario: each robot's drivers on its own
  bus, motion from the drivers' actual wheel speeds, truth and obstacle detections on Zenoh;
  the scenario's ``[world]`` slips the wheels, adds noise to the encoder estimates the
  drivers report and to the detections, and drops detections (docs/world.md).

Both run a fixed-rate loop on the system clock until SIGINT/SIGTERM; the SITL plant steps
its physics by the time that really passed since the last tick, so an overrun on a loaded
machine delays the world's updates but never slows its clock.
"""
from __future__ import annotations

import gc
import logging
import math
import signal
import time
from typing import Callable, Iterable

from agent.loop import FixedRateLoop, SystemClock, use_realtime
from common.payloads import MissionMsg, WheelsMsg
from firmware_sim.mocap_sim import SimulatedMocap
from firmware_sim.odrive_sim import DriverPair
from firmware_sim.sitl_plant import PlantRobot, SitlPlant
from transport.canbus import open_bus
from transport.zenoh_link import Arrivals, Keys, Latest, open_session, session_config

log = logging.getLogger(__name__)

MAX_STEP = 0.02   # s, longest physics step after a stall (the drivers' watchdog: 0.1 s or more)


def _stop_on_signals(stop: Callable[[], None]) -> None:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop())


def check_drivers_rate(rate: float) -> float:
    """``rate`` [Hz] if the drivers' loop can run at it, else ValueError saying why."""
    if not (math.isfinite(rate) and 100 <= rate <= 10000):
        raise ValueError(f"drivers' loop rate must be 100..10000 Hz (encoder estimates go out "
                         f"at 100 Hz), got {rate:g}")
    return rate


def run_drivers_only(drivers: DriverPair, rate: float = 200.0,
                     max_ticks: int | None = None,
                     publish_wheels: Callable[..., None] | None = None,
                     publish_period: float = 0.01, realtime_priority: int = 0) -> None:
    """Serve ``drivers`` at ``rate`` [Hz] until a signal (or ``max_ticks``); the axes advance
    by the time that really passed (at most MAX_STEP after a stall). ``publish_wheels(
    right_pos, left_pos, right_vel, left_vel, stamp)``, when given, is called every
    ``publish_period`` [s], for a world simulated on another host. ``realtime_priority`` >
    0: the loop runs SCHED_FIFO at it (emulated hardware, which on a robot is a separate
    board, must not starve when the robot computer's loops load this one)."""
    if realtime_priority:
        use_realtime(realtime_priority)
    clock = SystemClock()
    loop = FixedRateLoop(1.0 / check_drivers_rate(rate), clock)
    _stop_on_signals(loop.stop)
    last = [clock.monotonic()]
    next_publish = [last[0]]

    def tick(k: int, deadline: float) -> None:
        now = clock.monotonic()
        drivers.service(now)
        drivers.step(min(now - last[0], MAX_STEP))
        last[0] = now
        if publish_wheels is not None and now >= next_publish[0]:
            next_publish[0] = max(next_publish[0] + publish_period, now)
            publish_wheels(*drivers.wheel_state(), clock.wall())

    gc.freeze()           # start-up objects are never scanned again: no long GC pause in a tick
    try:
        loop.run(tick, max_ticks=max_ticks)
    finally:
        drivers.close()
        log.info("drivers stopped after %d ticks (%d overruns)", loop.stats.ticks,
                 loop.stats.overruns)


class RemoteWheels:
    """A robot's wheels whose drivers run on another host (they publish WheelsMsg): every
    report, in order (:class:`firmware_sim.sitl_plant.WheelReports`); as drivers of the
    plant, nothing to serve or advance here."""

    def __init__(self, arrivals: Arrivals[WheelsMsg], robot_id: int):
        self.arrivals, self.robot_id = arrivals, robot_id

    def reports(self) -> list[tuple[float, float, float]]:
        return [(m.stamp, m.right_pos, m.left_pos) for m in self.arrivals.take(self.robot_id)]

    def fileno(self) -> None:
        """No bus here: the drivers are remote."""

    def service(self, now: float, receive: bool = True) -> None:
        """Nothing to serve: the drivers are remote."""

    def step(self, dt: float) -> None:
        """Nothing to advance: the drivers are remote."""

    def wheel_state(self) -> None:
        """Not read: the plant rolls a remote robot through its :meth:`reports`."""

    def close(self) -> None:
        """The subscription is closed by its owner."""


def _pose(pose: Iterable[float]) -> tuple[float, float, float]:
    """A scenario pose (x [m], y [m], theta [rad]) as three floats."""
    x, y, theta = map(float, pose)
    return x, y, theta


def _scenario_index(scenario) -> dict[int, int]:
    """Robot id -> its index in the scenario (the key of its random draws)."""
    return {int(rid): i for i, rid in enumerate(scenario.ids)}


def _run_plant(session, keys: Keys, robots: list[PlantRobot], scenario, dt: float,
               clock: SystemClock, realtime_priority: int = 0) -> dict:
    """Publish truth and obstacles (and, with the scenario's ``[mocap]``, pose fixes) of
    ``robots`` while moving them in real time until a signal; the physics steps by the time
    that really passed (a late tick must not slow the world). Returns the loop statistics."""
    kinds = ("truth", "obstacles") + (("fix",) if scenario.mocap is not None else ())
    publishers = {(kind, rb.robot_id): session.declare_publisher(getattr(keys, kind)(rb.robot_id))
                  for rb in robots for kind in kinds}
    mocap = mission = None
    if scenario.mocap is not None:       # its outages count from the mission's epoch
        mission = Latest(session, keys.mission, MissionMsg.decode, time.time)

        def epoch() -> float | None:
            got = mission.snapshot().get(0) if mission is not None else None
            return got.msg.epoch if got else None

        mocap = SimulatedMocap(scenario.mocap,
                               lambda rid, data: publishers[("fix", rid)].put(data), epoch)
    plant = SitlPlant(robots, scenario.robot, scenario.obstacles, scenario.sensing_range,
                      lambda kind, rid, data: publishers[(kind, rid)].put(data),
                      world=scenario.world, period=scenario.control.period,
                      index=_scenario_index(scenario), mocap=mocap)
    if not scenario.world.ideal:
        log.warning("imperfect world: %s", scenario.world)
    # on the agents' grid (their ticks fall on multiples of their period in UNIX time plus
    # their phase, these steps on multiples of dt): truth and detections go out with them
    loop = FixedRateLoop(dt, clock, phase=0.0)
    _stop_on_signals(loop.stop)
    if realtime_priority:
        use_realtime(realtime_priority)
    last = [clock.monotonic()]

    def tick(k: int, deadline: float) -> None:
        now = clock.monotonic()
        step, last[0] = min(now - last[0], MAX_STEP), now
        plant.step(step, now, clock.wall())

    gc.freeze()           # start-up objects are never scanned again: no long GC pause in a tick
    try:
        loop.run(tick)
    finally:
        if mission is not None:
            mission.close()
    stats = loop.stats.summary()
    if mocap is not None:
        stats["mocap"] = {"published": mocap.published, "lost": mocap.lost}
    return stats


def run_world(scenario, swarm: str, conf, dt: float = 0.005, realtime_priority: int = 0
              ) -> dict:
    """The world of a multi-host SITL: robots roll as the wheels of their remote drivers
    turn (published positions); truth and obstacle detections published. Runs until a
    signal."""
    clock = SystemClock()
    keys = Keys(swarm)
    session = open_session(conf, "the world")
    try:
        # a second of reports of every robot fits (a stalled link delivers in a burst)
        arrivals = Arrivals(session, keys.wheels("*"), WheelsMsg.decode,
                            capacity=256 * len(scenario.ids))
        wheels = [RemoteWheels(arrivals, int(rid)) for rid in scenario.ids]
        robots = [PlantRobot(w.robot_id, _pose(pose), w, remote=w)
                  for w, pose in zip(wheels, scenario.poses)]
        stats = _run_plant(session, keys, robots, scenario, dt, clock, realtime_priority)
        arrivals.close()
        return stats
    finally:
        session.close()


def run_sitl_plant(scenario, robot_ids: list[int], swarm: str, connect: list[str],
                   can_interface: str, can_channel: str | None, can_ports: dict[int, int],
                   dt: float = 0.005, enable_watchdog: bool = True,
                   realtime_priority: int = 0) -> dict:
    """Host robots ``robot_ids`` of ``scenario`` until a signal; returns loop statistics.
    The drivers' watchdog times out after the scenario robot's ``watchdog_timeout``
    (``enable_watchdog`` False: disabled).
    ``realtime_priority`` > 0: the plant loop runs SCHED_FIFO (emulated hardware must not
    starve when the agents load the machine)."""
    clock = SystemClock()
    t0 = time.monotonic()
    keys = Keys(swarm)
    session = open_session(session_config("client", connect=connect), "the plant")
    robots: list[PlantRobot] = []
    pairs: dict[int, DriverPair] = {}           # the emulated drivers of robots, by id
    try:
        index = _scenario_index(scenario)
        r, w = scenario.robot, scenario.world
        for rid in robot_ids:
            bus = open_bus(can_interface, can_channel, port=can_ports.get(rid))
            drivers = pairs[rid] = DriverPair(bus, latency=r.drive_latency,
                                              encoder_noise=w.encoder_noise, noise_seed=w.seed,
                                              noise_key=index[rid])
            drivers.configure(vel_limit=r.wheel_speed_limit, ramp=r.wheel_ramp,
                              enable_watchdog=enable_watchdog,
                              watchdog_timeout=r.watchdog_timeout)
            robots.append(PlantRobot(rid, _pose(scenario.poses[index[rid]]), drivers))
        stats = _run_plant(session, keys, robots, scenario, dt, clock, realtime_priority)
        stats["cpu_seconds"] = time.process_time()
        stats["wall_seconds"] = time.monotonic() - t0
        stats["watchdog_trips"] = {rid: sum(a.watchdog_trips for a in d.axes.values())
                                   for rid, d in pairs.items()}
        return stats
    finally:
        for rb in robots:
            rb.drivers.close()
        session.close()
