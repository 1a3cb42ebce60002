"""Run a shell script inside User-Mode Linux, where the kernel has SocketCAN (vcan) and netem.

This machine's kernel has no CAN support; Debian's ``user-mode-linux`` package ships a
kernel that runs as an ordinary process and has vcan, can-raw and sch_netem as modules.
The guest sees the host's root read-only (hostfs), so the project's venv runs inside
unchanged (the host's /tmp too, so a checkout there works), and one host folder read-write
(``$UML_WORK``, the same path inside, also ``TMPDIR``) for outputs. The guest has
no network interface but loopback: nothing it does leaves the machine.

Used by the tests of the socketcan path and by ``bench/``; needs the Debian packages
``user-mode-linux`` and ``kmod`` (and ``can-utils`` for candump).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

UML_KERNEL = "linux"
MODULES = ("net/can/can.ko", "net/can/can-raw.ko", "drivers/net/can/dev/can-dev.ko",
           "drivers/net/can/vcan.ko", "net/sched/sch_netem.ko")
DONE = "UML-SCRIPT-EXIT"

INIT = """#!/bin/sh
mount -t proc proc /proc
mount -t sysfs sys /sys
mount -t tmpfs tmpfs /run
mount -t hostfs -o {work} none {work}
export PATH=/usr/sbin:/usr/bin:/sbin:/bin HOME={work} TMPDIR={work} PYTHONDONTWRITEBYTECODE=1
M=/usr/lib/uml/modules/$(uname -r)/kernel
for m in {modules}; do insmod $M/$m || echo "uml: insmod $m failed"; done
ip link set up lo
{vcans}
cd {cwd}
sh {work}/script.sh > {work}/output.txt 2>&1
echo "{done} $?"
poweroff -f
"""


class UmlUnavailable(RuntimeError):
    """User-Mode Linux (or kmod) is not installed here."""


@dataclass(frozen=True)
class UmlResult:
    returncode: int     # of the script inside the guest
    output: str         # its stdout and stderr
    console: str        # the guest kernel's console


def available() -> str | None:
    """None when UML can run here, else the reason it cannot."""
    if shutil.which(UML_KERNEL) is None:
        return "the 'linux' UML kernel is missing (apt-get install user-mode-linux)"
    if shutil.which("insmod") is None:
        return "insmod is missing (apt-get install kmod)"
    return None


def run_script(script: str, vcans: int = 1, timeout: float = 120.0, mem_mb: int = 512,
               cwd: str | os.PathLike = "/") -> UmlResult:
    """Boot UML, bring up vcan0..vcan{n-1}, run ``script`` with sh, power off.

    The script runs as root in ``cwd`` (read-only) and may write to ``$UML_WORK``.
    """
    reason = available()
    if reason:
        raise UmlUnavailable(reason)
    with tempfile.TemporaryDirectory(prefix="boundswarm-uml-") as tmp:
        work = Path(tmp)
        (work / "script.sh").write_text(f"UML_WORK={work}\nexport UML_WORK\n{script}\n")
        ups = "\n".join(f"ip link add dev vcan{i} type vcan && ip link set up vcan{i}"
                        for i in range(vcans))
        init = work / "init.sh"
        init.write_text(INIT.format(work=work, modules=" ".join(MODULES), vcans=ups,
                                    cwd=cwd, done=DONE))
        init.chmod(0o755)
        cmd = [UML_KERNEL, f"mem={mem_mb}M", "root=/dev/root", "rootfstype=hostfs",
               "rootflags=/", "ro", f"init={init}", "con=null", "con0=null,fd:1"]
        try:
            proc = subprocess.run(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, timeout=timeout, cwd=tmp)
        except subprocess.TimeoutExpired as exc:
            raise TimeoutError(f"UML guest did not finish within {timeout:g} s") from exc
        console = proc.stdout.decode(errors="replace")
        output = (work / "output.txt").read_text(errors="replace") \
            if (work / "output.txt").exists() else ""
        code = next((int(line.split()[-1]) for line in console.splitlines()
                     if line.startswith(DONE)), -1)
        return UmlResult(code, output, console)
