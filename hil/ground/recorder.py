"""Record a swarm's Zenoh traffic into an MCAP file (JSON messages, JSON schemas).

Every valid state, truth, obstacles and mission payload of a swarm becomes one MCAP message
on a topic named after its key (``/boundswarm/<swarm>/robot/3/state``), JSON-encoded with a
JSON schema so Foxglove Studio and the mcap tools read it directly; log time is the arrival
time (the sample's Zenoh timestamp, set by the router, else when the recorder took it),
publish time the payload's own stamp. Malformed payloads are counted, not recorded.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import operator
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import zenoh
from mcap.reader import make_reader
from mcap.writer import Writer

from common.payloads import FixMsg, MissionMsg, ObstaclesMsg, PayloadError, StateMsg, TruthMsg
from transport.zenoh_link import Keys

log = logging.getLogger(__name__)

MESSAGES = {"state": StateMsg, "truth": TruthMsg, "obstacles": ObstaclesMsg,
            "mission": MissionMsg, "fix": FixMsg}


def _kind(key: str) -> str:
    return key.rsplit("/", 1)[-1]


def _plain(value):
    """JSON for what the decoders put in messages besides numbers and tuples: arrays."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serializable")


_ENCODER = json.JSONEncoder(default=_plain)


def _any_json(cls) -> Callable[[bytes], tuple[bytes, float]]:
    """Payload -> (JSON object of the decoded message's fields, stamp); PayloadError if bad."""
    def encode(payload: bytes) -> tuple[bytes, float]:
        msg = cls.decode(payload)
        return _ENCODER.encode(vars(msg)).encode(), msg.stamp
    return encode


def _numbers_json(cls) -> Callable[[bytes], tuple[bytes, float]]:
    """_any_json, faster, for a message of numbers only: a template writes its fields, %r a
    float as json does (decode refuses non-finite ones), %d an int or an IntFlag as a plain
    int."""
    fields = dataclasses.fields(cls)
    template = ("{" + ", ".join(f'"{f.name}": %{"r" if f.type in ("float", float) else "d"}'
                                for f in fields) + "}").encode()
    values = operator.attrgetter(*(f.name for f in fields))

    def encode(payload: bytes) -> tuple[bytes, float]:
        msg = cls.decode(payload)
        return template % values(msg), msg.stamp
    return encode


ENCODERS: dict[str, Callable[[bytes], tuple[bytes, float]]] = {
    "state": _numbers_json(StateMsg), "truth": _numbers_json(TruthMsg),
    "obstacles": _any_json(ObstaclesMsg), "mission": _any_json(MissionMsg),
    "fix": _numbers_json(FixMsg)}


def _schema(kind: str) -> bytes:
    props: dict[str, dict[str, object]] = {f.name: {} for f in dataclasses.fields(MESSAGES[kind])}
    return json.dumps({"title": f"boundswarm.{kind}", "type": "object",
                       "properties": props}).encode()


class Recorder:
    """Writes every valid state, truth, obstacles and mission payload of a swarm into ``path``
    until :meth:`close`.

    Samples wait in Zenoh FIFO channels (``capacity`` each: when one is full, Zenoh blocks
    rather than drops, which stalls the session's routing, so the thread never stops
    emptying them: a message it cannot write is counted in ``dropped["write_error"]``) and a
    recorder thread writes them every ``interval`` seconds.
    """

    def __init__(self, session: zenoh.Session, keys: Keys, path: Path,
                 clock: Callable[[], float] = time.time, interval: float = 0.03,
                 capacity: int = 1 << 14):
        self.path, self._clock, self._interval = path, clock, interval
        self._file = open(path, "wb")
        self._writer = Writer(self._file)
        self._writer.start(profile="", library="boundswarm")
        self._lock = threading.Lock()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.recorded = 0
        self.recorded_per_key: Counter = Counter()    # key -> messages written
        self.dropped: Counter = Counter()
        self._closed = False
        self._stop = threading.Event()
        subscribe = {"state": keys.state("*"), "truth": keys.truth("*"),
                     "obstacles": keys.obstacles("*"), "mission": keys.mission,
                     "fix": keys.fix("*")}
        self._subs = [session.declare_subscriber(key, zenoh.handlers.FifoChannel(capacity))
                      for key in subscribe.values()]
        self._handlers = [(kind, sub.handler) for kind, sub in zip(subscribe, self._subs)]
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()

    def _channel(self, key: str, kind: str) -> int:
        if kind not in self._schemas:
            self._schemas[kind] = self._writer.register_schema(
                name=f"boundswarm.{kind}", encoding="jsonschema", data=_schema(kind))
        self._channels[key] = self._writer.register_channel(
            topic="/" + key, message_encoding="json", schema_id=self._schemas[kind])
        return self._channels[key]

    def _run(self) -> None:
        while not self._stop.wait(self._interval):
            self._drain()

    def _drain(self) -> None:
        """Write every sample waiting in the channels."""
        now = int(self._clock() * 1e9)
        channels, add = self._channels, self._writer.add_message
        for kind, handler in self._handlers:
            encode = ENCODERS[kind]
            try:
                while (sample := handler.try_recv()) is not None:
                    try:
                        data, stamp = encode(sample.payload.to_bytes())
                    except PayloadError as exc:
                        self.dropped[exc.reason] += 1
                        continue
                    key = str(sample.key_expr)
                    ts = sample.timestamp
                    try:
                        channel = channels.get(key)
                        if channel is None:
                            channel = self._channel(key, kind)
                        add(channel, log_time=ts.get_time_as_ntp64().as_nanos() if ts else now,
                            data=data, publish_time=int(stamp * 1e9))
                    except (OSError, ValueError) as exc:   # e.g. disk full: keep emptying the
                        if not self.dropped["write_error"]:     # channels, or Zenoh would block
                            log.error("recorder: writing %s failed: %s", self.path, exc)
                        self.dropped["write_error"] += 1
                        continue
                    self.recorded += 1
                    self.recorded_per_key[key] += 1
            except zenoh.ZError:           # empty and closed: the subscriber is undeclared
                pass

    def settle(self, quiet: float = 0.5, timeout: float = 10.0) -> None:
        """Wait until nothing has been written for ``quiet`` s (what was in flight when the
        publishers ended has arrived), at most ``timeout`` s."""
        end = time.monotonic() + timeout
        seen, since = -1, time.monotonic()
        while time.monotonic() < end:
            if self.recorded != seen:
                seen, since = self.recorded, time.monotonic()
            elif time.monotonic() - since >= quiet:
                return
            time.sleep(self._interval)

    def close(self) -> None:
        """Stop receiving, write what was received and finish the file."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        for sub in self._subs:     # while the thread still drains: Zenoh may wait on a full one
            sub.undeclare()
        self._stop.set()
        self._thread.join()
        self._drain()
        self._writer.finish()
        self._file.close()


def read_messages(path: Path) -> Iterator[tuple[str, str, float, dict]]:
    """(topic, kind, log time [s], message dict) of every message, in log-time order."""
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            yield (channel.topic, _kind(channel.topic), message.log_time / 1e9,
                   json.loads(message.data))
