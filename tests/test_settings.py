import argparse
import logging
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent import loop
from agent.config import ControlParams, RobotParams
from agent.settings import AgentSettings, SensingSettings, TimeoutSettings, load_settings
from common.schema import ConfigError, add_arguments, from_table, section_from_args, to_toml
from transport.settings import CanSettings, MavlinkSettings, ZenohSettings

BASE = {"robot_id": 3, "swarm": "demo", "initial_pose": [1.0, 2.0, 0.5]}


def test_round_trip_through_toml(tmp_path):
    s = AgentSettings(robot_id=7, swarm="s", initial_pose=(1.0, -2.0, 3.0), autostart=True,
                      can=CanSettings(interface="socketcan", channel="can0"),
                      realtime_priority=30)
    path = tmp_path / "robot.toml"
    path.write_text(to_toml(s))
    assert load_settings(path) == s


# --- property: settings -> TOML -> settings ----------------------------------------------
names = st.text(min_size=1, max_size=12)
positive = st.floats(min_value=1e-3, max_value=1e3, allow_nan=False)
finite = st.floats(allow_nan=False, allow_infinity=False)


@st.composite
def agent_settings(draw: st.DrawFn) -> AgentSettings:
    a = draw(st.floats(min_value=0.1, max_value=2.0))
    b = a + draw(st.floats(min_value=0.1, max_value=2.0))
    c = b + draw(st.floats(min_value=0.1, max_value=2.0))
    K, D_max = draw(positive), draw(positive)
    control = ControlParams(K=K, K_theta=draw(positive), D_max=D_max, K_ij=draw(positive),
                            a=a, b=b, c=c, u_max=draw(positive),
                            hysteresis=draw(st.floats(min_value=0.0, max_value=3.0)),
                            period=(b - a) / (2 * K * D_max) * draw(
                                st.floats(min_value=0.01, max_value=1.0)))
    robot = RobotParams(*(draw(positive) for _ in range(4)))
    left = draw(st.integers(0, 63))
    can = CanSettings(interface=draw(names), channel=draw(names),
                      port=draw(st.none() | st.integers(1, 65535)),
                      bitrate=draw(st.integers(10_000, 1_000_000)), left_node=left,
                      right_node=draw(st.integers(0, 63).filter(lambda n: n != left)))
    sensing = draw(st.floats(min_value=0.1, max_value=100.0))
    zenoh = ZenohSettings(mode=draw(st.sampled_from(["client", "peer"])),
                          connect=tuple(draw(st.lists(names, min_size=1, max_size=3))),
                          listen=tuple(draw(st.lists(names, max_size=2))),
                          config=draw(st.none() | names),
                          near_radius=draw(st.sampled_from([0.0, sensing + 1.0, sensing + 7.5])))
    mavlink = MavlinkSettings(url=f"udpout:127.0.0.1:{draw(st.integers(1, 65535))}",
                              origin=(draw(st.floats(-85, 85)), draw(st.floats(-180, 180)),
                                      draw(finite)),
                              gcs_failsafe=draw(st.booleans()), gcs_timeout=draw(positive),
                              signing_key_file=draw(st.none() | names))
    timeouts = TimeoutSettings(feedback=2 * control.period + draw(positive),
                               staleness=draw(positive), arm=draw(positive))
    return AgentSettings(robot_id=draw(st.integers(1, 255)),
                         swarm=draw(names.filter(lambda t: not set(t) & set("/*$?#"))),
                         initial_pose=(draw(finite), draw(finite), draw(finite)),
                         autostart=draw(st.booleans()),
                         realtime_priority=draw(st.integers(0, 99)), control=control,
                         robot=robot, can=can, zenoh=zenoh, timeouts=timeouts,
                         sensing=SensingSettings(sensing), mavlink=mavlink)


@settings(max_examples=150, deadline=None)
@given(agent_settings())
def test_every_settings_survive_the_toml_round_trip(s):
    import tomllib
    assert from_table(AgentSettings, tomllib.loads(to_toml(s)), "robot.toml") == s


