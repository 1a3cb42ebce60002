"""Zenoh: sessions that stay on the configured endpoints, the key space, latest-value caches.

Key space (prefix ``boundswarm/<swarm>``)::

    robot/<id>/state       agent state every period (common.payloads.StateMsg)
    robot/<id>/beacon      the same state at a low rate (5 Hz), for robots far away
    robot/<id>             liveliness token while the agent runs
    robot/<id>/obstacles   obstacle detections for that robot (ObstaclesMsg)
    robot/<id>/truth       ground truth pose, SITL only (TruthMsg)
    robot/<id>/wheels      emulated drivers' wheel speeds, multi-host SITL only (WheelsMsg)
    robot/<id>/fix         pose fix from motion capture or the SITL's simulated one (FixMsg)
    mission                formation and epoch (MissionMsg)

Receiving never blocks the control loop: samples wait in bounded rings filled by zenoh's
own threads; the loop drains them without blocking and reads :meth:`Latest.snapshot`, a
mapping that is never mutated after it is returned. Malformed payloads are dropped and
counted.

Deliveries of full-rate states grow as N^2 * f. With ``near_radius`` set, an agent takes every
robot's beacon (N^2 * 5 Hz in all) and subscribes to the full-rate state key of only the robots
whose last known position is within ``near_radius`` of its own (:class:`NearStates`); a robot
that stops talking still shows as stale in the beacons, so nothing is lost for safety.
"""
from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections import Counter
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Callable, Generic, Iterable, Mapping, TypeVar

import zenoh

from common.payloads import (
    FixMsg,
    MissionMsg,
    ObstaclesMsg,
    PayloadError,
    Received,
    StateMsg,
)

log = logging.getLogger(__name__)

M = TypeVar("M")


CONNECT_TIMEOUT_MS = 10_000    # how long a client keeps trying to reach its router


