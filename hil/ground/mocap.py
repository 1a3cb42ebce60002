"""The motion-capture bridge (``boundswarm mocap --config FILE``) on the ground station.

It reads a motion-capture system through ``motioncapture`` (libmotioncapture's Python
package, the ``mocap`` extra: VRPN, Vicon, Qualisys, OptiTrack, NOKOV, Motion Analysis,
FZMotion, and a ``mock`` system for tests) and, for every frame, publishes the fix of each
rigid body it maps to a robot on ``boundswarm/<swarm>/robot/<id>/fix`` (common.payloads.
FixMsg): x, y and the heading (yaw of the body's quaternion) in the motion-capture frame,
which must be the swarm's world frame (z up), stamped with the frame's capture time (its
arrival here less the configured ``latency``; the clocks of the ground station and the
robots are assumed in sync: chrony or PTP) and the configured error bound.

A mapped body missing from the frames (occluded, out of the volume, or misnamed), or with a
non-finite pose, gets no fix: its robot's agent holds once its last fix is older than its
``[pose] fix_timeout``. The bridge says so here too: a WARNING when a body has not been
seen for ``MISSING_WARNING`` s, and when it is back.

Config file (TOML, docs/formats.md)::

    swarm = "field"
    system = "vicon"                 # one of SYSTEMS
    hostname = "192.0.2.20"          # the motion-capture server (not for mock)
    options = ["port=801"]           # further connect options of the system, key=value
    error = 0.005                    # m, position error bound each fix states
    latency = 0.0                    # s, from the capture to its arrival here
    [zenoh]                          # transport.settings.ZenohSettings (the ground client)
    config = "ground-client.json5"   # relative to this file
    [[bodies]]
    name = "robot-1"                 # rigid body name in the motion-capture system
    robot = 1
"""
from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.payloads import FixMsg
from common.schema import ConfigError, from_table, load_toml, section, setting, tables, validate
from transport.settings import ZenohSettings

log = logging.getLogger(__name__)

SYSTEMS = ("vicon", "optitrack", "optitrack_closed_source", "qualisys", "nokov", "vrpn",
           "motionanalysis", "fzmotion", "mock")
MISSING_WARNING = 0.5    # s without a mapped body in the frames before a warning


@dataclass(frozen=True)
class Body:
    """A rigid body of the motion-capture system that is a robot."""

    name: str = setting(doc="rigid body name in the motion-capture system")
    robot: int = setting(doc="the robot's id", lo=1, hi=255)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class MocapSettings:
    """The bridge's config file."""

    swarm: str = setting(doc="swarm name: Zenoh key prefix boundswarm/<swarm>")
    system: str = setting(doc="motion-capture system (motioncapture's type)", choices=SYSTEMS)
    hostname: str | None = setting(None, doc="address of the motion-capture server")
    options: tuple[str, ...] = setting((), doc="further connect options of the system, "
                                       "key=value (mock: rigid_bodies, frequency)")
    error: float = setting(0.005, unit="m", doc="position error bound each fix states",
                           lo=0.0, open_lo=True)
    latency: float = setting(0.0, unit="s", doc="from the capture to its arrival here, "
                             "subtracted from the arrival time", lo=0.0, hi=1.0)
    zenoh: ZenohSettings = section(ZenohSettings, "the bridge's Zenoh session")
    bodies: tuple[Body, ...] = tables(doc="rigid bodies that are robots ([[bodies]] name, "
                                      "robot)")

    def __post_init__(self) -> None:
        validate(self)
        if any(ch in self.swarm for ch in "/*$?#"):
            raise ConfigError(f"MocapSettings.swarm: must not contain / * $ ? #, "
                              f"got {self.swarm!r}")
        if not self.bodies:
            raise ConfigError("MocapSettings.bodies: at least one [[bodies]] is required")
        for what in ("name", "robot"):
            values = [getattr(b, what) for b in self.bodies]
            dup = sorted({v for v in values if values.count(v) > 1}, key=str)
            if dup:
                raise ConfigError(f"MocapSettings.bodies: {what} given twice: {dup}")
        bad = [o for o in self.options if "=" not in o or o.startswith("=")]
        if bad:
            raise ConfigError(f"MocapSettings.options: expected key=value, got {bad}")
        if self.hostname is None and self.system != "mock":
            raise ConfigError(f"MocapSettings.hostname: missing (the {self.system} server)")

    def connect_options(self) -> dict[str, str]:
        """The options of ``motioncapture.connect``: hostname and ``options``."""
        out = dict(o.split("=", 1) for o in self.options)
        if self.hostname is not None:
            out["hostname"] = self.hostname
        return out


