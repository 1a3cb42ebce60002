"""The MCAP recorder: JSON exactly as before, every message of a swarm recorded, none lost."""
import dataclasses
import json
import time

import numpy as np
import pytest
from helpers import free_port
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from common.payloads import MissionMsg, ObstaclesMsg, PayloadError, StateMsg, TruthMsg, WheelsMsg
from common.vocabulary import StateFlags
from hil.ground.recorder import ENCODERS, Recorder, read_messages
from hil.sitl.processes import wait_until
from transport.zenoh_link import Keys, open_session, session_config


def reference_json(msg) -> bytes:
    """The recorder's JSON before it was made faster (dataclass fields, isinstance, dumps)."""
    out = {}
    for f in dataclasses.fields(msg):
        value = getattr(msg, f.name)
        if isinstance(value, np.ndarray):
            value = value.tolist()
        elif isinstance(value, tuple):
            value = list(value)
        elif isinstance(value, (np.integer, int)) and not isinstance(value, bool):
            value = int(value)
        out[f.name] = value
    return json.dumps(out).encode()


def same_as_before(kind: str, cls, payload: bytes) -> None:
    data, stamp = ENCODERS[kind](payload)
    msg = cls.decode(payload)
    assert data == reference_json(msg) and stamp == msg.stamp


f32 = st.floats(allow_nan=False, allow_infinity=False, width=32)
f64 = st.floats(allow_nan=False, allow_infinity=False)
u16, u32 = st.integers(0, 0xFFFF), st.integers(0, 0xFFFFFFFF)


@settings(max_examples=300, deadline=None)
@given(u16, u32, f64, st.lists(f32, min_size=7, max_size=7), st.integers(0, 255),
       st.integers(0, 7))
def test_state_json_is_unchanged(rid, seq, stamp, values, mode, flags):
    x, y, theta, v, u, x_d, y_d = values
    same_as_before("state", StateMsg, StateMsg(rid, seq, stamp, x, y, theta, v, u, x_d, y_d,
                                               mode, StateFlags(flags)).encode())


@settings(max_examples=300, deadline=None)
@given(u16, u32, f64, st.lists(f64, min_size=5, max_size=5))
def test_truth_json_is_unchanged(rid, seq, stamp, values):
    same_as_before("truth", TruthMsg, TruthMsg(rid, seq, stamp, *values).encode())


@pytest.mark.parametrize("k", [0, 1, 3])
def test_obstacles_and_mission_json_are_unchanged(k):
    rng = np.random.default_rng(k)
    same_as_before("obstacles", ObstaclesMsg,
                   ObstaclesMsg(4, 9, 1.7e9 + 0.1, rng.normal(size=(k, 2)),
                                rng.uniform(0.1, 2.0, k)).encode())
    same_as_before("mission", MissionMsg,
                   MissionMsg(2, 1.7e9, 1.7e9 + 3.0, (1.5, -2.0), (0.1, 0.0), 0.05,
                              np.arange(1, k + 1), rng.normal(size=(k, 2))).encode())


def test_a_bad_payload_raises_as_its_decoder_does():
    good = StateMsg(1, 1, 1.0, 0, 0, 0, 0, 0, 0, 0, 0, StateFlags(0)).encode()
    for bad, reason in [(good[:-1], "size"), (b"\x02" + good[1:], "version"),
                        (TruthMsg(1, 1, 1.0, 0, 0, 0, 0, 0).encode(), "kind"),
                        (good[:8] + np.float64(np.inf).tobytes() + good[16:], "nonfinite")]:
        with pytest.raises(PayloadError) as exc:
            ENCODERS["state"](bad)
        assert exc.value.reason == reason


