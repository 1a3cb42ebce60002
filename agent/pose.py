"""Odometry fused with pose fixes from an external source (motion capture): docs/pose.md.

The estimate is the odometry pose moved by one rigid transform of the plane (a rotation by
``phi`` then a translation), so the odometry's own increments are kept exactly. A fix
stamped ``t_fix`` (capture time, UNIX [s]) is compared with the estimate *at t_fix* (the
odometry kept over the last ``history`` seconds, interpolated), blended with it by a
scalar gain, and the transform is re-solved so that the estimate at t_fix is the blend:
every odometry increment since t_fix is then re-applied on top of the corrected pose, which
compensates the fix's latency.

The position uncertainty ``u`` [m] is a bound on the estimate's position error: after a
fix, sqrt((1 - g) u_pred^2); it then grows by ``drift`` times the distance the wheels drove
(path length plus half the wheel base times the turn). The gain is
g = u_pred^2 / (u_pred^2 + e^2), e the fix's stated error bound: a fix replaces a poor
estimate and only nudges a good one (a scalar Kalman update with bounds for deviations).
Heading takes the same gain. Plain floats, a deque of tuples: the agent runs on small
computers.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from agent.kinematics import wrap_angle
from common.payloads import FixMsg
from common.schema import setting, validate

Pose = tuple[float, float, float]

TRUST_FLOOR = 0.1     # the estimate's bound is never taken below this share of a fix's


@dataclass(frozen=True)
class PoseSettings:
    """``[pose]`` of the agent config: the robot has an external pose source (motion
    capture) whose fixes arrive on ``boundswarm/<swarm>/robot/<id>/fix``. Absent: odometry
    alone."""

    fix_timeout: float = setting(0.5, unit="s", doc="a fix older than this (from its capture "
                                 "time): failsafe HOLD; arming needs a younger one",
                                 lo=0.0, open_lo=True)
    drift: float = setting(0.05, doc="odometry position error per metre the wheels drive "
                           "(wheel slip), growing the uncertainty between fixes",
                           lo=0.0, hi=1.0)
    history: float = setting(0.5, unit="s", doc="odometry kept to place a late fix at its "
                             "capture time; older fixes are dropped", lo=0.0, open_lo=True)

    def __post_init__(self) -> None:
        validate(self)


class PoseFusion:
    """The pose estimate (x, y, theta) [m, m, rad] of one robot from its odometry and
    fixes, and its position uncertainty [m] (inf before the first fix)."""

    def __init__(self, settings: PoseSettings, wheel_base: float):
        self.s, self.half_base = settings, 0.5 * wheel_base
        self._phi, self._cos, self._sin, self._tx, self._ty = 0.0, 1.0, 0.0, 0.0, 0.0
        # raw odometry: (t [s], x, y, theta, distance driven so far [m])
        self._hist: deque[tuple[float, float, float, float, float]] = deque()
        self._bound = math.inf        # m, uncertainty just after the last fix
        self._driven_at_fix = 0.0     # m, distance driven at the last fix's capture time
        self.last_stamp = -math.inf   # s, capture time of the last fix applied
        self.applied = 0
        self.dropped_late = 0         # fixes older than the history
        self.dropped_future = 0       # fixes stamped after now + fix_timeout (clocks apart)
        self.pose: Pose = (0.0, 0.0, 0.0)

    def _apply(self, x: float, y: float, theta: float) -> Pose:
        c, s = self._cos, self._sin
        return (c * x - s * y + self._tx, s * x + c * y + self._ty,
                wrap_angle(theta + self._phi))

    def update(self, t: float, odometry: Pose) -> Pose:
        """Take the odometry pose at ``t`` (UNIX [s]); returns the estimate."""
        x, y, theta = odometry
        hist = self._hist
        driven = 0.0
        if hist:
            _, px, py, pth, driven = hist[-1]
            driven += (math.hypot(x - px, y - py)
                       + self.half_base * abs(wrap_angle(theta - pth)))
        hist.append((t, x, y, theta, driven))
        while len(hist) > 2 and hist[1][0] < t - self.s.history:
            hist.popleft()
        self.pose = self._apply(x, y, theta)
        return self.pose

    @property
    def uncertainty(self) -> float:
        """Bound on the estimate's position error now [m]."""
        driven = self._hist[-1][4] if self._hist else 0.0
        return self._bound + self.s.drift * (driven - self._driven_at_fix)

    def age(self, now: float) -> float:
        """Seconds since the capture of the last fix applied (inf: none yet)."""
        return now - self.last_stamp

    def fix(self, msg: FixMsg) -> bool:
        """Correct the estimate with ``msg`` if it is new; False if it was not applied
        (already applied, captured before the odometry kept, or stamped later than now +
        ``fix_timeout``: a source whose clock is ahead, whose fix would never age)."""
        hist = self._hist
        if msg.stamp <= self.last_stamp or not hist:
            return False
        if msg.stamp < hist[0][0]:
            self.dropped_late += 1
            return False
        if msg.stamp > hist[-1][0] + self.s.fix_timeout:
            self.dropped_future += 1
            return False
        ox, oy, oth, driven = _at(hist, msg.stamp)
        ex, ey, eth = self._apply(ox, oy, oth)
        u_pred = max(self._bound + self.s.drift * (driven - self._driven_at_fix),
                     TRUST_FLOOR * msg.error)
        e2 = msg.error * msg.error
        if math.isinf(u_pred):                  # the first fix: taken as it is
            g, self._bound = 1.0, msg.error
        else:
            u2 = u_pred * u_pred
            g, self._bound = u2 / (u2 + e2), math.sqrt(u2 * e2 / (u2 + e2))
        cx, cy = ex + g * (msg.x - ex), ey + g * (msg.y - ey)
        cth = eth + g * wrap_angle(msg.theta - eth)
        # the transform that takes the odometry pose at the fix onto the blend
        self._phi = wrap_angle(cth - oth)
        self._cos, self._sin = math.cos(self._phi), math.sin(self._phi)
        self._tx = cx - (self._cos * ox - self._sin * oy)
        self._ty = cy - (self._sin * ox + self._cos * oy)
        self._driven_at_fix = driven
        self.last_stamp = msg.stamp
        self.applied += 1
        _, x, y, theta, _ = hist[-1]
        self.pose = self._apply(x, y, theta)
        return True


def _at(hist: deque[tuple[float, float, float, float, float]], t: float
        ) -> tuple[float, float, float, float]:
    """Odometry (x, y, theta, distance driven) at ``t``, interpolated between the samples
    around it (the newest one for a ``t`` after it)."""
    if t >= hist[-1][0]:
        _, x, y, theta, driven = hist[-1]
        return x, y, theta, driven
    k = len(hist) - 1
    while hist[k - 1][0] > t:
        k -= 1
    t0, x0, y0, th0, d0 = hist[k - 1]
    t1, x1, y1, th1, d1 = hist[k]
    w = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
    return (x0 + w * (x1 - x0), y0 + w * (y1 - y0), wrap_angle(th0 + w * wrap_angle(th1 - th0)),
            d0 + w * (d1 - d0))
