"""The deadlock detector: no progress toward the reference for a configured time.

A robot is *deadlocked* while it is outside its convergence tolerance (|p_d_dot| / K +
TOLERANCE_MARGIN), was outside it a ``window`` of seconds ago too, and shed less than
PROGRESS of its tracking error since: stuck, or trailing its place at the reference's own
speed. A robot pushed out of a place it held (braking for a neighbour whose data came
late) is not deadlocked before it has been out of it for a window. The law
has no feed-forward of the reference's velocity, so a converged robot trails it by
|p_d_dot| / K (docs/controller.md, E9). The batch simulator's ``deadlocked`` metric
(:mod:`firmware_sim.metrics`) applies the same rule at the end of a run. Once deadlocked, a
robot stays so until it is within tolerance or sheds twice PROGRESS over a window: a robot
jostled back and forth, or creeping at the threshold, does not flip the verdict.
"""
from __future__ import annotations

from collections import deque

TOLERANCE_MARGIN = 0.25  # m, added to the steady-state lag |p_d_dot| / K
PROGRESS = 0.5           # m of tracking error a robot must shed in a window
WINDOW = 10.0            # s, the default window ([timeouts] deadlock)
SAMPLE = 1.0             # s between the errors kept


def tolerance(ref_speed: float, K: float) -> float:
    """The convergence tolerance [m] of a robot whose reference moves at ``ref_speed`` [m/s],
    with the law's gain ``K`` [1/s]."""
    return ref_speed / K + TOLERANCE_MARGIN


def stuck(error, then, out, out_then):
    """The deadlock rule: out of tolerance now (``out``) and a window ago (``out_then``),
    and a tracking error ``error`` [m] that shed less than PROGRESS of the ``then`` [m] of
    a window ago. On bools and floats (an agent) or numpy arrays of them (a run's robots,
    :mod:`firmware_sim.metrics`) alike."""
    return out & out_then & (error > then - PROGRESS)


class ProgressWatch:
    """One robot's deadlock verdict from its tracking error, updated every period."""

    def __init__(self, window: float = WINDOW):
        self.window = window                                  # s
        self.deadlocked = False
        # (t [s], error [m], outside the tolerance), one a second
        self._errors: deque[tuple[float, float, bool]] = deque()

    def reset(self) -> None:
        """Forget the history (the robot stopped following its reference)."""
        self._errors.clear()
        self.deadlocked = False

    def update(self, t: float, error: float, tol: float) -> bool:
        """The verdict at time ``t`` [s] (monotonic) for tracking ``error`` [m] and the
        tolerance ``tol`` [m]."""
        if not self._errors or t >= self._errors[-1][0] + SAMPLE:
            self._errors.append((t, error, error > tol))
        # keep one sample at or before t - window
        while len(self._errors) > 1 and self._errors[1][0] <= t - self.window:
            self._errors.popleft()
        t0, then, out = self._errors[0]
        full = t0 <= t - self.window
        if self.deadlocked:
            self.deadlocked = error > tol and not (full and error < then - 2.0 * PROGRESS)
        else:
            self.deadlocked = full and bool(stuck(error, then, error > tol, out))
        return self.deadlocked
