import io

from rich.console import Console

from hil.cli.console import LazyProgress, summary_table


class FakeClock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def test_progress_bar_only_after_a_second():
    clock = FakeClock()
    console = Console(file=io.StringIO(), force_terminal=True)
    with LazyProgress(console, "sim", delay=1.0, clock=clock) as progress:
        progress(0.1)
        clock.now = 0.9
        progress(0.5)
        assert not progress.shown                 # fast runs never show a bar
        clock.now = 1.1
        progress(0.6)
        assert progress.shown
        progress(1.0)


def test_quick_run_shows_no_bar():
    clock = FakeClock()
    console = Console(file=io.StringIO(), force_terminal=True)
    with LazyProgress(console, "sim", clock=clock) as progress:
        clock.now = 5.0
        progress(1.0)                             # finished: nothing left to show
        assert not progress.shown


def test_summary_table_formats_metrics():
    out = io.StringIO()
    console = Console(file=out, width=100)
    console.print(summary_table({"robots": 9, "converged": False, "convergence_time": None,
                                 "min_pair_distance": 1.97123, "stuck_robots": [3, 4]}, "t"))
    text = out.getvalue()
    assert "NO" in text and "1.97" in text and "3, 4" in text and "-" in text
