"""How much CPU this machine really had over a stretch of time, and how much of it was used:
the share its hypervisor stole, the share busy, and the kernel's cap on real-time processes.

A virtual machine's CPUs run only when the host schedules them; the time they were ready but
not run is *steal* (``/proc/stat``, the 8th field of the ``cpu`` line). A SITL swarm runs in
wall-clock time, so a host that steals a third of the CPU starves its agents exactly as a
too-small robot computer would: late periods, old neighbour data, robots that brake. Runs
under heavy steal say more about the host than about the swarm.

A swarm that needs more CPU than the machine has misses periods however it is scheduled.
Its loops run under SCHED_FIFO, and Linux lets real-time processes use only
``sched_rt_runtime_us`` of every ``sched_rt_period_us`` (95 % of each second by default):
beyond that the kernel stops every real-time process together for the rest of the second,
so a saturated swarm misses periods in all its agents at once, once a second.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

PROC_STAT = Path("/proc/stat")
RT_RUNTIME = Path("/proc/sys/kernel/sched_rt_runtime_us")
RT_PERIOD = Path("/proc/sys/kernel/sched_rt_period_us")


def machine_cores() -> int:
    """The cores this process may run on (its affinity: a container's or a taskset's), which
    can be fewer than the machine has (``os.cpu_count``)."""
    return len(os.sched_getaffinity(0))


@dataclass(frozen=True)
class CpuTimes:
    """The machine's cumulative CPU time over all its CPUs [clock ticks]."""

    total: int
    steal: int
    idle: int            # idle and waiting for I/O


def cpu_times(stat: Path = PROC_STAT) -> CpuTimes | None:
    """The aggregate ``cpu`` line of ``stat``, or None where there is none (not Linux) or it
    has no steal field (kernels before 2.6.11)."""
    try:
        line = stat.read_text().splitlines()[0]
    except (OSError, IndexError):
        return None
    fields = line.split()
    if fields[0] != "cpu" or len(fields) < 9:
        return None
    ticks = [int(x) for x in fields[1:9]]     # user nice system idle iowait irq softirq steal
    return CpuTimes(total=sum(ticks), steal=ticks[7], idle=ticks[3] + ticks[4])


def steal_share(before: CpuTimes | None, after: CpuTimes | None) -> float | None:
    """The share (0-1) of the CPU time between two readings that the host stole; None when
    either is missing or no time passed."""
    if before is None or after is None or after.total <= before.total:
        return None
    return (after.steal - before.steal) / (after.total - before.total)


def busy_share(before: CpuTimes | None, after: CpuTimes | None) -> float | None:
    """The share (0-1) of the CPU time the host gave between two readings that was used (not
    idle): 1 is a saturated machine. None as :func:`steal_share`."""
    if before is None or after is None:
        return None
    given = (after.total - before.total) - (after.steal - before.steal)
    if given <= 0:
        return None
    return 1.0 - (after.idle - before.idle) / given


def rt_limit(runtime: Path = RT_RUNTIME, period: Path = RT_PERIOD) -> float | None:
    """The share (0-1) of each CPU that real-time processes may use together; None when the
    kernel does not cap them (``sched_rt_runtime_us`` = -1) or does not say."""
    try:
        run_us, period_us = int(runtime.read_text()), int(period.read_text())
    except (OSError, ValueError):
        return None
    if run_us < 0 or period_us <= 0:
        return None
    return run_us / period_us
