import os
import subprocess
import sys
from pathlib import Path

import pytest

from agent.config import ConfigError
from agent.settings import (AgentSettings, CanSettings, load_settings, parse_settings,
                            settings_to_toml)

BASE = {"robot_id": 3, "swarm": "demo", "initial_pose": [1.0, 2.0, 0.5]}


def test_round_trip_through_toml(tmp_path):
    s = AgentSettings(robot_id=7, swarm="s", initial_pose=(1.0, -2.0, 3.0), autostart=True,
                      can=CanSettings(interface="socketcan", channel="can0"),
                      realtime_priority=30)
    path = tmp_path / "robot.toml"
    path.write_text(settings_to_toml(s))
    assert load_settings(path) == s


@pytest.mark.parametrize("change, field", [
    ({"robot_id": 0}, "robot_id"),
    ({"robot_id": "3"}, "robot_id"),
    ({"swarm": "a/b"}, "swarm"),
    ({"initial_pose": [0.0, 1.0]}, "initial_pose"),
    ({"autostart": "yes"}, "autostart"),
    ({"can": {"left_node": 1, "right_node": 1}}, r"\[can\] right_node"),
    ({"can": {"port": 70000}}, r"\[can\] port"),
    ({"can": {"speed": 1}}, r"\[can\]: unknown"),
    ({"zenoh": {"mode": "router"}}, r"\[zenoh\] mode"),
    ({"zenoh": {"connect": []}}, r"\[zenoh\] connect"),
    ({"timeouts": {"feedback": 0.01}}, r"\[timeouts\] feedback"),
    ({"control": {"period": 0.1}}, r"\[control\]"),
    ({"motors": {}}, "top level"),
    ({"realtime_priority": 100}, "realtime_priority"),
    ({"zenoh": {"near_radius": 2.0}}, r"\[zenoh\] near_radius"),
])
def test_bad_fields_are_named(change, field):
    doc = {**BASE, **change}
    with pytest.raises(ConfigError, match=field) as exc:
        parse_settings(doc, "robot.toml")
    assert "robot.toml" in str(exc.value)


def test_missing_required_fields():
    for key in BASE:
        doc = {k: v for k, v in BASE.items() if k != key}
        with pytest.raises(ConfigError, match=f"{key}: missing"):
            parse_settings(doc, "robot.toml")


@pytest.mark.skipif(os.geteuid() != 0, reason="SCHED_FIFO needs root here")
def test_realtime_priority_applies_to_the_calling_thread_only():
    import threading

    from agent.loop import use_realtime
    got = {}

    def loop_thread():
        got["granted"] = use_realtime(10)
        got["policy"] = os.sched_getscheduler(0)

    t = threading.Thread(target=loop_thread)
    t.start()
    t.join()
    assert got == {"granted": True, "policy": os.SCHED_FIFO}
    assert os.sched_getscheduler(0) == os.SCHED_OTHER      # this thread untouched


@pytest.mark.skipif(os.geteuid() != 0, reason="SCHED_FIFO needs root here")
def test_zenoh_threads_inherit_the_scheduling_of_the_thread_that_opens_the_session():
    """The agent relies on it to run Zenoh's threads one step under its loop."""
    code = """if True:
        import os
        from agent.loop import use_realtime
        from transport.zenoh_link import open_session, session_config
        assert use_realtime(4)
        session = open_session(session_config("peer"), "test")
        policies = {}
        for tid in os.listdir("/proc/self/task"):
            name = open(f"/proc/self/task/{tid}/comm").read().strip()
            if name.startswith(("rx-", "tx-", "app-", "net-", "acc-")):
                policies[name] = (os.sched_getscheduler(int(tid)),
                                  os.sched_getparam(int(tid)).sched_priority)
        session.close()
        print(sorted(set(policies.values())), len(policies))
    """
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, cwd=Path(__file__).resolve().parent.parent)
    assert out.returncode == 0, out.stderr
    policies, count = out.stdout.strip().rsplit(" ", 1)
    assert int(count) >= 1 and policies == f"[({os.SCHED_FIFO}, 4)]", out.stdout
