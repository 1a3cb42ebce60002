"""``boundswarm mission``: publish a scenario's mission (formation, shared epoch) to a swarm."""
from __future__ import annotations

import argparse
import time
from typing import TYPE_CHECKING

from rich.console import Console

from hil.cli.exit_codes import EXIT_OK
from hil.cli.options import Subparsers, add_zenoh_client_options, swarm_name, zenoh_client

if TYPE_CHECKING:
    import zenoh

    from agent.formation import Formation
    from hil.files.scenario import Scenario
    from transport.zenoh_link import Keys

REPEATS, REPEAT_PERIOD = 3, 0.2          # late subscribers get the mission too


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("mission", help="publish a scenario's mission to a swarm")
    p.add_argument("--scenario", required=True, help="scenario file (TOML)")
    p.add_argument("--swarm", required=True, type=swarm_name)
    add_zenoh_client_options(p, required=True)
    p.add_argument("--start-in", type=float, default=5.0, help="s until t = 0")
    p.add_argument("--wait", type=float, default=30.0,
                   help="s to wait for every robot's liveliness token")
    p.set_defaults(func=run)


def run(args: argparse.Namespace, console: Console) -> int:
    """Wait until every robot of the scenario is alive, then publish its mission; with
    ``[formation] assign = "shortest"``, its places go to the robots by where they report
    they stand (hil.files.assignment), not by the scenario's planned starts."""
    from common.payloads import MissionMsg
    from hil.files.scenario import load_scenario
    from hil.sitl.processes import wait_until
    from transport.zenoh_link import Keys, Presence, open_session
    sc = load_scenario(args.scenario)
    session = open_session(zenoh_client(args.config, args.connect), "the mission publisher")
    try:
        keys = Keys(args.swarm)
        presence = Presence(session, keys)
        ids = {int(i) for i in sc.ids}
        if not wait_until(lambda: presence.alive() >= ids, args.wait):
            missing = sorted(ids - presence.alive())
            raise RuntimeError(f"robots {missing} are not alive after {args.wait:g} s")
        formation = sc.formation
        if sc.assign == "shortest":
            formation = _assigned_where_they_stand(session, keys, sc, args.wait)
            console.print("places assigned by the robots' reported positions")
        epoch = time.time() + args.start_in
        msg = MissionMsg(1, time.time(), epoch, formation.center0, formation.velocity,
                         formation.omega, sc.ids, formation.offsets)
        for _ in range(REPEATS):
            session.put(keys.mission, msg.encode())
            time.sleep(REPEAT_PERIOD)
        console.print(f"mission of {sc.name} published to {args.swarm}: t = 0 in "
                      f"{args.start_in:g} s (epoch {epoch:.3f})")
        presence.close()
    finally:
        session.close()
    return EXIT_OK


def _assigned_where_they_stand(session: zenoh.Session, keys: Keys, sc: Scenario,
                               wait: float) -> Formation:
    """The scenario's formation, its places given to the robots by their latest states."""
    import numpy as np

    from common.payloads import StateMsg
    from hil.files.assignment import assigned
    from hil.sitl.processes import wait_until
    from transport.zenoh_link import Latest
    states = Latest(session, keys.state("*"), StateMsg.decode, time.time)
    try:
        ids = [int(i) for i in sc.ids]
        if not wait_until(lambda: set(states.snapshot()) >= set(ids), wait):
            missing = sorted(set(ids) - set(states.snapshot()))
            raise RuntimeError(f"no state from robots {missing} after {wait:g} s: cannot "
                               f"assign the places by where they stand")
        snap = states.snapshot()
        return assigned(sc.formation, np.array([[snap[i].msg.x, snap[i].msg.y] for i in ids]))
    finally:
        states.close()
