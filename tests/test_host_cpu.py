"""The host's stolen CPU share, from /proc/stat readings."""
from pathlib import Path

from hil.host_cpu import CpuTimes, cpu_times, steal_share

LINE = "cpu  {user} 0 {system} {idle} 0 0 0 {steal} 0 0\ncpu0 1 2 3 4 5 6 7 8 0 0\nintr 1\n"


def stat(tmp_path: Path, **ticks: int) -> Path:
    path = tmp_path / "stat"
    path.write_text(LINE.format(**ticks))
    return path


def test_the_aggregate_line_gives_the_total_and_the_stolen_ticks(tmp_path):
    times = cpu_times(stat(tmp_path, user=100, system=50, idle=800, steal=50))
    assert times == CpuTimes(total=1000, steal=50)


def test_the_share_stolen_between_two_readings(tmp_path):
    before = cpu_times(stat(tmp_path, user=100, system=50, idle=800, steal=50))
    after = cpu_times(stat(tmp_path, user=400, system=150, idle=1100, steal=350))
    assert steal_share(before, after) == 300 / 1000


def test_no_reading_or_no_time_passed_gives_no_share(tmp_path):
    times = cpu_times(stat(tmp_path, user=1, system=1, idle=1, steal=1))
    assert cpu_times(tmp_path / "missing") is None
    assert steal_share(None, times) is None and steal_share(times, None) is None
    assert steal_share(times, times) is None


def test_a_kernel_without_the_steal_field_gives_none(tmp_path):
    path = tmp_path / "stat"
    path.write_text("cpu  1 2 3 4 5 6 7\n")
    assert cpu_times(path) is None


def test_this_machine_has_a_reading():
    times = cpu_times()
    assert times is not None and times.total > 0 and 0 <= times.steal <= times.total
