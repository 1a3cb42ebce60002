"""The motion-capture bridge (boundswarm mocap) on libmotioncapture's mock system: frames to
fixes, its config, and the command end to end on a loopback router (its process ended,
pass or fail)."""
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import motioncapture
import pytest
import zenoh
from helpers import free_port

from common.payloads import FixMsg
from common.schema import ConfigError
from hil.ground.mocap import Bridge, load_mocap_settings, yaw
from transport.zenoh_link import Keys, open_session, session_config

ROOT = Path(__file__).resolve().parent.parent
S = math.sqrt(0.5)
# rigid bodies of the mock system: name(x, y, z, qw, qx, qy, qz)
BODIES = (f"robot-1(1.5,-2.0,0.1,{S},0,0,{S});robot-2(3.0,4.0,0.0,1,0,0,0);"
          f"wand(0,0,1,1,0,0,0)")

CONFIG = """swarm = "lab"
system = "mock"
options = ["rigid_bodies={bodies}", "frequency=200"]
error = 0.004
latency = 0.002
[zenoh]
connect = ["{endpoint}"]
[[bodies]]
name = "robot-1"
robot = 1
[[bodies]]
name = "robot-2"
robot = 2
[[bodies]]
name = "robot-3"
robot = 3
"""


def _config(tmp_path, endpoint="tcp/127.0.0.1:7447", text=CONFIG, bodies=BODIES):
    path = tmp_path / "mocap.toml"
    path.write_text(text.format(bodies=bodies, endpoint=endpoint))
    return path


def test_the_heading_is_the_yaw_of_the_quaternion():
    for theta in (0.0, 0.5, -2.0, 3.0):
        assert yaw(math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2)) == pytest.approx(theta)
    # a body rolled about its own x axis (q = q_z(0.8) q_x(0.4)) keeps its heading
    w, x = math.cos(0.2), math.sin(0.2)
    q = (math.cos(0.4) * w, math.cos(0.4) * x, math.sin(0.4) * x, math.sin(0.4) * w)
    assert yaw(*q) == pytest.approx(0.8)


def test_frames_of_the_mock_system_become_fixes_of_the_mapped_robots(tmp_path, caplog):
    s = load_mocap_settings(_config(tmp_path))
    mc = motioncapture.connect("mock", s.connect_options())
    sent = []
    bridge = Bridge(s, lambda rid, data: sent.append(FixMsg.decode(data)))
    t0 = 1.7e9
    for k in range(150):                      # 0.75 s of frames at 200 Hz
        mc.waitForNextFrame()
        bridge.frame(mc.rigidBodies, t0 + k / 200)
    one = [m for m in sent if m.robot_id == 1]
    two = [m for m in sent if m.robot_id == 2]
    assert len(one) == len(two) == 150 and {m.robot_id for m in sent} == {1, 2}
    assert (one[0].x, one[0].y) == pytest.approx((1.5, -2.0))
    assert one[0].theta == pytest.approx(math.pi / 2, abs=1e-5) and two[0].theta == 0.0
    assert one[0].error == pytest.approx(0.004) and one[-1].stamp == pytest.approx(
        t0 + 149 / 200 - 0.002)                              # arrival less the latency
    assert bridge.counters()["missing"] == {"robot-3": 150}
    assert "'robot-3' (robot 3) not seen for 0.5 s" in caplog.text


def test_the_config_is_checked_naming_file_and_key(tmp_path):
    with pytest.raises(ConfigError, match=r"mocap.toml: unknown field\(s\) host"):
        load_mocap_settings(_config(tmp_path, text='host = "x"\n' + CONFIG))
    with pytest.raises(ConfigError, match=r"mocap.toml: MocapSettings.system: expected vicon"):
        load_mocap_settings(_config(tmp_path, text=CONFIG.replace('"mock"', '"kinect"')))
    with pytest.raises(ConfigError, match=r"mocap.toml: MocapSettings.bodies: robot given "
                                          r"twice: \[1\]"):
        load_mocap_settings(_config(tmp_path, text=CONFIG.replace("robot = 2", "robot = 1")))
    with pytest.raises(ConfigError, match="MocapSettings.hostname: missing"):
        load_mocap_settings(_config(tmp_path, text=CONFIG.replace('"mock"', '"vicon"')))
    with pytest.raises(ConfigError, match=r"mocap.toml \[zenoh\]: unknown field\(s\) port"):
        load_mocap_settings(_config(tmp_path, text=CONFIG.replace("[zenoh]\n",
                                                                  "[zenoh]\nport = 1\n")))
    with pytest.raises(ConfigError, match="expected key=value"):
        load_mocap_settings(_config(tmp_path, text=CONFIG.replace('"frequency=200"',
                                                                  '"frequency"')))


def test_boundswarm_mocap_publishes_fixes_on_the_swarms_keys(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_session(session_config("router", listen=[endpoint]), "router")
    sub = router.declare_subscriber(Keys("lab").fix("*"), zenoh.handlers.FifoChannel(4096))
    stats = tmp_path / "stats.json"
    proc = subprocess.Popen(
        [sys.executable, "-m", "hil.cli", "mocap", "--config",
         str(_config(tmp_path, endpoint)), "--stats", str(stats), "--frames", "400"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        raw, _ = proc.communicate(timeout=60)
        text = raw.decode(errors="replace")
        assert proc.returncode == 0, text
        time.sleep(0.2)
        got = []
        while (sample := sub.try_recv()) is not None:
            got.append((str(sample.key_expr), FixMsg.decode(sample.payload.to_bytes())))
        keys = {k for k, _ in got}
        assert keys == {"boundswarm/lab/robot/1/fix", "boundswarm/lab/robot/2/fix"}, keys
        assert all(k.endswith(f"/{m.robot_id}/fix") for k, m in got)
        one = [m for _, m in got if m.robot_id == 1]
        assert len(one) > 300 and abs(one[-1].stamp - time.time()) < 30.0
        counters = json.loads(stats.read_text())
        assert counters["frames"] == 400 and counters["missing"] == {"robot-3": 400}
        assert "robot-3" in text
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()
        sub.undeclare()
        router.close()


def test_a_signal_ends_the_bridge(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_session(session_config("router", listen=[endpoint]), "router")
    proc = subprocess.Popen(
        [sys.executable, "-m", "hil.cli", "mocap", "--config", str(_config(tmp_path, endpoint))],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        time.sleep(3.0)
        proc.send_signal(signal.SIGTERM)
        text, _ = proc.communicate(timeout=20)
        assert proc.returncode == 0, text
        assert b"frames; fixes per robot" in text
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()
        router.close()


def test_robot_side_modules_do_not_import_motioncapture():
    code = ("import sys, agent.process, agent.node, agent.pose; "
            "print('motioncapture' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, check=True)
    assert out.stdout.strip() == "False"
