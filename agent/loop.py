"""A fixed-period loop on a monotonic clock with absolute deadlines.

Theory of operation: the k-th tick is due at start + k * period. With a ``phase``, start is
the first instant whose UNIX time is a multiple of the period plus the phase: loops on
synchronised clocks (one machine, or robots under chrony/PTP) with the same phase tick
together, so their states reach the network as one burst per period (Zenoh batches them)
and each is used one period after it was sent. After a tick the loop sleeps
until the next deadline that is still in the future; if a tick ran past one or more
deadlines, those ticks are skipped (never caught up in a burst) and counted as overruns.
The clock and the sleep are injected, so tests run the loop on simulated time.

Statistics: wake-up jitter (actual start minus deadline) and compute time per tick, kept
in a bounded ring so a long run does not grow memory.
"""
from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

log = logging.getLogger(__name__)

PAIR_SPREAD = 1e-4   # s, the most two monotonic readings round a wall-clock reading may differ
PAIR_TRIES = 10      # readings of the two clocks before the closest pair is taken


class Clock(Protocol):
    def monotonic(self) -> float: ...          # s, for scheduling and timeouts
    def wall(self) -> float: ...               # s, UNIX time, for stamps and the epoch
    def sleep_until(self, deadline: float) -> None: ...   # monotonic deadline [s]


class SystemClock:
    """The real clocks: CLOCK_MONOTONIC for scheduling, UNIX time for stamps."""

    def monotonic(self) -> float:
        return time.monotonic()

    def wall(self) -> float:
        return time.time()

    def sleep_until(self, deadline: float) -> None:
        delay = deadline - time.monotonic()
        if delay > 0:
            time.sleep(delay)


@dataclass
class LoopStats:
    """Timing of the ticks run so far (the last ``window`` ticks for percentiles)."""

    period: float
    window: int = 20000
    ticks: int = 0
    overruns: int = 0            # deadlines missed (ticks skipped)
    overrun_events: list = field(default_factory=list)  # (UNIX time [s], periods skipped)
                                                        # of the first MAX_EVENTS overruns
    unlogged: int = 0            # periods skipped by overruns after those
    jitter: deque = field(default_factory=deque)     # s, start - deadline
    compute: deque = field(default_factory=deque)    # s, tick duration

    MAX_EVENTS = 1000

    def overrun(self, wall: float, skipped: int) -> None:
        """A tick ended ``skipped`` deadlines late, noticed at UNIX time ``wall`` [s]."""
        self.overruns += skipped
        if len(self.overrun_events) < self.MAX_EVENTS:
            self.overrun_events.append((wall, skipped))
        else:
            self.unlogged += skipped

    def record(self, jitter: float, compute: float) -> None:
        self.ticks += 1
        for ring, value in ((self.jitter, jitter), (self.compute, compute)):
            ring.append(value)
            if len(ring) > self.window:
                ring.popleft()

    def summary(self) -> dict:
        """Percentiles in milliseconds, counts as integers."""
        def pct(ring: deque) -> dict:
            if not ring:
                return {"p50_ms": None, "p99_ms": None, "max_ms": None}
            a = np.asarray(ring) * 1e3
            return {"p50_ms": float(np.percentile(a, 50)), "p99_ms": float(np.percentile(a, 99)),
                    "max_ms": float(a.max())}
        return {"period_s": self.period, "ticks": self.ticks, "overruns": self.overruns,
                "overrun_events": [[round(t, 3), n] for t, n in self.overrun_events],
                "overruns_unlogged": self.unlogged,
                "jitter": pct(self.jitter), "compute": pct(self.compute)}


class FixedRateLoop:
    """Calls ``tick(k, deadline)`` every ``period`` seconds until ``stop()``; with a
    ``phase`` [s] the ticks fall at UNIX times n * period + phase (read from the clock's wall
    time when the loop starts: a later step of the wall clock shifts them until the next
    start); None: at the phase of the start."""

    def __init__(self, period: float, clock: Clock, phase: float | None = None):
        if not (period > 0 and math.isfinite(period)):
            raise ValueError(f"loop period must be a positive number of seconds, got {period!r}")
        if phase is not None and not 0.0 <= phase < period:
            raise ValueError(f"loop phase must be in [0, period {period:g} s), got {phase!r}")
        self.period = period
        self.clock = clock
        self.phase = phase
        self.stats = LoopStats(period)
        self._running = False

    def _on_grid(self, phase: float) -> float:
        """The monotonic time [s] of the first instant at ``phase`` [s] of the wall-clock
        grid (n period + phase). The wall clock is read between two monotonic readings, again
        while they are more than PAIR_SPREAD apart: a process preempted between the two
        clocks (many starting at once on a busy host) would otherwise tick off the grid,
        by the time it lost, for the whole run."""
        spread, mono, wall = math.inf, 0.0, 0.0
        for _ in range(PAIR_TRIES):
            before = self.clock.monotonic()
            now = self.clock.wall()
            after = self.clock.monotonic()
            if after - before < spread:
                spread, mono, wall = after - before, 0.5 * (before + after), now
            if spread <= PAIR_SPREAD:
                break
        return mono + (phase - wall) % self.period

    def stop(self) -> None:
        """Ask the loop to return after the current tick (safe from a signal handler)."""
        self._running = False

    def run(self, tick: Callable[[int, float], None], max_ticks: int | None = None) -> None:
        self._running = True
        start = self.clock.monotonic() if self.phase is None else self._on_grid(self.phase)
        k = 0
        while self._running and (max_ticks is None or self.stats.ticks < max_ticks):
            deadline = start + k * self.period
            self.clock.sleep_until(deadline)
            woke = self.clock.monotonic()
            tick(k, deadline)
            done = self.clock.monotonic()
            self.stats.record(woke - deadline, done - woke)
            # next deadline still in the future; deadlines passed meanwhile are skipped
            next_k = max(k + 1, math.floor((done - start) / self.period) + 1)
            if next_k > k + 1:
                self.stats.overrun(self.clock.wall(), next_k - (k + 1))
            k = next_k


def use_realtime(priority: int) -> bool:
    """Put the calling thread (the loop's, or a helper it waits on) under SCHED_FIFO at
    ``priority`` (1..99); threads it starts afterwards inherit it (the agent's Zenoh threads
    do), others keep theirs. Without the right (root, CAP_SYS_NICE or RLIMIT_RTPRIO) it runs
    on with normal scheduling and a warning."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:                      # PermissionError: not allowed
        log.warning("realtime_priority %d not granted (%s): normal scheduling", priority, exc)
        return False
    log.info("thread %s: SCHED_FIFO priority %d", threading.current_thread().name, priority)
    return True


def use_normal_scheduling() -> None:
    """Put the calling thread back under normal scheduling (SCHED_OTHER): for the work after
    a real-time loop has ended (statistics, closing sessions), which must not hold up the
    loops of other processes at the loop's priority."""
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
