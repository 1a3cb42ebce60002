"""CAN link benchmark: host side <-> emulated drivers (prints a table).

    .venv/bin/python bench/can_link.py [--seconds 3]

Measured over python-can's udp_multicast (drivers in a child process, this machine) and
over a real vcan0 inside User-Mode Linux (socketcan): the round trip of a remote request
for bus voltage and current (request -> answer, served by the drivers' 1 kHz loop) p50/p99,
how many such round trips per second
one host sustains, and the command-to-feedback latency (a new wheel velocity is sent; time
until an encoder estimate reports it, so it includes the 10 ms estimate period). Also the
bus load of one robot at 50 Hz on a 500 kbit/s bus from exact frame bit lengths.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from tooling import uml  # noqa: E402


def measure(interface: str, channel: str, port: int | None, seconds: float) -> dict:
    """Run inside the process that owns the host side; drivers must already be serving."""
    import numpy as np

    from transport.canbus import open_bus
    from transport.odrive_frames import Cmd, decode, request
    from transport.wheel_drivers import WheelDrivers

    bus = open_bus(interface, channel, port=port)
    try:
        host = WheelDrivers(bus)
        end = time.monotonic() + 20
        while host.feedback() is None and time.monotonic() < end:
            time.sleep(0.01)
        host.arm()
        rtt = []
        t_end = time.monotonic() + seconds
        want = 1 << 5 | Cmd.GET_BUS_VOLTAGE_CURRENT     # answered only on request
        while time.monotonic() < t_end:
            host.command(1.0, 1.0)                      # keep the watchdog fed
            t0 = time.perf_counter()
            host.poll()                                 # nothing stale in the queue
            bus.send(request(1, Cmd.GET_BUS_VOLTAGE_CURRENT))
            while True:
                msg = bus.recv(0.5)
                if msg is None:
                    break
                if msg.arbitration_id == want and not msg.is_remote_frame:
                    rtt.append(time.perf_counter() - t0)
                    decode(msg)
                    break
        lat = []
        for k in range(40):
            target = 2.0 + (k % 2)
            host.command(target, target)
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < 0.2:
                fb = host.feedback()
                if fb is not None and abs(fb.vel_rev_s[0] - target) < 1e-3:
                    lat.append(time.perf_counter() - t0)
                    break
                time.sleep(0.0002)
            time.sleep(0.02)
        a, b = np.array(rtt) * 1e3, np.array(lat) * 1e3
        return {"rtt_p50_ms": float(np.percentile(a, 50)),
                "rtt_p99_ms": float(np.percentile(a, 99)),
                "round_trips_per_s": len(rtt) / seconds,
                "cmd_to_feedback_p50_ms": float(np.percentile(b, 50)),
                "cmd_to_feedback_p99_ms": float(np.percentile(b, 99))}
    finally:
        bus.shutdown()


def with_drivers(interface: str, channel: str, port: int | None, seconds: float) -> dict:
    args = [sys.executable, "-m", "hil.cli", "plant", "--drivers-only", "--rate", "1000",
            "--can-interface", interface, "--can-channel", channel]
    args += ["--can-port", str(port)] if port else []
    child = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    try:
        return measure(interface, channel, port, seconds)
    finally:
        child.terminate()
        child.wait(timeout=10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--inner", help=argparse.SUPPRESS)     # interface,channel inside UML
    args = parser.parse_args()
    if args.inner:
        interface, channel = args.inner.split(",")
        print("RESULT " + json.dumps(with_drivers(interface, channel, None, args.seconds)))
        return
    rows = {"udp_multicast (this kernel)": with_drivers("udp_multicast", "ff11::b5:7", 43777,
                                                          args.seconds)}
    if uml.usable() is None:
        r = uml.run_script(f".venv/bin/python bench/can_link.py --inner socketcan,vcan0 "
                           f"--seconds {args.seconds}", cwd=ROOT, timeout=300)
        line = next((x for x in r.output.splitlines() if x.startswith("RESULT ")), None)
        if line:
            rows["socketcan vcan0 (UML guest)"] = json.loads(line[7:])
        else:
            print("UML run failed:", r.output[-800:])
    print(f"{'link':<30} {'RTR rtt p50':>11} {'p99':>7} {'round trips/s':>14} "
          f"{'cmd->fb p50':>11} {'p99':>7}  [ms]")
    for name, v in rows.items():
        print(f"{name:<30} {v['rtt_p50_ms']:>11.3f} {v['rtt_p99_ms']:>7.3f} "
              f"{v['round_trips_per_s']:>14.0f} {v['cmd_to_feedback_p50_ms']:>11.2f} "
              f"{v['cmd_to_feedback_p99_ms']:>7.2f}")

    from transport.busload import bus_load, frame_bits
    from transport.odrive_frames import Cmd, encode
    per_s = {"Set_Input_Vel (2 x 50 Hz)": [encode(n, Cmd.SET_INPUT_VEL, Input_Vel=3.1,
                                                  Input_Torque_FF=0.0) for n in (0, 1)] * 50,
             "Get_Encoder_Estimates (2 x 100 Hz)": [
                 encode(n, Cmd.GET_ENCODER_ESTIMATES, Pos_Estimate=12.3, Vel_Estimate=3.1)
                 for n in (0, 1)] * 100,
             "Heartbeat (2 x 10 Hz)": [encode(n, Cmd.HEARTBEAT, Axis_Error=0, Axis_State=8,
                                              Procedure_Result=0, Trajectory_Done_Flag=0)
                                       for n in (0, 1)] * 10}
    total = sum(bus_load(f, 1.0) for f in per_s.values())
    print(f"\nbus load of one robot at 50 Hz on 500 kbit/s: {total:.1%}")
    for name, frames in per_s.items():
        print(f"  {name:<36} {len(frames):>4} frames/s, {frame_bits(frames[0]):>3} bits each, "
              f"{bus_load(frames, 1.0):.1%}")


if __name__ == "__main__":
    main()
