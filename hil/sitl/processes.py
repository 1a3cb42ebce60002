"""Child processes of the SITL launcher: started, watched and ended by PID, never by name.

Each child gets its own process group, its output goes to a log file in the run folder, and
:meth:`Children.terminate_all` ends every one of them: SIGINT first (the agents' clean
shutdown: zero velocity, IDLE, liveliness dropped), SIGTERM after a grace period, SIGKILL
as the last resort. Used as a context manager, nothing is left running even when the
launcher fails.
"""
from __future__ import annotations

import contextlib
import logging
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

log = logging.getLogger(__name__)


@dataclass
class Child:
    name: str
    proc: subprocess.Popen
    log_path: Path
    expected_exit: bool = False

    @property
    def pid(self) -> int:
        return self.proc.pid

    def tail(self, lines: int = 15) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""


@dataclass
class Children:
    log_dir: Path
    children: list[Child] = field(default_factory=list)

    def start(self, name: str, args: list[str], env: dict | None = None) -> Child:
        """Start ``python -m hil.cli ARGS`` (the same interpreter) as child ``name``."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        log_path = self.log_dir / f"{name}.log"
        out = open(log_path, "wb")
        try:
            proc = subprocess.Popen([sys.executable, "-m", "hil.cli", *args],
                                    stdout=out, stderr=subprocess.STDOUT,
                                    stdin=subprocess.DEVNULL, start_new_session=True,
                                    env={**os.environ, **(env or {})})
        finally:
            out.close()
        child = Child(name, proc, log_path)
        self.children.append(child)
        log.info("started %s (pid %d)", name, proc.pid)
        return child

    def failed(self) -> list[Child]:
        """Children that exited although nobody asked them to."""
        return [c for c in self.children if c.proc.poll() is not None and not c.expected_exit]

    def terminate(self, child: Child, grace: float = 3.0) -> int | None:
        """End one child: SIGINT, then SIGTERM, then SIGKILL, each after ``grace`` s."""
        child.expected_exit = True
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            if child.proc.poll() is not None:
                break
            try:
                os.killpg(child.proc.pid, sig)
            except ProcessLookupError:
                break
            try:
                child.proc.wait(timeout=grace)
            except subprocess.TimeoutExpired:
                log.warning("%s (pid %d) ignored %s", child.name, child.pid, sig.name)
        return child.proc.poll()

    def terminate_together(self, children: list[Child], grace: float = 3.0) -> None:
        """End ``children`` at once: SIGINT to every one, then SIGTERM to those still there
        after ``grace`` s, then SIGKILL (a swarm's agents stop within a period of each
        other, not one after another, each using the last state of those already gone)."""
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            running = [c for c in children if c.proc.poll() is None]
            for child in running:
                child.expected_exit = True
                try:
                    os.killpg(child.proc.pid, sig)
                except ProcessLookupError:
                    pass
            end = time.monotonic() + grace
            for child in running:
                try:
                    child.proc.wait(timeout=max(end - time.monotonic(), 0.0))
                except subprocess.TimeoutExpired:
                    log.warning("%s (pid %d) ignored %s", child.name, child.pid, sig.name)

    def terminate_all(self, grace: float = 3.0) -> None:
        """End every child, newest first (agents before the plant that serves them). An
        interrupt or error meanwhile (a second Ctrl-C) kills every child left at once,
        then goes on: no child outlives the launcher."""
        try:
            for child in reversed(self.children):
                self.terminate(child, grace)
        except BaseException:
            self.kill_all()
            raise

    def kill_all(self, wait: float = 5.0) -> None:
        """SIGKILL to every child still running, then reap them (``wait`` s at most)."""
        running = [c for c in self.children if c.proc.poll() is None]
        for child in running:
            child.expected_exit = True
            with contextlib.suppress(ProcessLookupError):
                os.killpg(child.proc.pid, signal.SIGKILL)
        end = time.monotonic() + wait
        for child in running:
            with contextlib.suppress(subprocess.TimeoutExpired):
                child.proc.wait(timeout=max(end - time.monotonic(), 0.0))

    def __enter__(self) -> "Children":
        return self

    def __exit__(self, *exc) -> None:
        """Every child still running ends together, newest first (an error or Ctrl-C while
        dozens start up must not wait a grace period for each); a second interrupt
        meanwhile kills them."""
        try:
            self.terminate_together(list(reversed(self.children)))
        except BaseException:
            self.kill_all()
            raise


def wait_until(predicate, timeout: float, poll: float = 0.05) -> bool:
    """Poll ``predicate`` until true or ``timeout`` seconds pass (monotonic clock)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(poll)
    return bool(predicate())
