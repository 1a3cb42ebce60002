"""``boundswarm mission`` over a Zenoh router on loopback (scouting off): the places of a
formation as a set go to the robots by where they report they stand."""
import threading
import time

import pytest
from helpers import free_port

from common.payloads import MissionMsg, StateMsg
from common.vocabulary import StateFlags
from hil.cli import main
from hil.cli.exit_codes import EXIT_OK
from transport.zenoh_link import Keys, open_session, session_config

SCENARIO = """
name = "two"
duration = 5.0
robots = [{{id = 1, pose = [0.0, 0.0, 0.0]}}, {{id = 2, pose = [0.0, 5.0, 0.0]}}]
[formation]
kind = "offsets"
offsets = [[10.0, 0.0], [10.0, 5.0]]
{assign}
"""


@pytest.fixture
def swarm():
    """A router on loopback and a client standing in for robots 1 and 2, which report
    they stand where the scenario planned the other (y = 5 and y = 0)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    keys, stop, missions = Keys("t"), threading.Event(), []
    router = open_session(session_config("router", listen=[endpoint]), "router")
    robots = open_session(session_config("client", connect=[endpoint]), "robots")
    tokens = [robots.liveliness().declare_token(keys.robot(i)) for i in (1, 2)]
    sub = robots.declare_subscriber(keys.mission,
                                    lambda s: missions.append(MissionMsg.decode(
                                        s.payload.to_bytes())))

    def publish():
        seq = 0
        while not stop.is_set():
            for rid, y in ((1, 5.0), (2, 0.0)):
                robots.put(keys.state(rid), StateMsg(rid, seq, time.time(), 0.0, y, 0.0, 0.0,
                                                     0.0, 0.0, 0.0, 0, StateFlags(0)).encode())
            seq += 1
            time.sleep(0.05)

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    try:
        yield endpoint, missions
    finally:
        stop.set()
        thread.join()
        sub.undeclare()
        for t in tokens:
            t.undeclare()
        robots.close()
        router.close()


@pytest.mark.parametrize("assign, offsets", [
    ("", [[10.0, 0.0], [10.0, 5.0]]),                           # listed: as the file says
    ('assign = "shortest"', [[10.0, 5.0], [10.0, 0.0]]),        # by where they stand
])
def test_mission_gives_the_places_by_the_reported_positions(tmp_path, swarm, capsys, assign,
                                                            offsets):
    endpoint, missions = swarm
    path = tmp_path / "two.toml"
    path.write_text(SCENARIO.format(assign=assign))
    assert main(["mission", "--scenario", str(path), "--swarm", "t", "--connect", endpoint,
                 "--start-in", "1", "--wait", "10"]) == EXIT_OK
    deadline = time.monotonic() + 5.0
    while not missions and time.monotonic() < deadline:
        time.sleep(0.02)
    assert missions and missions[0].ids.tolist() == [1, 2]
    assert missions[0].offsets.tolist() == offsets
    assert ("reported positions" in capsys.readouterr().out) == bool(assign)
