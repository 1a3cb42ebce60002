"""Deployment bundles: manifest validation, certificates, systemd units, and the ground
router's mutual TLS and access control with real Zenoh sessions on loopback."""
import json
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import zenoh
from cryptography import x509
from helpers import free_port

from hil.ground.deploy import DeployError, deploy, load_manifest

ROOT = Path(__file__).resolve().parent.parent
VENV_BIN = Path(sys.executable).parent


MANIFEST = """version = 1
swarm = "field"
scenario = "{scenario}"
[router]
address = "127.0.0.1"
port = {port}
[gcs]
mavlink = "udpout:127.0.0.1:14550"
[[robots]]
id = 1
host = "robot-1.local"
can_interface = "can0"
[[robots]]
id = 2
host = "robot-2.local"
can_interface = "can1"
bitrate = 1000000
"""


@pytest.fixture(scope="module")
def bundles(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("deploy")
    port = free_port()
    path = tmp / "swarm.toml"
    path.write_text(MANIFEST.format(scenario=ROOT / "scenarios" / "sitl_small.toml", port=port))
    prefix = tmp / "prefix"                       # where install.sh would put the venv
    (prefix / "venv" / "bin").mkdir(parents=True)
    (prefix / "venv" / "bin" / "boundswarm").symlink_to(VENV_BIN / "boundswarm")
    out = tmp / "out"
    made = deploy(load_manifest(path), out, prefix=str(prefix), etc=str(out / "robot-1"))
    return {"out": out, "port": port, "made": made}


def test_bundle_contents_and_private_keys(bundles):
    out = bundles["out"]
    assert set(bundles["made"]) == {"ground", "robot-1", "robot-2"}
    r1 = {p.relative_to(out / "robot-1").as_posix() for p in (out / "robot-1").rglob("*")
          if p.is_file()}
    assert {"agent.toml", "zenoh.json5", "boundswarm-agent.service", "install.sh",
            "mavlink.key", "certs/ca.pem", "certs/robot-1.pem", "certs/robot-1.key"} <= r1
    assert not [p for p in r1 if p.endswith(".key") and p not in ("mavlink.key",
                                                                   "certs/robot-1.key")]
    assert any(p.startswith("wheels/boundswarm-") for p in r1)
    assert (out / "robot-1" / "certs" / "robot-1.key").stat().st_mode & 0o077 == 0
    assert len((out / "robot-1" / "mavlink.key").read_bytes()) == 32
    ca = x509.load_pem_x509_certificate((out / "ground" / "certs" / "ca.pem").read_bytes())
    cert = x509.load_pem_x509_certificate((out / "robot-2" / "certs" / "robot-2.pem").read_bytes())
    cert.verify_directly_issued_by(ca)
    assert cert.subject.rfc4514_string().endswith("CN=robot-2") or \
        "CN=robot-2" in cert.subject.rfc4514_string()
    agent = (out / "robot-2" / "agent.toml").read_text()
    assert 'channel = "can1"' in agent and "bitrate = 1000000" in agent
    assert 'config = "zenoh.json5"' in agent
    unit = (out / "robot-2" / "boundswarm-agent.service").read_text()
    assert "Type=notify" in unit and "WatchdogSec=" in unit and "Restart=on-failure" in unit
    assert "ip link set can1 up type can bitrate 1000000" in unit


def test_the_unit_documents_itself_with_the_installed_readme(bundles):
    """Documentation= names the README that install.sh installs, not a host elsewhere."""
    b = bundles["out"] / "robot-2"
    unit = (b / "boundswarm-agent.service").read_text()
    doc = next(line for line in unit.splitlines() if line.startswith("Documentation="))
    prefix = Path(doc.removeprefix("Documentation=file://")).parent
    assert doc == f"Documentation=file://{prefix}/README.md" and "http" not in unit
    assert f'install -m 0644 "$HERE"/README.md {prefix}/' in (b / "install.sh").read_text()
    notes = (b / "README.md").read_text()
    assert "robot 2" in notes and "can1" in notes and "journalctl -u boundswarm-agent" in notes


@pytest.mark.skipif(shutil.which("systemd-analyze") is None,
                    reason="systemd-analyze is not installed")
def test_units_pass_systemd_analyze_verify(bundles):
    for name in ("robot-1", "robot-2"):
        unit = bundles["out"] / name / "boundswarm-agent.service"
        proc = subprocess.run(["systemd-analyze", "verify", str(unit)], capture_output=True,
                              text=True)
        assert proc.returncode == 0, proc.stderr


def test_manifest_errors_name_the_field(tmp_path):
    good = MANIFEST.format(scenario=ROOT / "scenarios" / "sitl_small.toml", port=7447)
    for bad, field in [(good.replace("version = 1", "version = 2"), "version"),
                       (good.replace('host = "robot-1.local"\n', ""), r"robots\[0\].host"),
                       (good.replace("id = 2", "id = 1"), "duplicate robot ids"),
                       (good.replace("port = 7447", "port = 0"), r"\[router\] port"),
                       (good + "colour = 1\n", r"robots\[1\]: unknown")]:
        path = tmp_path / "m.toml"
        path.write_text(bad)
        with pytest.raises(DeployError, match=field):
            load_manifest(path)
    path = tmp_path / "m.toml"
    path.write_text(good.replace("id = 2", "id = 9"))
    with pytest.raises(DeployError, match=r"robots \[9\] are not in"):
        deploy(load_manifest(path), tmp_path / "o", wheel=ROOT / "README.md")


def _conf(path: Path) -> zenoh.Config:
    conf = zenoh.Config.from_file(str(path))
    conf.insert_json5("connect/timeout_ms", "1500")
    conf.insert_json5("connect/exit_on_failure", "true")
    return conf


def _client(out: Path, cn: str, port: int, via: int | None = None) -> zenoh.Session:
    """A client with ``cn``'s bundle certificate (paths made absolute for this test)."""
    base = out / ("ground" if cn == "ground" else cn)
    doc = json.loads((base / ("ground-client.json5" if cn == "ground" else "zenoh.json5"))
                     .read_text())
    tls = doc["transport"]["link"]["tls"]
    for k in ("root_ca_certificate", "connect_private_key", "connect_certificate"):
        tls[k] = str(base / "certs" / Path(tls[k]).name)
    doc["connect"]["endpoints"] = [f"tls/127.0.0.1:{via or port}"]
    p = base / f"test-{cn}.json5"
    p.write_text(json.dumps(doc))
    return zenoh.open(_conf(p))


@pytest.fixture
def router(bundles):
    out, port = bundles["out"], bundles["port"]
    doc = json.loads((out / "ground" / "router.json5").read_text())
    tls = doc["transport"]["link"]["tls"]
    for k in ("root_ca_certificate", "listen_private_key", "listen_certificate"):
        tls[k] = str(out / "ground" / "certs" / Path(tls[k]).name)
    doc["listen"]["endpoints"] = [f"tls/127.0.0.1:{port}"]
    path = out / "ground" / "test-router.json5"
    path.write_text(json.dumps(doc))
    session = zenoh.open(zenoh.Config.from_file(str(path)))
    try:
        yield session
    finally:
        session.close()


def test_client_without_a_valid_certificate_cannot_connect(bundles, router, tmp_path):
    port = bundles["port"]
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([f"tls/127.0.0.1:{port}"]))
    conf.insert_json5("connect/timeout_ms", "1500")
    conf.insert_json5("connect/exit_on_failure", "true")
    conf.insert_json5("transport/link/tls/root_ca_certificate",
                      json.dumps(str(bundles["out"] / "ground" / "certs" / "ca.pem")))
    with pytest.raises(zenoh.ZError):
        zenoh.open(conf).close()
    # a certificate from another swarm's CA is refused too
    other = tmp_path / "other"
    path = tmp_path / "m.toml"
    path.write_text(MANIFEST.format(scenario=ROOT / "scenarios" / "sitl_small.toml",
                                    port=port))
    deploy(load_manifest(path), other, wheel=ROOT / "README.md")
    with pytest.raises(zenoh.ZError):
        _client(other, "robot-1", port).close()


