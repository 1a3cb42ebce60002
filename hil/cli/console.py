"""Terminal output of the CLI: a progress bar for long runs and the summary table."""
from __future__ import annotations

import contextlib
import time
from typing import Callable, Iterator

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table


class LazyProgress:
    """A progress callback that shows a bar only once the work has taken ``delay`` seconds."""

    def __init__(self, console: Console, label: str, delay: float = 1.0,
                 clock: Callable[[], float] = time.monotonic):
        self._console, self._label, self._delay, self._clock = console, label, delay, clock
        self._start = clock()
        self._bar: Progress | None = None
        self._task: TaskID | None = None             # set with _bar

    def __call__(self, fraction: float) -> None:
        if self._bar is None or self._task is None:     # both None until the bar shows
            if fraction >= 1.0 or self._clock() - self._start < self._delay:
                return
            self._bar = Progress(TextColumn("{task.description}"), BarColumn(),
                                 TextColumn("{task.percentage:>3.0f}%"), TimeRemainingColumn(),
                                 console=self._console, transient=True)
            self._bar.start()
            self._task = self._bar.add_task(self._label, total=1.0)
        self._bar.update(self._task, completed=fraction)

    @property
    def shown(self) -> bool:
        return self._bar is not None

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()

    def __enter__(self) -> "LazyProgress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@contextlib.contextmanager
def count_progress(console: Console, label: str, total: int
                   ) -> Iterator[Callable[[bool], None]]:
    """A bar over ``total`` items: done/total, failures, elapsed time and ETA. Yields
    ``advance(failed)``, to call once per finished item."""
    bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                   TextColumn("{task.fields[failed]}"), TimeElapsedColumn(),
                   TextColumn("ETA"), TimeRemainingColumn(), console=console)
    task = bar.add_task(label, total=total, failed="")
    failures = 0

    def advance(failed: bool) -> None:
        nonlocal failures
        failures += failed
        bar.update(task, advance=1, failed=f"{failures} failed" if failures else "")

    with bar:
        yield advance


def _fmt(value) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "NO"
    if isinstance(value, float):
        return f"{value:.3g}"
    if isinstance(value, list):
        return ", ".join(str(v) for v in value) or "none"
    return str(value)


SUMMARY_KEYS = (("robots", "robots", ""), ("converged", "converged", ""),
                ("convergence_time", "convergence time", "s"),
                ("min_pair_distance", "min distance between robots", "m"),
                ("min_obstacle_clearance", "min obstacle clearance", "m"),
                ("collisions", "collisions", ""), ("stuck_robots", "not converged", ""),
                ("max_abs_v", "max |v|", "m/s"), ("max_abs_u", "max |u|", "rad/s"),
                ("final_max_tracking_error", "final max tracking error", "m"),
                ("mode_switches", "mode switches", ""))


def summary_table(metrics: dict, title: str) -> Table:
    table = Table(title=title, show_header=True, header_style="bold")
    table.add_column("metric")
    table.add_column("value", justify="right")
    table.add_column("unit")
    for key, label, unit in SUMMARY_KEYS:
        if key in metrics:
            table.add_row(label, _fmt(metrics[key]), unit)
    return table