def session_config(mode: str, listen: Iterable[str] = (), connect: Iterable[str] = (),
                   extra: Mapping[str, object] | None = None) -> zenoh.Config:
    """A Zenoh config with multicast scouting off and only the given endpoints.

    ``mode`` is ``router``, ``peer`` or ``client``; endpoints are locators such as
    ``tcp/127.0.0.1:7447``. ``extra`` inserts further JSON5 keys (e.g. TLS settings).
    """
    if mode not in ("router", "peer", "client"):
        raise ValueError(f"zenoh mode must be router, peer or client, got {mode!r}")
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if mode == "client":
        # a client (agent, plant) started with its router, or before it, retries instead of
        # failing on the first refused connection (zenoh's default for clients)
        conf.insert_json5("connect/timeout_ms", json.dumps(CONNECT_TIMEOUT_MS))
        conf.insert_json5("connect/retry", json.dumps(
            {"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2}))
    for key, value in (extra or {}).items():
        conf.insert_json5(key, json.dumps(value))
    return conf


def config_from_file(path: str) -> zenoh.Config:
    """A Zenoh config from a JSON5 file, with multicast scouting forced off."""
    try:
        conf = zenoh.Config.from_file(path)
    except (zenoh.ZError, OSError) as exc:
        raise ValueError(f"{path}: not a valid zenoh config: {exc}") from None
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


def open_session(conf: zenoh.Config, what: str) -> zenoh.Session:
    """Open a session, turning zenoh's error into one that says what could not be opened."""
    try:
        return zenoh.open(conf)
    except zenoh.ZError as exc:
        raise ConnectionError(f"cannot open the zenoh session for {what}: {exc}") from None


@dataclass(frozen=True)
class Keys:
    """The key expressions of one swarm."""

    swarm: str

    def __post_init__(self) -> None:
        if not self.swarm or any(c in self.swarm for c in "/*$?#"):
            raise ValueError(f"swarm name must be non-empty without / * $ ? #, "
                             f"got {self.swarm!r}")

    @property
    def prefix(self) -> str:
        return f"boundswarm/{self.swarm}"

    def robot(self, robot_id: int) -> str:
        return f"{self.prefix}/robot/{robot_id}"

    def state(self, robot_id: int | str) -> str:
        return f"{self.prefix}/robot/{robot_id}/state"

    def beacon(self, robot_id: int | str) -> str:
        return f"{self.prefix}/robot/{robot_id}/beacon"

    def obstacles(self, robot_id: int | str) -> str:
        return f"{self.prefix}/robot/{robot_id}/obstacles"

    def truth(self, robot_id: int | str) -> str:
        return f"{self.prefix}/robot/{robot_id}/truth"

    def wheels(self, robot_id: int | str) -> str:
        return f"{self.prefix}/robot/{robot_id}/wheels"

    def fix(self, robot_id: int | str) -> str:
        return f"{self.prefix}/robot/{robot_id}/fix"

    @property
    def mission(self) -> str:
        return f"{self.prefix}/mission"

    @property
    def all_robots(self) -> str:
        return f"{self.prefix}/robot/*"

    @staticmethod
    def robot_id_of(key: str) -> int | None:
        """The robot id in ``.../robot/<id>[/...]``, or None."""
        parts = str(key).split("/")
        try:
            return int(parts[parts.index("robot") + 1])
        except (ValueError, IndexError):
            return None


class Latest(Generic[M]):
    """Latest valid message per robot id on a key expression, with counters.

    Samples wait in a bounded ring (zenoh's RingChannel: the oldest is dropped when full,
    zenoh's threads never block and no Python callback competes with the loop for the GIL);
    :meth:`snapshot` drains it, decodes, and returns a mapping that is never mutated
    afterwards. ``decode(bytes) -> msg`` raises PayloadError for a payload to drop;
    ``ignore`` lists robot ids not to keep (the agent's own state). Counters: ``received``,
    ``accepted``, ``dropped`` by reason (PayloadError reasons, and ``out_of_order``: older
    than the held one).
    """

    def __init__(self, session: zenoh.Session, key: str, decode: Callable[[bytes], M],
                 clock: Callable[[], float], ignore: Iterable[int] = (), capacity: int = 256):
        self._decode, self._clock, self._ignore = decode, clock, frozenset(ignore)
        self._lock = threading.Lock()
        self._latest: Mapping[int, Received[M]] = MappingProxyType({})
        self.received = 0
        self.accepted = 0
        self.dropped: Counter = Counter()
        self._sub: zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]] | None = (
            session.declare_subscriber(key, zenoh.handlers.RingChannel(capacity)))  # None: closed

    def _drain(self) -> None:
        sub = self._sub
        if sub is None:                 # closed (the callers check first)
            return
        latest = None
        now = self._clock()
        while (sample := sub.try_recv()) is not None:
            self.received += 1
            try:
                msg = self._decode(sample.payload.to_bytes())
            except PayloadError as exc:
                self.dropped[exc.reason] += 1
                log.debug("dropped payload on %s: %s", sample.key_expr, exc)
                continue
            rid = getattr(msg, "robot_id", 0)
            if rid in self._ignore:
                continue
            if latest is None:
                latest = dict(self._latest)
            held = latest.get(rid)
            if held is not None and getattr(msg, "stamp", 0.0) < getattr(held.msg, "stamp", 0.0):
                self.dropped["out_of_order"] += 1
                continue
            self.accepted += 1
            ts = sample.timestamp            # the router's, when it timestamps (its default)
            latest[rid] = Received(msg, now,
                                   ts.get_time_as_ntp64().as_nanos() * 1e-9 if ts else None)
        if latest is not None:
            self._latest = MappingProxyType(latest)

    def snapshot(self) -> Mapping[int, Received[M]]:
        """The latest message of each robot id (after taking in what has arrived; after
        :meth:`close`, what was held then)."""
        with self._lock:
            if self._sub is not None:
                self._drain()
            return self._latest

    def counters(self) -> dict:
        with self._lock:
            if self._sub is not None:
                self._drain()
            return {"received": self.received, "accepted": self.accepted,
                    "dropped": dict(self.dropped)}

    def close(self) -> None:
        """Undeclare the subscription (safe while another thread takes a snapshot)."""
        with self._lock:
            sub, self._sub = self._sub, None
        if sub is not None:            # outside the lock: a snapshot never waits on Zenoh
            sub.undeclare()


class Arrivals(Generic[M]):
    """Every valid message on a key expression, per robot id in the order of their stamps,
    kept until taken: for a consumer that must not skip any (the multi-host world rolls a
    robot through each of its wheel reports). Samples wait in a bounded ring as in
    :class:`Latest`; one older than a robot's last accepted stamp is dropped
    (``out_of_order``). Single-threaded: drained by :meth:`take` only."""

    def __init__(self, session: zenoh.Session, key: str, decode: Callable[[bytes], M],
                 capacity: int = 1024):
        self._decode = decode
        self._pending: dict[int, list[M]] = {}
        self._stamp: dict[int, float] = {}
        self.received = 0
        self.dropped: Counter = Counter()
        self._sub: zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]] | None = (
            session.declare_subscriber(key, zenoh.handlers.RingChannel(capacity)))

    def take(self, robot_id: int) -> list[M]:
        """The messages of ``robot_id`` that arrived since the last take, oldest first."""
        sub = self._sub
        while sub is not None and (sample := sub.try_recv()) is not None:
            self.received += 1
            try:
                msg = self._decode(sample.payload.to_bytes())
            except PayloadError as exc:
                self.dropped[exc.reason] += 1
                continue
            rid, stamp = getattr(msg, "robot_id", 0), getattr(msg, "stamp", 0.0)
            if stamp <= self._stamp.get(rid, -math.inf):
                self.dropped["out_of_order"] += 1
                continue
            self._stamp[rid] = stamp
            self._pending.setdefault(rid, []).append(msg)
        return self._pending.pop(robot_id, [])

    def close(self) -> None:
        """Undeclare the subscription."""
        sub, self._sub = self._sub, None
        if sub is not None:
            sub.undeclare()


