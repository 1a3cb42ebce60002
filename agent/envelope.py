"""What the safety governor lets a robot do: the statement a run makes at start.

For a profile, a sensing range and an expected data age: the top speed, the speed toward a
robot met head-on at the edge of the sensing range, the disc of a neighbour driving beside
the robot at the formation's pace (which sets how far apart two robots must be for a third
to pass between them) and the least gap behind one at that pace that lets the robot keep
it. Computed with the governor's own functions (agent.discs, agent.governor).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from agent.braking import braking_speed
from agent.config import ControlParams, RobotParams
from agent.discs import neighbour_radii
from agent.governor import NO_GAPS, braking_of, fold_hazard, frame_limits, limit_frame
from agent.params import LawParams, NeighbourModel
from agent.trail import SPLITS, straight


@dataclass(frozen=True)
class SpeedEnvelope:
    """What the safety governor lets a robot do, for a statement at start."""

    top: float          # m/s, the fastest it is commanded and can go (K D_max, its wheels)
    head_on: float      # m/s, the fastest the governor allows toward a robot just sensed
    sensing_range: float  # m
    data_age: float     # s, the expected age of neighbour data
    pace: float = 0.0   # m/s, the speed of the formation's places
    beside: float = 0.0  # m, the disc of a neighbour driving beside the robot at the pace
    follow: float = 0.0  # m, the least gap behind a robot at the pace that lets it keep it

    def describe(self) -> str:
        verdict = ("never limits driving in the open" if self.head_on >= self.top else
                   f"limits the robot to {self.head_on:.2f} m/s toward a robot it has just "
                   f"sensed {self.sensing_range:g} m away")
        return (f"safety governor: top speed {self.top:.2f} m/s; with neighbour data "
                f"{self.data_age * 1e3:.0f} ms old it {verdict}; a robot driving beside "
                f"it at the places' {self.pace:.2f} m/s is a disc of {self.beside:.2f} m: it "
                f"passes between two such robots only where they are more than "
                f"{self.passable:.2f} m apart; behind one it keeps that pace only "
                f"{self.follow:.2f} m or more back")

    @property
    def passable(self) -> float:
        """The least distance [m] between two robots driving side by side at the pace that
        a robot can pass between: it owns half the gap beyond each one's disc, so the
        gap must be wider than both discs."""
        return 2.0 * self.beside


def _model(control: ControlParams, robot: RobotParams) -> NeighbourModel:
    """The neighbours of a robot of this profile, heard from however old their data."""
    return NeighbourModel.of(LawParams.of(control, robot), control.a, control.period,
                             math.inf, robot.watchdog_timeout)


def speed_envelope(control: ControlParams, robot: RobotParams, sensing_range: float,
                   data_age: float = 0.0, pace: float = 0.0) -> SpeedEnvelope:
    """The governor's speed toward a robot met head-on at the edge of the sensing range
    [m]: each robot owns half the gap beyond a, less what the other travels in the data's
    age [s] at the top speed, and must stop in it after a period and the drive latency.
    And the disc (agent.discs.neighbour_radii: the radius of the gap's shared half) of a
    neighbour abeam that, like this robot, drives straight on at ``pace`` [m/s]."""
    top = min(control.v_max, robot.v_wheel_max)
    free = 0.5 * (sensing_range - control.a) - top * data_age
    head_on = braking_speed(free, robot.a_max, control.period + robot.drive_latency)
    # this robot's motion over each split of the age, straight north at the pace; the
    # neighbour's report, data_age old, puts it that much behind
    trail = straight(pace, 0.0, 1.0, data_age, SPLITS)
    beside = neighbour_radii(-sensing_range, trail.walked[0], 0.5 * math.pi, pace, 0.0,
                             data_age, trail, _model(control, robot)).half
    follow = _follow(control, robot, sensing_range, data_age, pace)
    return SpeedEnvelope(top, head_on, sensing_range, data_age, pace, beside, follow)


def _follow(control: ControlParams, robot: RobotParams, sensing_range: float,
            data_age: float, pace: float) -> float:
    """The least gap [m] (to within a millimetre, at most ``sensing_range``) to a robot
    straight ahead, both driving along the same line at ``pace`` [m/s], at which the
    governor lets the robot behind go on at the pace, with data ``data_age`` [s] old:
    the law's governor (agent.governor.braking_of) on the one hazard of the robot ahead."""
    p = LawParams.of(control, robot)
    model = _model(control, robot)
    trail = straight(pace, 1.0, 0.0, data_age, SPLITS)   # this robot, east at the pace
    frame = limit_frame(0.0, pace, 0.0, braking_of(p, control.period))

    def keeps_pace(gap: float) -> bool:
        report = gap - pace * data_age      # m, east: where the one ahead was at its stamp
        disc = neighbour_radii(-report, 0.0, 0.0, pace, 0.0, data_age, trail, model)
        gaps = fold_hazard(NO_GAPS, frame, report + disc.east, disc.north, disc.full,
                           disc.half, 1.0)
        return frame_limits(gaps, frame).fwd >= pace

    lo, hi = control.a, sensing_range
    if pace <= 0.0 or keeps_pace(lo):
        return lo
    if not keeps_pace(hi):
        return hi
    while hi - lo > 1e-3:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if keeps_pace(mid) else (mid, hi)
    return hi
