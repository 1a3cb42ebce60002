"""Record a swarm's Zenoh traffic into an MCAP file (JSON messages, JSON schemas).

Every valid payload under ``boundswarm/<swarm>/**`` becomes one MCAP message on a topic
named after its key (``/boundswarm/<swarm>/robot/3/state``), JSON-encoded with a JSON schema
so Foxglove Studio and the mcap tools read it directly; log time is the arrival time,
publish time the payload's own stamp. Malformed payloads are counted, not recorded.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import zenoh
from mcap.reader import make_reader
from mcap.writer import Writer

from transport.payloads import (MissionMsg, ObstaclesMsg, PayloadError, StateMsg, TruthMsg)
from transport.zenoh_link import Keys

log = logging.getLogger(__name__)

DECODERS: dict[str, Callable] = {"state": StateMsg.decode, "truth": TruthMsg.decode,
                                 "obstacles": ObstaclesMsg.decode, "mission": MissionMsg.decode}


def _kind(key: str) -> str:
    return key.rsplit("/", 1)[-1]


def _jsonable(msg) -> dict:
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
    return out


def _schema(kind: str) -> bytes:
    cls = {"state": StateMsg, "truth": TruthMsg, "obstacles": ObstaclesMsg,
           "mission": MissionMsg}[kind]
    props = {f.name: {} for f in dataclasses.fields(cls)}
    return json.dumps({"title": f"boundswarm.{kind}", "type": "object",
                       "properties": props}).encode()


class Recorder:
    """Writes everything valid under ``keys.prefix`` into ``path`` until :meth:`close`."""

    def __init__(self, session: zenoh.Session, keys: Keys, path: Path,
                 clock: Callable[[], float] = time.time):
        self.path, self._clock = path, clock
        self._file = open(path, "wb")
        self._writer = Writer(self._file)
        self._writer.start(profile="", library="boundswarm")
        self._lock = threading.Lock()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.recorded = 0
        self.dropped: Counter = Counter()
        self._closed = False
        self._sub = session.declare_subscriber(f"{keys.prefix}/**", self._on_sample)

    def _channel(self, topic: str, kind: str) -> int:
        if kind not in self._schemas:
            self._schemas[kind] = self._writer.register_schema(
                name=f"boundswarm.{kind}", encoding="jsonschema", data=_schema(kind))
        if topic not in self._channels:
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="json", schema_id=self._schemas[kind])
        return self._channels[topic]

    def _on_sample(self, sample: zenoh.Sample) -> None:
        now = self._clock()
        key = str(sample.key_expr)
        kind = _kind(key)
        decode = DECODERS.get(kind)
        if decode is None:
            return
        try:
            msg = decode(sample.payload.to_bytes())
        except PayloadError as exc:
            with self._lock:
                self.dropped[exc.reason] += 1
            return
        data = json.dumps(_jsonable(msg)).encode()
        with self._lock:
            if self._closed:
                return
            channel = self._channel("/" + key, kind)
            self._writer.add_message(channel, log_time=int(now * 1e9), data=data,
                                     publish_time=int(msg.stamp * 1e9))
            self.recorded += 1

    def close(self) -> None:
        self._sub.undeclare()
        with self._lock:
            if not self._closed:
                self._closed = True
                self._writer.finish()
                self._file.close()


def read_messages(path: Path) -> Iterator[tuple[str, str, float, dict]]:
    """(topic, kind, log time [s], message dict) of every message, in log-time order."""
    with open(path, "rb") as f:
        for _schema_, channel, message in make_reader(f).iter_messages(log_time_order=True):
            yield (channel.topic, _kind(channel.topic), message.log_time / 1e9,
                   json.loads(message.data))
