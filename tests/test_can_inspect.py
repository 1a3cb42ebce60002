"""CAN inspection: statistics and alarms (simulated time), log -> decode -> replay, and a
watchdog alarm after the process driving the wheels is killed."""
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import pytest
from helpers import free_port

from hil.cli.can import armed_writer, replay
from hil.ground.can_inspect import BusStats
from transport.busload import bus_load
from transport.canbus import open_bus
from transport.odrive_frames import Cmd, encode

ROOT = Path(__file__).resolve().parent.parent


def traffic(seconds=2.0, watchdog_after=None, vel=3.0):
    """One robot's frames with timestamps: commands 50 Hz, encoders 100 Hz, heartbeats 10 Hz."""
    frames = []
    for k in range(int(seconds * 1000)):
        t = 1000.0 + k / 1000
        tripped = watchdog_after is not None and t - 1000.0 > watchdog_after
        if k % 20 == 0 and not tripped:
            frames += [encode(n, Cmd.SET_INPUT_VEL, Input_Vel=vel, Input_Torque_FF=0.0)
                       for n in (0, 1)]
        if k % 10 == 0:
            frames += [encode(n, Cmd.GET_ENCODER_ESTIMATES, Pos_Estimate=t, Vel_Estimate=vel)
                       for n in (0, 1)]
        if k % 100 == 0:
            frames += [encode(n, Cmd.HEARTBEAT, Axis_Error=0x1000000 if tripped else 0,
                              Axis_State=1 if tripped else 8, Procedure_Result=0,
                              Trajectory_Done_Flag=0) for n in (0, 1)]
        for m in frames[-6:]:
            if m.timestamp == 0.0:
                m.timestamp = t
    return frames


def test_rates_load_and_signals():
    frames = traffic()
    stats = BusStats()
    for m in frames:
        stats.feed(m)
    doc = stats.summary(frames[-1].timestamp)
    by = {(m["name"], m["node"]): m for m in doc["messages"]}
    assert by[("Get_Encoder_Estimates", 0)]["rate_hz"] == pytest.approx(100, rel=0.03)
    assert by[("Heartbeat", 1)]["rate_hz"] == pytest.approx(10, rel=0.1)
    assert by[("Set_Input_Vel", 1)]["rate_hz"] == pytest.approx(50, rel=0.05)
    assert by[("Heartbeat", 1)]["expected_hz"] == 10.0 and by[("Heartbeat", 1)]["side"] == "right"
    assert doc["bus_load"] == pytest.approx(bus_load(frames, 2.0), rel=0.1)
    assert doc["alarms"] == []
    assert "Axis_State=CLOSED_LOOP_CONTROL" in stats.describe("Heartbeat",
                                                               by[("Heartbeat", 0)]["signals"])


def test_alarms():
    frames = traffic(seconds=2.0, watchdog_after=1.0, vel=10.0)
    frames += [can.Message(timestamp=1001.5, arbitration_id=0x3E, data=bytes(8),
                           is_extended_id=False),
               can.Message(timestamp=1001.6, arbitration_id=0x2D, data=bytes(2),
                           is_extended_id=False)]
    stats = BusStats(vel_limit=10.0)
    for m in sorted(frames, key=lambda m: m.timestamp):
        stats.feed(m)
    kinds = {(a.kind, a.node) for a in stats.alarms(1002.0)}
    assert {("watchdog", 0), ("watchdog", 1), ("at_velocity_limit", 0), ("unknown_id", None),
            ("dlc", None)} <= kinds
    assert ("stale_node", 0) in {(a.kind, a.node) for a in stats.alarms(1003.0)}


def test_filters_by_node_and_message():
    stats = BusStats(nodes={1}, messages={"heartbeat"})
    for m in traffic(seconds=0.5):
        stats.feed(m)
    assert {(s.name, s.node) for s in stats.streams.values()} == {("Heartbeat", 1)}


def test_log_decode_replay_reproduces_the_frames(tmp_path):
    frames = traffic(seconds=0.3)
    log = tmp_path / "capture.log"
    with can.Logger(str(log)) as logger:
        for m in frames:
            m.channel = "vcan0"
            logger.on_message_received(m)
    # decode works as a filter on candump -L lines
    out = subprocess.run([sys.executable, "-m", "hil.cli", "can", "decode", "-"],
                         input=log.read_text(), capture_output=True, text=True, cwd=ROOT,
                         check=True).stdout.splitlines()
    assert len(out) == len(frames)
    assert "Set_Input_Vel node 0: Input_Vel=3.000 rev/s" in out[0]
    assert any("Axis_State=CLOSED_LOOP_CONTROL" in line for line in out)
    # replay onto a bus and record what arrives
    port = free_port("udp6")
    rx = open_bus("udp_multicast", "ff11::b5:3", port=port)
    tx = open_bus("udp_multicast", "ff11::b5:3", port=port)
    got: list[tuple[can.Message, float]] = []

    def receive() -> None:
        # stamped on arrival here: the kernel's receive stamps (SO_TIMESTAMPNS) are only
        # switched on a while after the socket asks, and the first frames are stamped
        # when read instead
        while (m := rx.recv(1.0)) is not None:
            got.append((m, time.perf_counter()))

    receiver = threading.Thread(target=receive)
    try:
        receiver.start()
        replay(tx, list(can.LogReader(str(log))))
    finally:
        receiver.join()
        rx.shutdown()
        tx.shutdown()
    assert [(m.arbitration_id, bytes(m.data)) for m, _ in got] == \
        [(m.arbitration_id, bytes(m.data)) for m in frames]
    # the frames arrive spread over the log's span, not all at once (the exact timing is
    # checked on a simulated clock below: this shared machine may stall any real one)
    span = frames[-1].timestamp - frames[0].timestamp
    assert got[-1][1] - got[0][1] > 0.5 * span


