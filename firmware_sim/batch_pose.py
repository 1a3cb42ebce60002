"""The motion-capture pose source in the batch simulator: each robot's odometry fused with
simulated fixes by the agent's own estimator (agent.pose.PoseFusion), as in the SITL.

The scenario's ``[mocap]`` table (firmware_sim.mocap_sim.MocapParams) is read as in the
SITL, with one difference of time: the batch sees the truth only at the control periods'
boundaries, so it captures there, at most once a period (every ``ceil(1 / (rate * period))``
periods). A capture is the true pose with Gaussian noise, stamped with its time and
delivered at the first period at least ``latency`` later; it is lost with probability
``dropout`` or in an outage (``[[mocap.outage]]``, mission time). The robots start at rest
with one fix of where they stand (as an agent arms only with a fix). A robot whose last fix
is older than ``fix_timeout`` goes to a failsafe HOLD for the rest of the run, as its agent
does.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from agent.pose import PoseFusion, PoseSettings
from common.payloads import FixMsg
from firmware_sim.mocap_sim import MocapParams


class BatchPoseSource:
    """Pose estimates (N, 4): x, y, theta [m, m, rad] and the position uncertainty [m] that
    grows the governor's hazards, for robots ``ids`` starting at ``pose0`` (N, 3); ``jump``
    (N, 2) [m]: how far the last step's fixes moved each estimate (for
    :func:`agent.law.moved_estimate`)."""

    def __init__(self, params: MocapParams, ids: np.ndarray, pose0: np.ndarray,
                 period: float, wheel_base: float, world_seed: int):
        self.p, self.ids = params, [int(r) for r in ids]
        self.every = max(1, math.ceil(1.0 / (params.rate * period) - 1e-9))
        self._rng = np.random.default_rng([params.seed, world_seed, 3])
        settings = PoseSettings(fix_timeout=params.fix_timeout,
                                history=max(PoseSettings().history,
                                            params.latency + 2.0 * period))
        self.fusion = [PoseFusion(settings, wheel_base) for _ in self.ids]
        self._queue: deque[tuple[float, int, FixMsg]] = deque()   # (due, index, fix)
        self._seq = 0
        self.held = np.zeros(len(self.ids), bool)   # robots in a failsafe HOLD
        self.out = np.zeros((len(self.ids), 4))
        self.jump = np.zeros((len(self.ids), 2))   # m, what this period's fixes moved each
        for i, f in enumerate(self.fusion):       # at rest, with a fix of where they stand
            f.update(0.0, (float(pose0[i, 0]), float(pose0[i, 1]), float(pose0[i, 2])))
            f.fix(FixMsg(self.ids[i], 0, 0.0, float(pose0[i, 0]), float(pose0[i, 1]),
                         float(pose0[i, 2]), params.error))

    def step(self, step: int, t: float, odometry: np.ndarray, truth: np.ndarray) -> np.ndarray:
        """The estimates at period ``step`` (time ``t`` [s]) from the robots' ``odometry``
        (N, 3) and, for the capture, their ``truth`` (N, 3)."""
        p = self.p
        if step > 0 and step % self.every == 0:
            self._seq += 1
            noise = self._rng.normal(size=(len(self.ids), 3))
            lost = self._rng.random(len(self.ids)) < p.dropout
            for i in range(len(self.ids)):
                if not (lost[i] or p.out(self.ids[i], t)):
                    fix = p.fix(self.ids[i], self._seq, t, truth[i], noise[i])
                    self._queue.append((t + p.latency, i, fix))
        out = self.out
        for i, f in enumerate(self.fusion):
            out[i, :3] = f.update(t, (float(odometry[i, 0]), float(odometry[i, 1]),
                                      float(odometry[i, 2])))
        while self._queue and self._queue[0][0] <= t + 1e-9:
            _, i, fix = self._queue.popleft()
            self.fusion[i].fix(fix)
        for i, f in enumerate(self.fusion):
            self.jump[i, 0], self.jump[i, 1] = f.pose[0] - out[i, 0], f.pose[1] - out[i, 1]
            out[i, 0], out[i, 1], out[i, 2] = f.pose
            out[i, 3] = f.uncertainty
            if f.age(t) > p.fix_timeout:
                self.held[i] = True
        return out
