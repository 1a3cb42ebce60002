"""How the SITL launcher hosts a swarm's data path: the Zenoh router in a process of its own.

The router is the one hop every neighbour state takes. Hosted in the launcher, it shared a
process (and the interpreter lock, and normal scheduling) with the MCAP recorder and the
status views, and ran under the agents' real-time loops: on a loaded machine a state then
waited there for hundreds of milliseconds. Here the router is ``boundswarm router`` started
as a child with its own runtime threads and SCHED_FIFO priority; the launcher is one more
client of it (recorder, status, mission), like any ground station.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import zenoh

from agent.loop import use_normal_scheduling, use_realtime
from common.schema import setting, validate
from hil.sitl.processes import Child, Children
from transport.zenoh_link import open_session, session_config


def zenoh_runtime(threads: int) -> str:
    """A ZENOH_RUNTIME (zenoh-runtime's syntax) that runs every runtime of a process on
    ``threads`` worker threads: a process of a SITL swarm spends less CPU handing each
    message between threads than with Zenoh's five or six runtimes."""
    return (f"(rx: (worker_threads: {threads}), app: (handover: rx), tx: (handover: rx), "
            "acc: (handover: rx), net: (handover: rx))")


@dataclass(frozen=True)
class LaunchSettings:
    """The SITL launcher's data path and the bound its summary checks."""

    router_priority: int = setting(9, doc="SCHED_FIFO priority of the Zenoh router process "
                                   "and of the launcher's Zenoh threads (0: normal "
                                   "scheduling); 9: with the agents' Zenoh threads, under "
                                   "their loops (10)", lo=0, hi=99)
    router_threads: int = setting(2, doc="Zenoh runtime worker threads of the router",
                                  lo=1, hi=16)
    tick_groups: int = setting(0, doc="the agents tick in this many groups at phases spread "
                               "over the period (the k-th robot at (k mod groups) / groups of "
                               "it); 1: all at phase 0, as robots with synchronised clocks "
                               "do, their states one burst a period (the least CPU in all); "
                               "more: each group's ticks end sooner on a machine that runs "
                               "every agent, at one burst and wake-up more a period; 0 "
                               "(auto): 4 where agents share processes, else 1", lo=0, hi=8)
    agents_per_process: int = setting(0, doc="agents one process runs, each in turn every "
                                      "period, on one Zenoh session (robots the world kills "
                                      "keep a process of their own); 1: one process per "
                                      "robot, as on robots; more: less CPU on a machine "
                                      "with fewer cores than robots; 0 (auto): 1 up to 8 "
                                      "robots per core, beyond that about 2 processes per "
                                      "core", lo=0, hi=64)
    age_bound: float = setting(0.05, unit="s", doc="the summary warns when an agent's "
                               "neighbour-state age p99 exceeds this", lo=0.0, open_lo=True,
                               hi=10.0)

    def __post_init__(self) -> None:
        validate(self)


SHARE_ABOVE = 8     # robots per core beyond which the agents share processes (auto)
SHARED_GROUPS = 4   # tick groups of shared processes (auto)


def shared_per_process(robots: int, cores: int, groups: int) -> int:
    """Agents per process for about two processes per core (at least four), each tick
    group's robots split evenly between its processes."""
    per_group = math.ceil(max(4, 2 * cores) / groups)     # processes of a tick group
    return math.ceil(math.ceil(robots / groups) / per_group)


def agent_layout(robots: int, cores: int, launch: LaunchSettings) -> tuple[int, int]:
    """(tick groups, agents per process) for ``robots`` agents on ``cores``: each as
    ``launch`` sets it, or where 0 (auto): one process per robot at one phase up to
    SHARE_ABOVE robots per core; beyond (a process per robot would saturate the machine:
    docs/performance.md, "Agents sharing a process"), or where agents share processes
    anyway, SHARED_GROUPS tick groups and :func:`shared_per_process`."""
    given = launch.agents_per_process
    shared = given > 1 or (given == 0 and robots > SHARE_ABOVE * cores)
    groups = launch.tick_groups or (SHARED_GROUPS if shared else 1)
    per = given or (shared_per_process(robots, cores, groups) if shared else 1)
    return groups, per


def router_config(endpoint: str) -> dict:
    """The router's Zenoh config (JSON, which is JSON5): only ``endpoint``, scouting off."""
    return {"mode": "router", "listen": {"endpoints": [endpoint]},
            "connect": {"endpoints": []}, "scouting": {"multicast": {"enabled": False}}}


def start_router(children: Children, endpoint: str, config_dir: Path,
                 launch: LaunchSettings) -> Child:
    """Write ``config_dir/router.json5`` and start ``boundswarm router`` on it as child
    ``router``, with its own runtime threads and scheduling."""
    path = config_dir / "router.json5"
    path.write_text(json.dumps(router_config(endpoint), indent=2) + "\n")
    args = ["router", "--config", str(path)]
    if launch.router_priority:
        args += ["--realtime-priority", str(launch.router_priority)]
    return children.start("router", args,
                          env={"ZENOH_RUNTIME": zenoh_runtime(launch.router_threads)})


def open_launcher_session(endpoint: str, launch: LaunchSettings) -> zenoh.Session:
    """The launcher's client session to the router at ``endpoint``: Zenoh's threads, started
    with it, inherit SCHED_FIFO at ``launch.router_priority`` (when granted); the calling
    thread goes back to normal scheduling."""
    realtime = launch.router_priority > 0 and use_realtime(launch.router_priority)
    try:
        return open_session(session_config("client", connect=[endpoint]), "the SITL launcher")
    finally:
        if realtime:
            use_normal_scheduling()
