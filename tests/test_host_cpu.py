"""The host's stolen CPU share, from /proc/stat readings."""
from pathlib import Path

from hil.sitl.host_cpu import CpuTimes, busy_share, cpu_times, rt_limit, steal_share

LINE = "cpu  {user} 0 {system} {idle} 0 0 0 {steal} 0 0\ncpu0 1 2 3 4 5 6 7 8 0 0\nintr 1\n"


def stat(tmp_path: Path, **ticks: int) -> Path:
    path = tmp_path / "stat"
    path.write_text(LINE.format(**ticks))
    return path


def test_the_aggregate_line_gives_the_total_and_the_stolen_ticks(tmp_path):
    times = cpu_times(stat(tmp_path, user=100, system=50, idle=800, steal=50))
    assert times == CpuTimes(total=1000, steal=50, idle=800)


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


def test_the_share_busy_is_of_the_time_the_host_gave(tmp_path):
    before = cpu_times(stat(tmp_path, user=100, system=50, idle=800, steal=50))
    after = cpu_times(stat(tmp_path, user=400, system=150, idle=1100, steal=350))
    # 1000 ticks passed, 300 stolen: of the 700 given, 300 idle
    assert busy_share(before, after) == 1.0 - 300 / 700
    assert busy_share(before, None) is None and busy_share(before, before) is None


def test_the_kernel_cap_on_real_time_processes(tmp_path):
    runtime, period = tmp_path / "runtime", tmp_path / "period"
    period.write_text("1000000\n")
    runtime.write_text("950000\n")
    assert rt_limit(runtime, period) == 0.95
    runtime.write_text("-1\n")                   # uncapped
    assert rt_limit(runtime, period) is None
    assert rt_limit(tmp_path / "missing", period) is None


def test_a_saturated_machine_is_named_in_the_missed_periods_warning(monkeypatch):
    from hil.cli import sitl
    assert sitl.saturation(None) == "" and sitl.saturation(0.5) == ""
    monkeypatch.setattr(sitl, "rt_limit", lambda: 0.95)
    clause = sitl.saturation(0.97)
    assert "97% busy" in clause and "95% of each second" in clause
    monkeypatch.setattr(sitl, "rt_limit", lambda: None)
    assert sitl.saturation(0.97) == " (its CPUs were 97% busy in the mission)"
