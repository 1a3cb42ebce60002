"""Zenoh link over a router on loopback (scouting off): keys, latest values, presence."""
import math
import threading
import time

import pytest
from helpers import free_port

from common.payloads import StateMsg
from common.vocabulary import StateFlags
from hil.sitl.processes import wait_until
from transport.zenoh_link import Keys, Latest, Presence, open_session, session_config


@pytest.fixture
def sessions():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    opened = []
    try:
        opened.append(open_session(session_config("router", listen=[endpoint]), "router"))
        for _ in range(2):
            opened.append(open_session(session_config("client", connect=[endpoint]), "client"))
        yield opened[1], opened[2]
    finally:
        for s in reversed(opened):
            s.close()


def state(rid, seq, stamp):
    return StateMsg(rid, seq, stamp, 1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, StateFlags(0))


def test_keys():
    k = Keys("demo")
    assert k.state(3) == "boundswarm/demo/robot/3/state"
    assert k.robot(3) == "boundswarm/demo/robot/3"
    assert k.mission == "boundswarm/demo/mission" and Keys.robot_id_of(k.truth(12)) == 12
    with pytest.raises(ValueError, match="swarm name"):
        Keys("a/b")


def test_config_refuses_unknown_mode():
    with pytest.raises(ValueError, match="zenoh mode"):
        session_config("server")


def test_latest_value_cache_drops_malformed_and_own(sessions):
    a, b = sessions
    keys = Keys("t")
    cache = Latest(b, keys.state("*"), StateMsg.decode, time.time, ignore=[9])
    try:
        pub = a.declare_publisher(keys.state(1))
        time.sleep(0.2)
        snap_before = cache.snapshot()
        for seq in range(5):
            pub.put(state(1, seq, 100.0 + seq).encode())
        a.put(keys.state(2), b"garbage")
        a.put(keys.state(9), state(9, 0, 1.0).encode())          # own id: ignored
        a.put(keys.state(1), state(1, 99, 50.0).encode())        # older stamp: out of order
        assert wait_until(lambda: cache.counters()["received"] >= 8, 5.0, poll=0.01)
        snap = cache.snapshot()
        assert list(snap) == [1] and snap[1].msg.seq == 4
        assert dict(snap_before) == {}                            # snapshots never change
        c = cache.counters()
        assert c["dropped"] == {"size": 1, "out_of_order": 1} and c["accepted"] == 5
        with pytest.raises(TypeError):
            # a write to the read-only snapshot, on purpose: refused at run time
            snap[5] = None  # type: ignore[index]
    finally:
        cache.close()


def test_presence_join_and_leave(sessions):
    a, b = sessions
    keys = Keys("t")
    presence = Presence(b, keys)
    try:
        token = a.liveliness().declare_token(keys.robot(4))
        assert wait_until(lambda: presence.alive() == {4}, 5.0, poll=0.01)
        token.undeclare()
        assert wait_until(lambda: presence.alive() == frozenset(), 5.0, poll=0.01)
        assert presence.left[4] == 1
    finally:
        presence.close()


def test_unreachable_router_is_a_clear_error():
    conf = session_config("client", connect=[f"tcp/127.0.0.1:{free_port()}"])
    conf.insert_json5("connect/timeout_ms", "200")
    conf.insert_json5("connect/exit_on_failure", "true")
    with pytest.raises(ConnectionError, match="cannot open the zenoh session for agent 3"):
        open_session(conf, "agent 3")


def test_swarm_link_between_two_agents_and_a_recording(sessions, tmp_path):
    import numpy as np

    from common.payloads import MissionMsg, ObstaclesMsg
    from hil.ground.recorder import Recorder, read_messages
    from transport.zenoh_link import SwarmLink

    a, b = sessions
    keys = Keys("t")
    rec = Recorder(b, keys, tmp_path / "run.mcap")
    one, two = SwarmLink(a, keys, 1, time.time), SwarmLink(b, keys, 2, time.time)
    try:
        time.sleep(0.3)
        one.publish(state(1, 1, time.time()))
        a.put(keys.obstacles(2), ObstaclesMsg(2, 1, time.time(), np.array([[1.0, 2.0]]),
                                              np.array([0.5])).encode())
        a.put(keys.mission, MissionMsg(1, time.time(), time.time(), (0.0, 0.0), (1.0, 0.0),
                                       0.0, np.array([1, 2]), np.zeros((2, 2))).encode())
        a.put(keys.state(5), b"\x01\x01bad")
        assert wait_until(lambda: two.mission() is not None and two.obstacles() is not None
                          and 1 in two.neighbours(), 5.0, poll=0.01)
        obstacles, mission = two.obstacles(), one.mission()
        assert obstacles is not None and mission is not None
        assert obstacles.radii.tolist() == [0.5] and mission.ids.tolist() == [1, 2]
        assert 2 not in two.neighbours()                        # own state not a neighbour
        assert wait_until(lambda: rec.recorded >= 3, 5.0, poll=0.01)
    finally:
        one.close()
        two.close()
        rec.close()
    kinds = [kind for _, kind, _, _ in read_messages(tmp_path / "run.mcap")]
    assert {"state", "obstacles", "mission"} <= set(kinds)
    assert rec.dropped["size"] == 1