@pytest.fixture
def sessions():
    """A router (where the SITL launcher records) and a client on loopback."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_session(session_config("router", listen=[endpoint]), "router")
    client = open_session(session_config("client", connect=[endpoint]), "client")
    try:
        yield router, client
    finally:
        client.close()
        router.close()



def publish_swarm(session, keys, ticks: int) -> dict[str, set]:
    """States, truths and obstacles of 5 robots, beacons and wheels (not recorded), a mission
    and bad payloads; returns the recorded (topic, seq) expected of each kind."""
    sent: dict[str, set] = {"state": set(), "truth": set(), "obstacles": set(), "mission": set()}
    for tick in range(ticks):
        now = time.time()
        for r in range(1, 6):
            payloads = {"state": StateMsg(r, tick, now, 0.1 * r, 2.0, 0.3, 0.2, 0.0, 1.0, 2.0,
                                          2, StateFlags(1)).encode(),
                        "truth": TruthMsg(r, tick, now, 0.1 * r, 2.0, 0.3, 0.2, 0.01).encode(),
                        "obstacles": ObstaclesMsg(r, tick, now, np.array([[1.0, 2.0]]),
                                                  np.array([0.5])).encode()}
            for kind, payload in payloads.items():
                key = getattr(keys, kind)(r)
                session.put(key, payload)
                sent[kind].add(("/" + key, tick))
            session.put(keys.beacon(r), payloads["state"])
            session.put(keys.wheels(r), WheelsMsg(r, tick, now, 0, 0, 0, 0).encode())
    session.put(keys.mission, MissionMsg(7, time.time(), time.time(), (0.0, 0.0), (1.0, 0.0),
                                         0.0, np.array([1, 2]), np.zeros((2, 2))).encode())
    sent["mission"].add(("/" + keys.mission, 7))
    session.put(keys.state(9), b"\x01\x01bad")
    session.put(keys.truth(9), StateMsg(9, 0, 1.0, 0, 0, 0, 0, 0, 0, 0, 0, StateFlags(0)).encode())
    return sent


def recorded(path) -> dict[str, list]:
    got: dict[str, list] = {}
    for topic, kind, _, msg in read_messages(path):
        got.setdefault(kind, []).append((topic, msg["seq"]))
    return got


def test_every_published_message_is_recorded_once(sessions, tmp_path):
    router, client = sessions
    keys = Keys("t")
    start = time.time()
    rec = Recorder(router, keys, tmp_path / "run.mcap")
    try:
        time.sleep(0.3)
        sent = publish_swarm(client, keys, ticks=200)
        total = sum(map(len, sent.values()))
        assert wait_until(lambda: rec.recorded >= total, 10.0, poll=0.01)
    finally:
        rec.close()
    got = recorded(tmp_path / "run.mcap")
    assert {kind: sorted(rows) for kind, rows in got.items()} == \
        {kind: sorted(rows) for kind, rows in sent.items()}                  # once each, no more
    assert rec.recorded == total and rec.dropped == {"size": 1, "kind": 1}
    with open(tmp_path / "run.mcap", "rb") as f:                           # no empty channels
        summary = make_reader(f).get_summary()
        assert summary is not None
        channels = summary.channels.values()
    assert sorted(c.topic for c in channels) == sorted({t for rows in sent.values()
                                                        for t, _ in rows})
    times = [t for _, _, t, _ in read_messages(tmp_path / "run.mcap")]
    assert start <= times[0] and times[-1] <= time.time()                   # arrival times


def test_close_writes_what_arrived_and_not_yet_written(sessions, tmp_path):
    router, client = sessions
    keys = Keys("t")
    rec = Recorder(router, keys, tmp_path / "run.mcap", interval=3600.0)   # only close writes
    arrived = []
    probe = router.declare_subscriber(keys.truth("*"), lambda s: arrived.append(s))
    try:
        time.sleep(0.3)
        sent = publish_swarm(client, keys, ticks=100)
        assert wait_until(lambda: len(arrived) >= len(sent["truth"]), 10.0, poll=0.01)
        time.sleep(0.2)
        assert rec.recorded == 0
    finally:
        probe.undeclare()
        rec.close()
    assert {kind: sorted(rows) for kind, rows in recorded(tmp_path / "run.mcap").items()} == \
        {kind: sorted(rows) for kind, rows in sent.items()}
    rec.close()                                                              # twice is fine


def test_without_zenoh_timestamps_log_time_is_the_recorders_clock(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_session(session_config("router", listen=[endpoint],
                                         extra={"timestamping/enabled": False}), "router")
    client = open_session(session_config("client", connect=[endpoint]), "client")
    keys = Keys("t")
    rec = Recorder(router, keys, tmp_path / "run.mcap", clock=lambda: 1234.5)
    try:
        time.sleep(0.3)
        client.put(keys.state(1), StateMsg(1, 1, 99.0, 0, 0, 0, 0, 0, 0, 0, 0,
                                           StateFlags(0)).encode())
        assert wait_until(lambda: rec.recorded == 1, 10.0, poll=0.01)
    finally:
        rec.close()
        client.close()
        router.close()
    [(topic, kind, log_time, msg)] = read_messages(tmp_path / "run.mcap")
    assert (topic, kind, log_time, msg["stamp"]) == ("/boundswarm/t/robot/1/state", "state",
                                                     1234.5, 99.0)


def test_a_failing_write_is_counted_and_the_channels_keep_emptying(sessions, tmp_path,
                                                                   monkeypatch):
    """A full disk must not stop the recorder from taking samples: Zenoh would block the
    router's routing on a full channel."""
    router, client = sessions
    keys = Keys("t")
    rec = Recorder(router, keys, tmp_path / "run.mcap")

    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(rec._writer, "add_message", disk_full)
    try:
        time.sleep(0.3)
        sent = publish_swarm(client, keys, ticks=100)
        total = sum(map(len, sent.values()))
        assert wait_until(lambda: rec.dropped["write_error"] >= total, 10.0, poll=0.01)
        assert rec.recorded == 0 and rec.dropped["write_error"] == total
    finally:
        rec.close()