def test_a_robot_cannot_publish_on_another_robots_key(bundles, router):
    out, port = bundles["out"], bundles["port"]
    ground, r1, r2 = (_client(out, cn, port) for cn in ("ground", "robot-1", "robot-2"))
    got = []
    try:
        ground.declare_subscriber("boundswarm/field/**",
                                  lambda s: got.append((str(s.key_expr),
                                                        s.payload.to_bytes())))
        time.sleep(0.5)
        r1.put("boundswarm/field/robot/1/state", b"from robot 1")
        r2.put("boundswarm/field/robot/1/state", b"spoofed by robot 2")
        r2.put("boundswarm/field/robot/2/state", b"from robot 2")
        deadline = time.monotonic() + 3
        while len(got) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)
    finally:
        for s in (ground, r1, r2):
            s.close()
    assert ("boundswarm/field/robot/1/state", b"from robot 1") in got
    assert ("boundswarm/field/robot/2/state", b"from robot 2") in got
    assert ("boundswarm/field/robot/1/state", b"spoofed by robot 2") not in got


class TamperingLink:
    """A TCP relay on 127.0.0.1 to ``upstream`` that forwards whole TLS records; once
    ``attack`` is set, it flips a bit in each record going upstream ("flip": tampered) or
    sends each application-data record twice ("repeat": replayed). :meth:`close` ends it."""

    def __init__(self, upstream: int, mode: str):
        self.upstream, self.mode, self.attack = upstream, mode, False
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.socks: list[socket.socket] = [self.server]
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            try:
                down, _ = self.server.accept()
                up = socket.create_connection(("127.0.0.1", self.upstream))
            except OSError:
                return
            self.socks += [down, up]
            threading.Thread(target=self._pump, args=(down, up, True), daemon=True).start()
            threading.Thread(target=self._pump, args=(up, down, False), daemon=True).start()

    def _pump(self, src: socket.socket, dst: socket.socket, upstream: bool) -> None:
        buf = b""
        try:
            while data := src.recv(65536):
                buf += data
                # a TLS record: type (1 byte), version (2), length (2), then length bytes
                while len(buf) >= 5 and len(buf) >= 5 + int.from_bytes(buf[3:5], "big"):
                    end = 5 + int.from_bytes(buf[3:5], "big")
                    record, buf = buf[:end], buf[end:]
                    attacked = upstream and self.attack
                    if attacked and self.mode == "flip":
                        record = record[:-1] + bytes([record[-1] ^ 0x01])
                    dst.sendall(record)
                    if attacked and self.mode == "repeat" and record[0] == 23:
                        dst.sendall(record)
        except OSError:
            pass
        for sock in (src, dst):
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    def close(self) -> None:
        try:
            self.server.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        for sock in self.socks:
            sock.close()