# --- bad input ---------------------------------------------------------------------------
@pytest.mark.parametrize("change, field", [
    ({"robot_id": 0}, "robot_id: must be >= 1"),
    ({"robot_id": "3"}, "robot_id: expected an integer"),
    ({"swarm": "a/b"}, "swarm: must not contain"),
    ({"initial_pose": [0.0, 1.0]}, "initial_pose: expected a list of 3"),
    ({"autostart": "yes"}, "autostart: expected true or false"),
    ({"can": {"left_node": 1, "right_node": 1}}, r"\[can\]: CanSettings.right_node: must differ"),
    ({"can": {"port": 70000}}, r"\[can\]: CanSettings.port: must be <= 65535"),
    ({"can": {"speed": 1}}, r"\[can\]: unknown field\(s\) speed"),
    ({"zenoh": {"mode": "router"}}, r"\[zenoh\]: ZenohSettings.mode: expected client or peer"),
    ({"zenoh": {"connect": []}}, r"\[zenoh\]: ZenohSettings.connect: a client needs"),
    ({"zenoh": {"connect": "tcp/a:1"}}, r"\[zenoh\]: ZenohSettings.connect: expected a list"),
    ({"timeouts": {"feedback": 0.01}}, r"\[timeouts\] feedback: must be at least two periods"),
    ({"timeouts": {"arm": 0}}, r"\[timeouts\]: TimeoutSettings.arm: must be > 0 \[s\]"),
    ({"control": {"period": 0.1}}, r"\[control\]: ControlParams.period: period 0.1 s breaks"),
    ({"control": 3}, r"\[control\]: expected a table"),
    ({"control": {"K": [1]}}, r"\[control\]: ControlParams.K: expected a number, got \[1\]"),
    ({"initial_pose": [0, "a", 1]}, "initial_pose: expected a list of 3 finite numbers"),
    ({"zenoh": {"listen": ["", "x"]}}, r"\[zenoh\]: ZenohSettings.listen: expected a list of "),
    ({"mavlink": {"gcs_failsafe": 1}}, r"\[mavlink\]: MavlinkSettings.gcs_failsafe: expected t"),
    ({"mavlink": {"origin": [0.0, 200.0, 0.0]}}, r"\[mavlink\]: MavlinkSettings.origin: longi"),
    ({"motors": {}}, r"robot.toml: unknown field\(s\) motors"),
    ({"realtime_priority": 100}, "realtime_priority: must be <= 99"),
    ({"tick_phase": 0.02}, r"tick_phase: must be below the period \(0.02 s\), got 0.02"),
    ({"tick_phase": -0.001}, r"tick_phase: must be >= 0"),
    ({"zenoh": {"near_radius": 2.0}}, r"\[zenoh\] near_radius: must be 0 or at least"),
])
def test_bad_fields_are_named(change, field):
    doc = {**BASE, **change}
    with pytest.raises(ConfigError, match=field) as exc:
        from_table(AgentSettings, doc, "robot.toml")
    assert str(exc.value).startswith("robot.toml")


def test_missing_required_fields():
    for key in BASE:
        doc = {k: v for k, v in BASE.items() if k != key}
        with pytest.raises(ConfigError, match=f"robot.toml: AgentSettings.{key}: missing"):
            from_table(AgentSettings, doc, "robot.toml")


def test_sensing_range_defaults_to_2c_of_the_configured_controller():
    s = from_table(AgentSettings, {**BASE, "control": {"c": 5.0}}, "robot.toml")
    assert s.sensing_range == 10.0 == s.sensing.range
    assert AgentSettings(robot_id=1, swarm="s", initial_pose=(0.0, 0.0, 0.0)).sensing_range == 8.0


def test_missing_relative_files_are_named(tmp_path):
    path = tmp_path / "robot.toml"
    path.write_text(to_toml(AgentSettings(robot_id=1, swarm="s", initial_pose=(0.0, 0.0, 0.0),
                                          mavlink=MavlinkSettings(signing_key_file="k.key"))))
    with pytest.raises(ConfigError, match=r"robot.toml: \[mavlink\] signing_key_file: no such"):
        load_settings(path)


def test_command_line_flags_derived_from_the_whole_config():
    parser = argparse.ArgumentParser()
    add_arguments(parser, AgentSettings)
    with pytest.raises(SystemExit):                      # robot_id, swarm, pose are required
        parser.parse_args([])
    required = ["--robot-id", "4", "--swarm", "s", "--initial-pose", "1", "2", "0.5"]
    assert section_from_args(AgentSettings, parser.parse_args(required)) == AgentSettings(
        robot_id=4, swarm="s", initial_pose=(1.0, 2.0, 0.5))
    args = parser.parse_args(required + [
        "--autostart", "--control-K", "2", "--can-port", "43001", "--zenoh-mode", "peer",
        "--zenoh-connect", "--zenoh-listen", "tcp/127.0.0.1:1", "tcp/127.0.0.1:2",
        "--timeouts-arm", "3", "--mavlink-gcs-failsafe", "--sensing-range", "9"])
    s = section_from_args(AgentSettings, args)
    assert s.autostart and s.control.K == 2.0 and s.can.port == 43001
    assert s.zenoh == ZenohSettings(mode="peer", connect=(),
                                    listen=("tcp/127.0.0.1:1", "tcp/127.0.0.1:2"))
    assert s.timeouts.arm == 3.0 and s.mavlink.gcs_failsafe and s.sensing_range == 9.0
    text = parser.format_help()
    assert "--can-channel" in text and "ff11::b5:1" in text and "[rev/s]" in text
    with pytest.raises(SystemExit):
        parser.parse_args(required + ["--zenoh-mode", "router"])    # choices from the schema
    with pytest.raises(ConfigError, match=r"--can-bitrate: must be >= 10000 \[bit/s\]"):
        section_from_args(AgentSettings, parser.parse_args(required + ["--can-bitrate", "9"]))
    with pytest.raises(ConfigError, match=r"--control: ControlParams: need 0 < a < b < c"):
        section_from_args(AgentSettings, parser.parse_args(required + ["--control-b", "9"]))