class Presence:
    """Which robots of the swarm hold a liveliness token (join and leave)."""

    def __init__(self, session: zenoh.Session, keys: Keys):
        self._lock = threading.Lock()
        self._alive: frozenset[int] = frozenset()
        self.left: Counter = Counter()
        self._sub = session.liveliness().declare_subscriber(keys.all_robots, self._on_sample,
                                                            history=True)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        rid = Keys.robot_id_of(str(sample.key_expr))
        if rid is None:
            return
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self._alive = self._alive | {rid}
            else:
                self._alive = self._alive - {rid}
                self.left[rid] += 1
                log.info("robot %d left the swarm (liveliness token dropped)", rid)

    def alive(self) -> frozenset[int]:
        return self._alive

    def close(self) -> None:
        self._sub.undeclare()


def newest(*maps: Mapping[int, Received[StateMsg]]) -> dict[int, Received[StateMsg]]:
    """Per robot id, the message with the latest stamp among ``maps``."""
    out: dict[int, Received[StateMsg]] = {}
    for m in maps:
        for rid, rec in m.items():
            held = out.get(rid)
            if held is None or rec.msg.stamp > held.msg.stamp:
                out[rid] = rec
    return out


def _add_counters(total: dict, c: dict) -> None:
    """Add one subscription's :meth:`Latest.counters` into ``total`` (dropped: a Counter)."""
    total["received"] += c["received"]
    total["accepted"] += c["accepted"]
    total["dropped"].update(c["dropped"])


