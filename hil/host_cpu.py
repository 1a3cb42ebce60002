"""How much CPU this machine really had over a stretch of time: the share its hypervisor
stole.

A virtual machine's CPUs run only when the host schedules them; the time they were ready but
not run is *steal* (``/proc/stat``, the 8th field of the ``cpu`` line). A SITL swarm runs in
wall-clock time, so a host that steals a third of the CPU starves its agents exactly as a
too-small robot computer would: late periods, old neighbour data, robots that brake. Runs
under heavy steal say more about the host than about the swarm.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

PROC_STAT = Path("/proc/stat")


@dataclass(frozen=True)
class CpuTimes:
    """The machine's cumulative CPU time over all its CPUs [clock ticks]."""

    total: int
    steal: int


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
    return CpuTimes(total=sum(ticks), steal=ticks[7])


def steal_share(before: CpuTimes | None, after: CpuTimes | None) -> float | None:
    """The share (0-1) of the CPU time between two readings that the host stole; None when
    either is missing or no time passed."""
    if before is None or after is None or after.total <= before.total:
        return None
    return (after.steal - before.steal) / (after.total - before.total)