def test_near_states_subscribe_to_near_robots_only(sessions):
    """With a near radius, full-rate states come only from robots near; beacons from all."""
    from transport.zenoh_link import SwarmLink

    a, b = sessions
    keys = Keys("near")
    setup_in = []
    me = SwarmLink(a, keys, 1, time.time, near_radius=10.0,
                   thread_setup=lambda: setup_in.append(threading.current_thread().name))
    near, far = SwarmLink(b, keys, 2, time.time), SwarmLink(b, keys, 3, time.time)

    def at(link, rid, seq, x):
        link.publish(StateMsg(rid, seq, time.time(), x, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0,
                              StateFlags(0)))

    try:
        time.sleep(0.3)
        seq = 0

        def round_(x_near, x_far, seconds):
            nonlocal seq
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                seq += 1
                at(near, 2, seq, x_near)
                at(far, 3, seq, x_far)
                at(me, 1, seq, 0.0)
                me.neighbours()
                time.sleep(0.02)

        round_(5.0, 50.0, 1.5)
        c = me.counters()
        assert c["near"] == [2]                                   # robot 3 is 50 m away
        assert set(me.neighbours()) == {2, 3}                     # ... but known from beacons
        assert c["states"]["accepted"] > 20                       # ~50 Hz from robot 2
        assert 4 <= c["beacons"]["accepted"] <= 25                # 5 Hz from each of 2, 3
        # robot 3 comes near, robot 2 goes far beyond radius + hysteresis
        round_(30.0, 4.0, 1.0)
        assert me.counters()["near"] == [3]
        # robot 2's dropped subscription still counts; the refocus thread ran the setup
        assert me.counters()["states"]["accepted"] > c["states"]["accepted"]
        assert setup_in == ["near-refocus-1"]
        last = me.neighbours()[3].msg
        assert last.x == 4.0 and time.time() - last.stamp < 0.2   # full rate, fresh
    finally:
        for link in (me, near, far):
            link.close()


def test_near_radius_below_the_sensing_range_is_refused(tmp_path):
    from agent.settings import load_settings
    from common.schema import ConfigError

    cfg = tmp_path / "robot.toml"
    cfg.write_text('robot_id = 1\nswarm = "s"\ninitial_pose = [0.0, 0.0, 0.0]\n'
                   '[zenoh]\nnear_radius = 5.0\n[sensing]\nrange = 8.0\n')
    with pytest.raises(ConfigError, match=r"\[zenoh\] near_radius.*at least the sensing range"):
        load_settings(cfg)


def test_a_client_waits_for_a_router_that_starts_after_it():
    """Agents and plants start with their router, not after it: a client retries for a
    while instead of failing on the first refused connection."""
    import threading

    from helpers import free_port
    port = free_port("tcp")
    endpoint = f"tcp/127.0.0.1:{port}"
    routers = []
    starter = threading.Timer(0.5, lambda: routers.append(
        open_session(session_config("router", listen=[endpoint]), "late router")))
    starter.start()
    try:
        client = open_session(session_config("client", connect=[endpoint]), "early client")
        client.close()
    finally:
        starter.join()
        for r in routers:
            r.close()
    assert routers


def test_a_state_carries_its_routers_timestamp_and_publications_are_counted(sessions):
    from transport.zenoh_link import SwarmLink
    a, b = sessions
    keys = Keys("t")
    one = SwarmLink(a, keys, 1, time.time)
    got = Latest(b, keys.state("*"), StateMsg.decode, time.time)
    try:
        time.sleep(0.3)
        t0 = time.time()
        one.publish(state(1, 1, t0))
        assert wait_until(lambda: 1 in got.snapshot(), 5.0, poll=0.01)
        rec = got.snapshot()[1]
        # one machine, one clock: published, then routed, then taken (1 ms for rounding)
        assert rec.routed is not None
        assert t0 - 1e-3 <= rec.routed <= rec.received + 1e-3
        assert one.counters()["published"] == 1
    finally:
        got.close()
        one.close()


def test_a_robot_closing_in_fast_is_followed_at_full_rate_before_it_is_near(sessions):
    """12 m away, radius 10, from one driving east at 3 m/s: a robot coming at 3 m/s from
    the east is subscribed to (they may close 2.4 m before its states flow), one beside it
    driving east as fast is not."""
    from transport.zenoh_link import SwarmLink

    a, b = sessions
    keys = Keys("lead")
    me = SwarmLink(a, keys, 1, time.time, near_radius=10.0)
    fast, along = SwarmLink(b, keys, 2, time.time), SwarmLink(b, keys, 3, time.time)
    try:
        time.sleep(0.3)
        end = time.monotonic() + 1.5
        seq = 0
        while time.monotonic() < end:
            seq += 1
            for link, rid, x, y, theta in ((fast, 2, 12.0, 0.0, math.pi),
                                           (along, 3, 0.0, 12.0, 0.0), (me, 1, 0.0, 0.0, 0.0)):
                link.publish(StateMsg(rid, seq, time.time(), x, y, theta, 3.0, 0.0, 0.0, 0.0, 0,
                                      StateFlags(0)))
            me.neighbours()
            time.sleep(0.02)
        assert me.counters()["near"] == [2]
    finally:
        for link in (me, fast, along):
            link.close()