class NearStates:
    """Neighbour states for a large swarm: all beacons, full-rate states of the robots near.

    A thread of its own revises the subscriptions every ``period`` [s] around the position
    and velocity last given to :meth:`focus` (metres, world frame; m/s): it subscribes to the
    state key of each robot that is, or may be, within ``radius`` by the time its full-rate
    states flow, and drops the subscription of robots beyond ``radius + hysteresis``. "May
    be": its last known distance less how far the two robots can close in on each other (the
    norm of their velocities' difference, as reported) over that data's age plus ``lead``
    [s] (a refocus period, a beacon period and the subscription's set-up), so that a robot
    closing in fast is followed at full rate before it is within ``radius``, not on 5 Hz
    beacons, while robots moving together in formation are not. Declaring and undeclaring
    take Zenoh's locks, which its (normally scheduled) threads may hold, so the real-time
    loop never does it. :meth:`snapshot` is like :meth:`Latest.snapshot`: per robot, the
    newer of its beacon and its state, a mapping never mutated afterwards.
    """

    def __init__(self, session: zenoh.Session, keys: Keys, robot_id: int,
                 clock: Callable[[], float], radius: float, hysteresis: float = 2.0,
                 period: float = 0.1, lead: float = 0.4,
                 thread_setup: Callable[[], object] | None = None):
        """``thread_setup`` runs first in the refocus thread (e.g. the loop's real-time
        scheduling, so that a thread taking the interpreter lock is never starved while the
        loop waits for it)."""
        self._session, self._keys, self._clock = session, keys, clock
        self.radius, self.hysteresis, self.lead = radius, hysteresis, lead
        self.beacons = Latest(session, keys.beacon("*"), StateMsg.decode, clock,
                              ignore=[robot_id])
        # replaced whole (never mutated) by the refocus thread, read by the loop
        self.near: Mapping[int, Latest[StateMsg]] = MappingProxyType({})
        # dropped subscriptions' counters: counts, and a Counter of "dropped" by reason
        self._closed: dict[str, Any] = {"received": 0, "accepted": 0, "dropped": Counter()}
        self._counter_lock = threading.Lock()
        self._snapshot: Mapping[int, Received[StateMsg]] = MappingProxyType({})
        self._focus: tuple[float, float, float, float] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._refocus_loop, args=(period, thread_setup),
                                        name=f"near-refocus-{robot_id}", daemon=True)
        self._thread.start()

    def focus(self, x: float, y: float, vx: float = 0.0, vy: float = 0.0) -> None:
        """Own position [m] and velocity [m/s] to revise the near set around (cheap, never
        blocks)."""
        self._focus = (x, y, vx, vy)

    def snapshot(self) -> Mapping[int, Received[StateMsg]]:
        near = self.near
        self._snapshot = MappingProxyType(newest(
            self.beacons.snapshot(), *(sub.snapshot() for sub in near.values())))
        return self._snapshot

    def _refocus_loop(self, period: float, setup: Callable[[], object] | None) -> None:
        if setup is not None:
            setup()
        while not self._stop.wait(period):
            if self._focus is None:
                continue
            try:
                self.refocus(*self._focus)
            except zenoh.ZError:                # e.g. the session closing: try again later
                log.exception("near set not revised")

    def refocus(self, x: float, y: float, vx: float = 0.0, vy: float = 0.0) -> None:
        """Subscribe to the robots now near (x, y) [m] for a robot moving at (vx, vy) [m/s],
        drop those gone far."""
        near = dict(self.near)
        new, gone = [], []
        now = self._clock()
        try:
            for rid, rec in self._snapshot.items():
                m = rec.msg
                relative = math.hypot(m.v * math.cos(m.theta) - vx,
                                      m.v * math.sin(m.theta) - vy)
                closing = relative * (max(now - m.stamp, 0.0) + self.lead)
                d = ((m.x - x) ** 2 + (m.y - y) ** 2) ** 0.5 - closing
                if rid not in near and d <= self.radius:
                    near[rid] = Latest(self._session, self._keys.state(rid), StateMsg.decode,
                                       self._clock, capacity=8)
                    new.append(near[rid])
                elif rid in near and d > self.radius + self.hysteresis:
                    gone.append(near.pop(rid))
        except BaseException:
            for sub in new:                     # never published: undeclare them here
                sub.close()
            raise
        if self._stop.is_set():                 # closing meanwhile: it owns self.near
            for sub in new:
                sub.close()
            return
        with self._counter_lock:                # counters() sees each sub once
            self.near = MappingProxyType(near)
            for sub in gone:
                _add_counters(self._closed, sub.counters())
        for sub in gone:
            sub.close()

    def counters(self) -> dict:
        """Full-rate state counters (as :meth:`Latest.counters`), closed subscriptions included."""
        with self._counter_lock:
            total = {**self._closed, "dropped": Counter(self._closed["dropped"])}
            near = self.near
        for sub in near.values():
            _add_counters(total, sub.counters())
        return {**total, "dropped": dict(total["dropped"])}

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        for sub in (self.beacons, *self.near.values()):
            sub.close()
        self.near = MappingProxyType({})