def load_mocap_settings(path: str | Path) -> MocapSettings:
    """Read a bridge config; a relative ``[zenoh] config`` is taken from the file's folder."""
    path = Path(path)
    s = from_table(MocapSettings, load_toml(path, "mocap config"), str(path))
    if s.zenoh.config is not None:
        zpath = path.parent / s.zenoh.config
        if not zpath.is_file():
            raise ConfigError(f"{path}: [zenoh] config: no such file {zpath}")
        s = dataclasses.replace(s, zenoh=dataclasses.replace(s.zenoh, config=str(zpath)))
    return s


def yaw(w: float, x: float, y: float, z: float) -> float:
    """Heading [rad] about z of the rotation quaternion (w, x, y, z)."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class Bridge:
    """Fixes from frames: ``publish(robot_id, payload)`` for each mapped body seen."""

    def __init__(self, settings: MocapSettings, publish: Callable[[int, bytes], None]):
        self.s, self.publish = settings, publish
        self.frames = 0
        self.published: Counter = Counter()      # robot id -> fixes
        self.missing: Counter = Counter()        # body name -> frames without it
        self._seen: dict[str, float] = {}        # body name -> last arrival [s]
        self._warned: set[str] = set()
        self._start: float | None = None

    def frame(self, bodies: Mapping[str, Any], arrived: float) -> None:
        """Publish the fix of every mapped body of a frame that arrived at ``arrived``
        (UNIX [s]); ``bodies`` maps names to objects with ``position`` (x, y, z [m]) and
        ``rotation`` (a quaternion with w, x, y, z)."""
        self.frames += 1
        if self._start is None:
            self._start = arrived
        stamp = arrived - self.s.latency
        for b in self.s.bodies:
            body = bodies.get(b.name)
            pose = None
            if body is not None:
                p, q = body.position, body.rotation
                pose = (float(p[0]), float(p[1]), yaw(q.w, q.x, q.y, q.z))
            if pose is None or not all(map(math.isfinite, pose)):
                self.missing[b.name] += 1
                since = self._seen.get(b.name, self._start)
                if arrived - since >= MISSING_WARNING and b.name not in self._warned:
                    self._warned.add(b.name)
                    log.warning("rigid body %r (robot %d) not seen for %.1f s: its agent "
                                "gets no fix and holds", b.name, b.robot, arrived - since)
                continue
            if b.name in self._warned:
                self._warned.discard(b.name)
                log.warning("rigid body %r (robot %d) seen again", b.name, b.robot)
            self._seen[b.name] = arrived
            self.published[b.robot] += 1
            self.publish(b.robot, FixMsg(b.robot, self.frames, stamp, *pose,
                                         self.s.error).encode())

    def counters(self) -> dict:
        return {"frames": self.frames, "published": dict(self.published),
                "missing": dict(self.missing)}


def run_bridge(settings: MocapSettings, stop: threading.Event,
               max_frames: int | None = None, clock: Callable[[], float] = time.time) -> dict:
    """Bridge frames to Zenoh until ``stop`` is set (or ``max_frames``); returns the
    counters. The frames are read in a thread of their own (``waitForNextFrame`` blocks
    while the system sends nothing), so a signal always ends the bridge."""
    try:
        import motioncapture
    except ImportError:
        raise RuntimeError("the Python package motioncapture is not installed: install "
                           "boundswarm with its mocap extra, pip install "
                           "'boundswarm[mocap]'") from None
    from transport.zenoh_link import Keys, config_from_file, open_session, session_config
    try:
        mc = motioncapture.connect(settings.system, settings.connect_options())
    except RuntimeError as exc:
        raise ConnectionError(f"cannot connect to the {settings.system} motion-capture "
                              f"system at {settings.hostname}: {exc}") from None
    z = settings.zenoh
    conf = (config_from_file(z.config) if z.config else
            session_config(z.mode, z.listen, z.connect))
    session = open_session(conf, "the motion-capture bridge")
    failure: list[BaseException] = []
    try:
        keys = Keys(settings.swarm)
        pubs = {b.robot: session.declare_publisher(keys.fix(b.robot)) for b in settings.bodies}
        bridge = Bridge(settings, lambda rid, data: pubs[rid].put(data))

        def read() -> None:
            try:
                while not stop.is_set():
                    mc.waitForNextFrame()
                    if stop.is_set():
                        break
                    bridge.frame(mc.rigidBodies, clock())
                    if max_frames is not None and bridge.frames >= max_frames:
                        break
            except BaseException as exc:     # reported by the main thread
                failure.append(exc)
            finally:
                stop.set()

        reader = threading.Thread(target=read, name="mocap-frames", daemon=True)
        reader.start()
        log.info("bridging %s to boundswarm/%s: %s", settings.system, settings.swarm,
                 ", ".join(f"{b.name} -> robot {b.robot}" for b in settings.bodies))
        while not stop.wait(0.2):
            pass
        reader.join(timeout=1.0)      # may still wait for a frame that never comes
        if failure:
            raise RuntimeError(f"reading the motion-capture system failed: "
                               f"{failure[0]}") from failure[0]
        return bridge.counters()
    finally:
        session.close()