class _SentAt(can.BusABC):
    """A bus that notes the simulated time at which each frame is sent."""

    def __init__(self, clock):
        self.clock, self.sent, self.channel_info = clock, [], "sent-at"
        super().__init__(channel="sent-at")       # BusABC does not use it

    def send(self, msg, timeout=None):
        self.sent.append(self.clock())

    def _recv_internal(self, timeout):
        return None, False


def test_replay_sends_each_frame_at_its_log_time_scaled_by_speed():
    now = [100.0]

    def clock():
        now[0] += 1e-5          # each reading of the clock takes 10 us
        return now[0]

    def sleep(seconds):
        assert seconds > 0
        now[0] += seconds

    frames = traffic(seconds=0.3)
    for speed in (1.0, 4.0):
        bus = _SentAt(clock)
        start = now[0]
        assert replay(bus, frames, speed=speed, clock=clock, sleep=sleep) == len(frames)
        due = [(m.timestamp - frames[0].timestamp) / speed for m in frames]
        late = [t - start - d for t, d in zip(bus.sent, due)]
        assert min(late) >= 0.0 and max(late) < 5e-4, (min(late), max(late))


def test_replay_refuses_commands_while_an_armed_agent_writes(tmp_path):
    port = free_port("udp6")
    log = tmp_path / "cmds.log"
    with can.Logger(str(log)) as logger:
        m = encode(0, Cmd.SET_INPUT_VEL, Input_Vel=1.0, Input_Torque_FF=0.0)
        m.timestamp, m.channel = 1.0, "vcan0"
        logger.on_message_received(m)
    drivers = subprocess.Popen([sys.executable, "-m", "hil.cli", "plant", "--drivers-only",
                                "--can-interface", "udp_multicast", "--can-channel",
                                "ff11::b5:4", "--can-port", str(port)], cwd=ROOT,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    host_bus = open_bus("udp_multicast", "ff11::b5:4", port=port)
    try:
        from transport.wheel_drivers import WheelDrivers
        host = WheelDrivers(host_bus)
        deadline = time.monotonic() + 20
        while host.feedback() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        host.arm()
        proc = subprocess.Popen([sys.executable, "-m", "hil.cli", "can", "replay", str(log),
                                 "--can-interface", "udp_multicast", "--can-channel",
                                 "ff11::b5:4", "--can-port", str(port)], cwd=ROOT,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        while proc.poll() is None:
            host.command(0.5, 0.5)
            time.sleep(0.02)
        assert proc.stderr is not None
        assert proc.returncode == 2 and "armed agent" in proc.stderr.read()
    finally:
        host_bus.shutdown()
        drivers.terminate()
        drivers.wait(timeout=10)


def test_killing_the_writer_shows_a_watchdog_alarm_within_a_second():
    port = free_port("udp6")
    group = "ff11::b5:5"
    drivers = subprocess.Popen([sys.executable, "-m", "hil.cli", "plant", "--drivers-only",
                                "--can-interface", "udp_multicast", "--can-channel", group,
                                "--can-port", str(port)], cwd=ROOT, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    agent = subprocess.Popen([sys.executable, "-c", f"""
import time
from transport.canbus import open_bus
from transport.wheel_drivers import WheelDrivers
host = WheelDrivers(open_bus("udp_multicast", "{group}", port={port}))
while host.feedback() is None:
    time.sleep(0.02)
host.arm()
print("armed", flush=True)
while True:
    host.command(1.0, 1.0)
    time.sleep(0.02)
"""], cwd=ROOT, stdout=subprocess.PIPE)
    try:
        assert agent.stdout is not None
        assert agent.stdout.readline().strip() == b"armed"
        watch = open_bus("udp_multicast", group, port=port)
        try:
            assert armed_writer(watch, listen=0.5)
            os.kill(agent.pid, signal.SIGKILL)
            t_kill = time.monotonic()
            stats = BusStats()
            seen = None
            while time.monotonic() - t_kill < 1.0 and seen is None:
                m = watch.recv(0.05)
                if m is not None:
                    stats.feed(m)
                if any(a.kind == "watchdog" for a in stats.alarms(time.time())):
                    seen = time.monotonic() - t_kill
        finally:
            watch.shutdown()
        assert seen is not None and seen < 1.0
    finally:
        for p in (agent, drivers):
            if p.poll() is None:
                p.kill()
            p.wait(timeout=10)


def test_stats_json_shape_from_the_cli(tmp_path):
    port = free_port("udp6")
    drivers = subprocess.Popen([sys.executable, "-m", "hil.cli", "plant", "--drivers-only",
                                "--can-interface", "udp_multicast", "--can-channel",
                                "ff11::b5:6", "--can-port", str(port)], cwd=ROOT,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        out = subprocess.run([sys.executable, "-m", "hil.cli", "can", "stats", "--duration",
                              "1.5", "--json", "--can-interface", "udp_multicast",
                              "--can-channel", "ff11::b5:6", "--can-port", str(port)],
                             capture_output=True, text=True, cwd=ROOT, timeout=60, check=True)
    finally:
        drivers.terminate()
        drivers.wait(timeout=10)
    doc = json.loads(out.stdout)
    assert doc["bitrate"] == 500000 and 0 < doc["bus_load"] < 0.2
    names = {(m["name"], m["node"]) for m in doc["messages"]}
    assert ("Get_Encoder_Estimates", 0) in names and ("Heartbeat", 1) in names
    assert all({"name", "node", "rate_hz", "count"} <= set(m) for m in doc["messages"])
