"""The fixed-rate loop on simulated time."""
import pytest
from helpers import SimClock

from agent.loop import FixedRateLoop


def test_ticks_on_absolute_deadlines_without_drift():
    clock = SimClock()
    loop = FixedRateLoop(0.02, clock)
    starts = []

    def tick(k, deadline):
        starts.append((k, clock.now))
        clock.now += 0.005                     # compute time

    loop.run(tick, max_ticks=500)
    assert [k for k, _ in starts] == list(range(500))
    assert starts[-1][1] == pytest.approx(1000.0 + 499 * 0.02)   # no accumulated drift
    s = loop.stats.summary()
    assert s["overruns"] == 0 and s["ticks"] == 500
    assert s["compute"]["p50_ms"] == pytest.approx(5.0)
    assert s["jitter"]["max_ms"] == pytest.approx(0.0, abs=1e-6)


def test_overrun_skips_missed_ticks_instead_of_catching_up():
    clock = SimClock()
    loop = FixedRateLoop(0.02, clock)
    seen = []
    wall0 = clock.wall()

    def tick(k, deadline):
        seen.append(k)
        clock.now += 0.065 if k == 3 else 0.001   # tick 3 overruns by 2 periods and more

    loop.run(tick, max_ticks=8)
    assert seen == [0, 1, 2, 3, 7, 8, 9, 10]
    assert loop.stats.overruns == 3
    # when (UNIX time) and by how much: tick 3 started at 0.06 s and ended at 0.125 s
    assert loop.stats.summary()["overrun_events"] == [[round(wall0 + 0.125, 3), 3]]
    loop.stats.overrun_events.extend([(0.0, 1)] * (loop.stats.MAX_EVENTS - 1))
    loop.stats.overrun(wall0 + 9.0, 2)                  # the log is full: counted apart
    assert loop.stats.summary()["overruns_unlogged"] == 2 and loop.stats.overruns == 5


def test_aligned_loops_tick_together_on_the_wall_clock_grid():
    """Robots whose loops start at different instants, each on its own monotonic clock
    (synchronised wall clocks): with phase 0, every tick's UNIX time is a multiple of the
    period, so they tick at the same instants; with another phase, that much later; without
    one, at their start's phase."""
    period = 0.02
    walls: dict[str, list[float]] = {}
    for name, start, offset, phase in (("a", 1000.0, 1.7e9 + 0.0031, 0.0),
                                        ("b", 52.3377, 1.7e9 + 947.6654, 0.0),
                                        ("c", 52.3377, 1.7e9 + 947.6654, None),
                                        ("d", 52.3377, 1.7e9 + 947.6654, 0.01)):
        clock = SimClock(start, offset)
        loop = FixedRateLoop(period, clock, phase)
        seen: list[float] = []
        walls[name] = seen

        def note(k: int, d: float, seen: list[float] = seen, clock: SimClock = clock) -> None:
            seen.append(clock.wall())

        loop.run(note, max_ticks=50)
    for name in ("a", "b"):
        off_grid = [round(w / period) * period - w for w in walls[name]]
        assert max(map(abs, off_grid)) < 1e-6, name
    assert walls["a"][0] > 1.7e9 + 1000.0031 - 1e-9          # never before the start
    assert walls["a"][0] - (1.7e9 + 1000.0031) < period
    c_phase = walls["c"][0] % period
    assert c_phase == pytest.approx((1.7e9 + 947.6654 + 52.3377) % period)
    assert min(c_phase, period - c_phase) > 1e-3               # not on the grid
    assert max(abs((w - 0.01) % period - period / 2) for w in walls["d"]) > period / 2 - 1e-6


class PreemptedClock(SimClock):
    """A simulated clock whose process loses ``lost`` s between its first monotonic and
    its first wall-clock reading (preempted as many processes start at once)."""

    def __init__(self, lost: float):
        super().__init__(52.3377, 1.7e9 + 947.6654)
        self.lost, self.reads = lost, 0

    def monotonic(self) -> float:
        self.reads += 1
        value = super().monotonic()
        if self.reads == 1:
            self.now += self.lost
        return value


def test_a_loop_preempted_between_the_clocks_still_ticks_on_the_grid():
    """The phase comes from a wall-clock reading paired with the monotonic clock: a start
    that loses 8.6 ms between the two readings (one CI run's agents ticked that far off
    their phase for the whole run) is read again."""
    period = 0.02
    clock = PreemptedClock(0.0086)
    loop = FixedRateLoop(period, clock, 0.0)
    walls: list[float] = []
    loop.run(lambda k, d: walls.append(clock.wall()), max_ticks=20)
    assert max(abs(round(w / period) * period - w) for w in walls) < 1e-6
    assert clock.reads > 2                                 # it read the pair again


def test_a_phase_outside_the_period_is_refused():
    for phase in (-0.001, 0.02, 0.5):
        with pytest.raises(ValueError, match="phase"):
            FixedRateLoop(0.02, SimClock(), phase)


def test_stop_from_inside_a_tick():
    clock = SimClock()
    loop = FixedRateLoop(0.01, clock)
    loop.run(lambda k, d: loop.stop() if k == 4 else None)
    assert loop.stats.ticks == 5


def test_bad_period_is_refused():
    with pytest.raises(ValueError, match="period"):
        FixedRateLoop(0.0, SimClock())