@pytest.mark.parametrize("mode", ["flip", "repeat"])
def test_tampered_or_replayed_records_on_a_robot_link_deliver_nothing(bundles, router, mode):
    """Mutual TLS on the link: a modified or repeated record breaks robot 1's connection at
    the router; no altered or repeated state reaches a subscriber."""
    from common.payloads import StateMsg
    from common.vocabulary import StateFlags
    out, port = bundles["out"], bundles["port"]
    link = TamperingLink(port, mode)
    got: list[bytes] = []
    ground = r1 = None
    try:
        ground = _client(out, "ground", port)
        ground.declare_subscriber("boundswarm/field/robot/1/state",
                                  lambda s: got.append(s.payload.to_bytes()))
        r1 = _client(out, "robot-1", port, via=link.port)
        time.sleep(0.5)
        sent, first_attacked = {}, None
        for seq in range(1, 61):
            if seq == 21:
                link.attack, first_attacked = True, seq
            payload = StateMsg(1, seq, time.time(), float(seq), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                               0, StateFlags(0)).encode()
            sent[seq] = payload
            r1.put("boundswarm/field/robot/1/state", payload)
            time.sleep(0.05)
        time.sleep(0.5)
    finally:
        for session in (r1, ground):
            if session is not None:
                session.close()
        link.close()
    seqs = [StateMsg.decode(p).seq for p in got]
    assert first_attacked is not None
    assert all(p == sent[s] for p, s in zip(got, seqs))         # nothing altered
    assert len(seqs) == len(set(seqs))                           # nothing twice
    assert len([s for s in seqs if s < first_attacked]) >= 15    # the link worked before
    assert not [s for s in seqs if s > first_attacked]           # and carried nothing after


