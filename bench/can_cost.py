"""CPU cost of one robot's CAN traffic at both ends, per second of operation (prints a table).

    .venv/bin/python bench/can_cost.py [--seconds 20] [--rounds 5]

One robot's steady flow over python-can's ``udp_multicast`` on this machine, as in the SITL:
the host side (transport.wheel_drivers, as the agent drives it at 50 Hz: drain the feedback,
send both wheel velocities) and the emulated drivers (firmware_sim.odrive_sim, served at
200 Hz as the SITL plant does: take the commands, send encoder estimates at 100 Hz and
heartbeats at 10 Hz per axis). Both ends run in this process on simulated time (no sleep),
each timed apart with the thread's CPU clock, so the figures are CPU seconds per second of
robot operation (% of one core), not wall time. ``--rounds`` repeats and prints the median.
Uses only public APIs that older commits have, so it runs under bench/side_by_side.py.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path.cwd()))

from firmware_sim.odrive_sim import DriverPair  # noqa: E402
from transport.canbus import DEFAULT_GROUP, open_bus  # noqa: E402
from transport.wheel_drivers import WheelDrivers  # noqa: E402

STEP = 0.005          # s, the plant's step
TICKS_PER_STEP = 4    # the agent's 20 ms period


def one_round(seconds: float, port: int) -> tuple[float, float, int]:
    """(host side, drivers) CPU seconds per second of operation, and frames the host used."""
    host_bus = open_bus("udp_multicast", DEFAULT_GROUP, port=port)
    driver_bus = open_bus("udp_multicast", DEFAULT_GROUP, port=port)
    sim = [0.0]
    host = WheelDrivers(host_bus, clock=lambda: sim[0])
    drivers = DriverPair(driver_bus)
    drivers.configure(vel_limit=10.0, ramp=20.0)
    cpu = time.thread_time
    host_cpu = drivers_cpu = 0.0
    used = 0
    try:
        host.arm()
        for k in range(int(seconds / STEP)):
            sim[0] = now = k * STEP
            t0 = cpu()
            drivers.service(now)
            drivers.step(STEP)
            t1 = cpu()
            drivers_cpu += t1 - t0
            if k % TICKS_PER_STEP == 0:
                time.sleep(0)               # let the datagrams land (loopback is synchronous)
                t0 = cpu()
                fb = host.feedback()
                used += fb is not None
                host.command(1.0 + 0.5 * (k % 40 < 20), 1.0)
                host_cpu += cpu() - t0
    finally:
        host_bus.shutdown()
        driver_bus.shutdown()
    return host_cpu / seconds, drivers_cpu / seconds, used


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per round")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--port", type=int, default=47321, help="udp_multicast port to use")
    args = ap.parse_args()
    hosts, drivers = [], []
    for _ in range(args.rounds):
        h, d, used = one_round(args.seconds, args.port)
        if used == 0:
            sys.exit("the host side never got feedback: the bus carried nothing")
        hosts.append(h)
        drivers.append(d)
    print(f"{'side':>14} {'median':>8} {'min':>8} {'max':>8}   (% of one core, per robot)")
    for name, v in (("host (agent)", hosts), ("drivers", drivers)):
        print(f"{name:>14} {100 * statistics.median(v):7.2f}% {100 * min(v):7.2f}% "
              f"{100 * max(v):7.2f}%")


if __name__ == "__main__":
    main()
