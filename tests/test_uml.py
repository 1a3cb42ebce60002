"""The User-Mode Linux guest used for the real socketcan (vcan) path."""
from pathlib import Path

import pytest
from tooling import uml

ROOT = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.skipif(uml.usable() is not None,
                                reason=f"UML unusable: {uml.usable()}")


def test_vcan_in_uml_carries_python_can_frames():
    script = """
ip -br link show vcan0
.venv/bin/python - <<'PY'
import can
with can.Bus(interface="socketcan", channel="vcan0") as a, \\
        can.Bus(interface="socketcan", channel="vcan0") as b:
    a.send(can.Message(arbitration_id=0x02D, data=bytes.fromhex("000020C00000803E"),
                       is_extended_id=False))
    msg = b.recv(2.0)
    print("RX", hex(msg.arbitration_id), msg.data.hex())
PY
"""
    r = uml.run_script(script, cwd=ROOT, timeout=90)
    assert r.returncode == 0, r.output + r.console[-2000:]
    assert "vcan0" in r.output and "RX 0x2d 000020c00000803e" in r.output


def test_script_failure_is_reported():
    r = uml.run_script("echo failing; exit 7", cwd=ROOT, timeout=90)
    assert r.returncode == 7 and "failing" in r.output