def test_a_replayed_state_payload_is_dropped_by_the_neighbours(bundles, router):
    """An old state of robot 1 sent again on its key (by a valid client) is older than the
    one held: robot 2's agent drops it and counts it."""
    from common.payloads import StateMsg
    from common.vocabulary import StateFlags
    from transport.zenoh_link import Keys, SwarmLink
    out, port = bundles["out"], bundles["port"]
    r1, r2 = _client(out, "robot-1", port), _client(out, "robot-2", port)
    two = SwarmLink(r2, Keys("field"), 2, time.time)
    try:
        time.sleep(0.5)
        payloads = [StateMsg(1, seq, time.time(), float(seq), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0,
                             StateFlags(0)).encode() for seq in (1, 2, 3)]
        for p in payloads:
            r1.put("boundswarm/field/robot/1/state", p)
            time.sleep(0.05)
        deadline = time.monotonic() + 5
        while (1 not in two.neighbours() or two.neighbours()[1].msg.seq != 3) \
                and time.monotonic() < deadline:
            time.sleep(0.05)
        r1.put("boundswarm/field/robot/1/state", payloads[0])        # the replay
        deadline = time.monotonic() + 5
        while not two.counters()["states"]["dropped"] and time.monotonic() < deadline:
            time.sleep(0.05)
        assert two.neighbours()[1].msg.seq == 3 and two.neighbours()[1].msg.x == 3.0
        assert two.counters()["states"]["dropped"] == {"out_of_order": 1}
    finally:
        two.close()
        r1.close()
        r2.close()


def test_the_example_manifest_deploys_with_its_motion_capture_bridge(tmp_path):
    from agent.pose import PoseSettings
    from agent.settings import load_settings
    from hil.ground.mocap import load_mocap_settings
    made = deploy(load_manifest(ROOT / "examples" / "swarm.toml"), tmp_path,
                  wheel=ROOT / "README.md")
    assert set(made) == {"ground"} | {f"robot-{i}" for i in range(1, 10)}
    bridge = load_mocap_settings(tmp_path / "ground" / "mocap.toml")
    assert bridge.swarm == "field" and bridge.system == "vicon"
    assert bridge.hostname == "192.0.2.20" and bridge.error == 0.005
    assert [(b.name, b.robot) for b in bridge.bodies] == [(f"cart{i}", i) for i in range(1, 10)]
    assert bridge.zenoh.config == str(tmp_path / "ground" / "ground-client.json5")
    agent = load_settings(tmp_path / "robot-4" / "agent.toml")
    assert agent.pose == PoseSettings(fix_timeout=0.5) and agent.robot_id == 4
    notes = (tmp_path / "ground" / "README.md").read_text()
    assert "boundswarm mocap --config mocap.toml" in notes and "cart4 -> robot 4" in notes
    assert "README.md[mocap]" in notes                     # the bundled wheel, its extra


def test_without_mocap_no_bridge_and_no_pose_table(bundles):
    out = bundles["out"]
    assert not (out / "ground" / "mocap.toml").exists()
    assert "[pose]" not in (out / "robot-1" / "agent.toml").read_text()
    assert "boundswarm mocap" not in (out / "ground" / "README.md").read_text()


def test_mocap_table_errors_name_the_field(tmp_path):
    good = MANIFEST.format(scenario=ROOT / "scenarios" / "sitl_small.toml", port=7447)
    mocap = '[mocap]\nsystem = "vicon"\nhostname = "10.0.0.2"\n'
    at = good.index("[[robots]]")
    for bad, field in [(mocap + "rate = 100\n", r"m.toml \[mocap\]: unknown field\(s\) rate"),
                       (mocap.replace("vicon", "kinect"), r"\[mocap\]: MocapSettings.system"),
                       (mocap + "fix_timeout = 0\n", r"\[mocap\]: PoseSettings.fix_timeout"),
                       ('[mocap]\nsystem = "qualisys"\n', "MocapSettings.hostname: missing")]:
        path = tmp_path / "m.toml"
        path.write_text(good[:at] + bad + good[at:])
        with pytest.raises(DeployError, match=field):
            load_manifest(path)
    path = tmp_path / "m.toml"
    path.write_text(good[:at] + mocap + good[at:].replace(
        'can_interface = "can0"', 'can_interface = "can0"\nrigid_body = "robot-2"'))
    with pytest.raises(DeployError, match=r"bodies: name given twice: \['robot-2'\]"):
        load_manifest(path)
