"""What one robot's period reads of the settings: the law's gains and wheels, and what it
counts on of its neighbours, as plain records.

Derived from the settings (agent.config) once, at start and when a parameter changes; the
period (agent.period) reads only these, so that the agent runs it interpreted and the batch
simulator compiles the same source (firmware_sim.compiled). Metres, seconds, radians.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

if TYPE_CHECKING:
    from agent.config import ControlParams, RobotParams

TWO_PI = 2.0 * math.pi


class LawParams(NamedTuple):
    """The gains and distances the law reads (from :class:`agent.config.ControlParams`)."""

    K: float            # 1/s
    K_theta: float      # 1/s
    D_max: float        # m
    K_ij: float         # 1
    b: float            # m
    c: float            # m
    u_max: float        # rad/s
    hysteresis: float   # m
    accel: float        # m/s^2, braking deceleration (inf: an ideal robot)
    speed_up: float     # m/s^2, the most the law speeds up |v|
    turn_up: float      # m/s^2, the most the law speeds up the wheels' half difference
    latency: float      # s, from a command to the drivers applying it
    wheel_radius: float  # m
    wheel_base: float   # m
    speed_limit: float  # rev/s per wheel (inf: none)
    ramp: float         # rev/s^2 per wheel (inf: none)
    watchdog: float     # s the drivers go on with the last command should the agent die
    slip: float         # 1, the wheels' slip the governor allows for (0: none)
    governor: bool      # the safety governor acts
    sidestep: bool      # TRACK passes a neighbour in the way on its right
    pair_hysteresis: bool   # AVOID's hysteresis per pair (else per robot)
    exchange: float     # m^2, the least gain of a place exchange (0: none; agent.exchange)

    @classmethod
    def of(cls, control: ControlParams, robot: RobotParams | None) -> LawParams:
        """The law's view of the controller and of the robot (None: an ideal robot, whose
        wheels follow any command at once). ``law = "paper"`` turns the deadlock resolution
        off (sidestep, per-pair hysteresis and place exchange)."""
        inf = math.inf
        limits = ((robot.a_max, robot.a_up, robot.a_turn_up, robot.drive_latency,
                   robot.wheel_radius, robot.wheel_base, robot.wheel_speed_limit,
                   robot.wheel_ramp, robot.watchdog_timeout, robot.wheel_slip)
                  if robot is not None else (inf, inf, inf, 0.0, 1.0, 1.0, inf, inf, 0.0,
                                             0.0))
        resolve = control.law != "paper"
        return cls(control.K, control.K_theta, control.D_max, control.K_ij, control.b,
                   control.c, control.u_max, control.hysteresis, *limits, control.governor,
                   control.sidestep and resolve, control.pair_hysteresis and resolve,
                   control.exchange if resolve else 0.0)


class NeighbourModel(NamedTuple):
    """What a robot counts on of each neighbour (the swarm's robots are alike: a
    neighbour's limits are this robot's), for the safety governor's discs (agent.discs)."""

    a: float            # m, the collision distance
    accel: float        # m/s^2, each wheel's ramp: how fast its speed can change (inf: at once)
    half_base: float    # m, half its wheel base
    top_speed: float    # m/s, the fastest it goes
    staleness: float    # s, older data: silent, maybe dead
    stop_time: float    # s, how long a dead agent's drivers go on (watchdog, drive latency)
    wheel_top: float    # m/s, each wheel's top ground speed
    speed_up: float     # m/s^2, the most its law speeds it up (A17)
    lag: float          # s, how late its wheels follow the command it reports
    turn_up: float      # m/s^2, the most its law speeds up its wheels' half difference

    @classmethod
    def of(cls, p: LawParams, a: float, period: float, staleness: float, watchdog: float
           ) -> NeighbourModel:
        """The neighbours of a robot of law parameters ``p``, period [s] and ``watchdog``
        [s] (its drivers' watchdog, should its agent die), with the staleness limit [s]."""
        wheel_top = TWO_PI * p.wheel_radius * p.speed_limit
        top = p.K * p.D_max
        return cls(a, p.accel, 0.5 * p.wheel_base, top if top < wheel_top else wheel_top,
                   staleness, watchdog + p.latency, wheel_top, p.speed_up,
                   period + p.latency, p.turn_up)


class PeriodParams(NamedTuple):
    """Everything one robot's period reads of its settings (agent.period.robot_period)."""

    law: LawParams
    model: NeighbourModel
    sensing_range: float    # m: neighbours' centres and obstacles' surfaces within it count

    @classmethod
    def of(cls, control: ControlParams, robot: RobotParams | None, sensing_range: float,
           staleness: float, watchdog: float) -> PeriodParams:
        """From the settings (``robot`` None: the batch simulator's ideal robot, whose
        drivers' ``watchdog`` [s] is given apart)."""
        law = LawParams.of(control, robot)
        return cls(law, NeighbourModel.of(law, control.a, control.period, staleness, watchdog),
                   sensing_range)