class SwarmLink:
    """One agent's Zenoh link (common.ports.SwarmPort): its state out (and a beacon every
    ``BEACON_PERIOD``); neighbours, its obstacles and the mission in; a liveliness token
    while it runs. ``near_radius`` [m] > 0 takes full-rate states only from robots within
    it (:class:`NearStates`; ``thread_setup`` runs first in its refocus thread); 0 takes every
    robot's."""

    BEACON_PERIOD = 0.2        # s

    def __init__(self, session: zenoh.Session, keys: Keys, robot_id: int,
                 clock: Callable[[], float], near_radius: float = 0.0,
                 thread_setup: Callable[[], object] | None = None):
        self.keys, self.robot_id = keys, robot_id
        self._pub = session.declare_publisher(keys.state(robot_id))
        self._beacon = session.declare_publisher(keys.beacon(robot_id))
        self._beacon_due = 0.0
        self.published = 0             # states put (beacons apart)
        self._token = session.liveliness().declare_token(keys.robot(robot_id))
        self.states: Latest[StateMsg] | NearStates = (
            NearStates(session, keys, robot_id, clock, near_radius,
                       thread_setup=thread_setup) if near_radius > 0 else
            Latest(session, keys.state("*"), StateMsg.decode, clock, ignore=[robot_id]))
        self._obstacles = Latest(session, keys.obstacles(robot_id), ObstaclesMsg.decode, clock)
        self._mission = Latest(session, keys.mission, MissionMsg.decode, clock)

    def publish(self, state: StateMsg) -> None:
        payload = state.encode()
        self._pub.put(payload)
        self.published += 1
        # schedules only: a step of the wall clock must not stall them
        now = time.monotonic()
        if now >= self._beacon_due:
            self._beacon.put(payload)
            self._beacon_due = now + self.BEACON_PERIOD
        if isinstance(self.states, NearStates):
            self.states.focus(state.x, state.y, state.v * math.cos(state.theta),
                              state.v * math.sin(state.theta))

    def neighbours(self) -> Mapping[int, Received[StateMsg]]:
        return self.states.snapshot()

    def obstacles(self) -> ObstaclesMsg | None:
        got = self._obstacles.snapshot().get(self.robot_id)
        return got.msg if got else None

    def mission(self) -> MissionMsg | None:
        got = self._mission.snapshot().get(0)
        return got.msg if got else None

    def counters(self) -> dict:
        out: dict[str, object] = {"published": self.published,
                                  "states": self.states.counters(),
                                  "obstacles": self._obstacles.counters(),
                                  "mission": self._mission.counters()}
        if isinstance(self.states, NearStates):
            out["beacons"] = self.states.beacons.counters()
            out["near"] = sorted(self.states.near)
        return out

    def close(self) -> None:
        """Drop the liveliness token (the swarm sees this robot leave) and the subscribers."""
        self._token.undeclare()
        for sub in (self.states, self._obstacles, self._mission):
            sub.close()
        self._pub.undeclare()
        self._beacon.undeclare()


class FixLink:
    """The pose fixes of one robot (common.ports.FixPort): the newest by capture stamp."""

    def __init__(self, session: zenoh.Session, keys: Keys, robot_id: int,
                 clock: Callable[[], float]):
        self.robot_id = robot_id
        self._fixes = Latest(session, keys.fix(robot_id), FixMsg.decode, clock, capacity=64)

    def fix(self) -> FixMsg | None:
        got = self._fixes.snapshot().get(self.robot_id)
        return got.msg if got else None

    def counters(self) -> dict:
        return self._fixes.counters()

    def close(self) -> None:
        self._fixes.close()
