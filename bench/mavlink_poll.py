"""Cost of one MAVLink poll with full telemetry to a ground station (prints a table).

    .venv/bin/python bench/mavlink_poll.py [--polls 1000] [--repeats 5]

The link of one robot in FORMATION mode, polled on simulated time every control period
(0.02 s), sends its telemetry over loopback UDP to a pymavlink ground station that drains
it. Reported per repeat and as the median over repeats: mean, median and p99 wall time of a
poll, and the p99 as a share of the control period.
"""
from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from typing import Any

import numpy as np
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mav2

from agent.config import ControlParams
from agent.node import AgentMode
from transport.mavlink_io import open_transport
from transport.mavlink_link import MavlinkLink, MavlinkSettings, VehicleState

PERIOD = 0.02                    # s, the control period the link is polled at
ROBOT, GCS_SYS, GCS_COMP = 7, 255, 190


class MovingVehicle:
    """A vehicle in formation that accepts every command (the link's VehicleControl)."""

    def __init__(self) -> None:
        self.control = ControlParams()

    def state(self) -> VehicleState:
        return VehicleState(AgentMode.FORMATION, None, 3.0, 4.0, 0.3, 1.0, 0.5)

    def arm(self) -> str | None:
        return None

    def disarm(self) -> str | None:
        return None

    def set_mode(self, mode: AgentMode) -> str | None:
        return None

    def param(self, name: str) -> float:
        return float(getattr(self.control, name))

    def set_param(self, name: str, value: float) -> str | None:
        changes: dict[str, Any] = {name: float(value)}
        self.control = dataclasses.replace(self.control, **changes)
        return None


def free_udp_port() -> int:
    import socket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def poll_costs(polls: int) -> np.ndarray:
    """Wall time [us] of ``polls`` polls of a link whose ground station drains every frame."""
    port = free_udp_port()
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=GCS_SYS,
                                     source_component=GCS_COMP)
    gcs.mav = mav2.MAVLink(gcs, srcSystem=GCS_SYS, srcComponent=GCS_COMP)
    settings = MavlinkSettings(url=f"udpout:127.0.0.1:{port}")
    link = MavlinkLink(open_transport(settings.url), MovingVehicle(), ROBOT, settings,
                       wall=time.time)
    try:
        now, costs = 100.0, []
        for _ in range(polls):
            t0 = time.perf_counter_ns()
            link.poll(now)
            costs.append(time.perf_counter_ns() - t0)
            now += PERIOD
            while gcs.recv_match(blocking=False) is not None:
                pass
        return np.asarray(costs, dtype=float) / 1e3
    finally:
        link.close()
        gcs.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--polls", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    rows = []
    print(f"{'repeat':>6} {'mean [us]':>10} {'median [us]':>12} {'p99 [us]':>9} "
          f"{'p99 / period':>13}")
    for k in range(args.repeats):
        c = poll_costs(args.polls)
        row = (float(c.mean()), float(np.median(c)), float(np.percentile(c, 99)))
        rows.append(row)
        print(f"{k + 1:>6} {row[0]:10.1f} {row[1]:12.1f} {row[2]:9.1f} "
              f"{row[2] * 1e-6 / PERIOD:13.2%}")
    med = [statistics.median(r[i] for r in rows) for i in range(3)]
    print(f"{'median':>6} {med[0]:10.1f} {med[1]:12.1f} {med[2]:9.1f} "
          f"{med[2] * 1e-6 / PERIOD:13.2%}")


if __name__ == "__main__":
    main()