# --- realtime scheduling, granted or not ------------------------------------------------
def _policy_in_a_thread(priority: int) -> dict:
    got: dict = {}

    def loop_thread() -> None:
        got["granted"] = loop.use_realtime(priority)
        got["policy"] = os.sched_getscheduler(0)

    t = threading.Thread(target=loop_thread)
    t.start()
    t.join()
    return got


def test_realtime_priority_asks_the_kernel_for_the_calling_thread(monkeypatch):
    calls = []
    monkeypatch.setattr(loop.os, "sched_setscheduler",
                        lambda pid, policy, param: calls.append((pid, policy,
                                                                 param.sched_priority)))
    assert loop.use_realtime(10) is True
    assert calls == [(0, os.SCHED_FIFO, 10)]          # 0: the calling thread only


def test_realtime_priority_not_granted_means_one_warning_and_normal_scheduling(monkeypatch,
                                                                               caplog):
    def refuse(pid, policy, param):
        raise PermissionError(1, "Operation not permitted")
    monkeypatch.setattr(loop.os, "sched_setscheduler", refuse)
    with caplog.at_level(logging.WARNING, logger="agent.loop"):
        assert loop.use_realtime(10) is False
    assert [r.levelno for r in caplog.records] == [logging.WARNING]
    assert "not granted" in caplog.text


def test_realtime_priority_applies_to_the_calling_thread_only():
    """On this machine, whichever the kernel decides: granted means SCHED_FIFO for that
    thread alone, refused means normal scheduling everywhere."""
    got = _policy_in_a_thread(10)
    expected = os.SCHED_FIFO if got["granted"] else os.SCHED_OTHER
    assert got["policy"] == expected
    assert os.sched_getscheduler(0) == os.SCHED_OTHER      # this thread untouched


def test_normal_scheduling_again_after_the_loop():
    """The agent's bookkeeping after its loop ends runs normally scheduled (it must not hold
    up other processes' loops at the loop's priority)."""
    got: dict = {}

    def loop_thread() -> None:
        got["granted"] = loop.use_realtime(10)
        loop.use_normal_scheduling()
        got["policy"] = os.sched_getscheduler(0)

    t = threading.Thread(target=loop_thread)
    t.start()
    t.join()
    assert got["policy"] == os.SCHED_OTHER


def test_zenoh_threads_inherit_the_scheduling_of_the_thread_that_opens_the_session():
    """The agent relies on it to run Zenoh's threads one step under its loop (and, when
    SCHED_FIFO is not granted, on every thread staying normally scheduled)."""
    code = """if True:
        import os
        from agent.loop import use_realtime
        from transport.zenoh_link import open_session, session_config
        granted = use_realtime(4)
        import time
        session = open_session(session_config("peer"), "test")
        policies = {}
        end = time.monotonic() + 10.0       # its runtimes may start their threads late
        while not policies and time.monotonic() < end:
            time.sleep(0.05)
            for tid in os.listdir("/proc/self/task"):
                try:
                    name = open(f"/proc/self/task/{tid}/comm").read().strip()
                    if name.startswith(("rx-", "tx-", "app-", "net-", "acc-")):
                        policies[name] = (os.sched_getscheduler(int(tid)),
                                          os.sched_getparam(int(tid)).sched_priority)
                except (FileNotFoundError, ProcessLookupError):
                    pass                    # a thread that ended meanwhile
        session.close()
        print(granted, sorted(set(policies.values())), len(policies))
    """
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, cwd=Path(__file__).resolve().parent.parent)
    assert out.returncode == 0, out.stderr
    granted, rest = out.stdout.strip().split(" ", 1)
    policies, count = rest.rsplit(" ", 1)
    expected = (os.SCHED_FIFO, 4) if granted == "True" else (os.SCHED_OTHER, 0)
    assert int(count) >= 1 and policies == f"[{expected}]", out.stdout
