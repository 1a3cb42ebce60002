"""The launcher's child processes: ended by PID, together when asked."""
import signal
import subprocess
import sys
import time

import pytest

from hil.sitl.processes import Child, Children

STUBBORN = ("import signal, sys, time; signal.signal(signal.SIGINT, signal.SIG_IGN); "
            "print('ready', flush=True); time.sleep(60)")


@pytest.fixture
def stubborn(tmp_path):
    """Three children that ignore SIGINT (only SIGTERM or SIGKILL ends them), ready."""
    children = Children(tmp_path)
    for k in range(3):
        proc = subprocess.Popen([sys.executable, "-c", STUBBORN], stdout=subprocess.PIPE,
                                start_new_session=True, text=True)
        children.children.append(Child(f"stubborn_{k}", proc, tmp_path / f"{k}.log"))
    try:
        for child in children.children:
            assert child.proc.stdout is not None
            assert child.proc.stdout.readline().strip() == "ready"
        yield children
    finally:
        for child in children.children:
            if child.proc.poll() is None:
                child.proc.kill()
            child.proc.wait()
            if child.proc.stdout is not None:
                child.proc.stdout.close()


def test_children_ended_together_wait_one_grace_period_not_one_each(stubborn):
    started = time.monotonic()
    stubborn.terminate_together(stubborn.children, grace=1.0)
    elapsed = time.monotonic() - started
    assert [c.proc.returncode for c in stubborn.children] == [-signal.SIGTERM] * 3
    assert elapsed < 2.5, elapsed              # one after another: 3 s and more
    assert not stubborn.failed()               # asked to end: not failures


def test_an_interrupt_while_ending_the_children_kills_every_one_left(stubborn, monkeypatch):
    """A second Ctrl-C (or any error) while the launcher ends its children one by one: the
    ones not yet ended get SIGKILL at once, and the interrupt goes on."""
    ended: list[str] = []

    def interrupted(child, grace=3.0):
        if ended:
            raise KeyboardInterrupt
        ended.append(child.name)
        child.expected_exit = True
        child.proc.terminate()
        child.proc.wait()

    monkeypatch.setattr(stubborn, "terminate", interrupted)
    with pytest.raises(KeyboardInterrupt):
        stubborn.terminate_all()
    assert ended == ["stubborn_2"]                              # newest first
    assert [c.proc.poll() for c in stubborn.children] == [-signal.SIGKILL, -signal.SIGKILL,
                                                          -signal.SIGTERM]
    assert not stubborn.failed()


def test_leaving_the_block_ends_the_children_together(stubborn):
    """An error (or Ctrl-C) out of ``with Children``: every child gets SIGINT at once, then
    SIGTERM one grace period later, not a grace period each."""
    started = time.monotonic()
    with pytest.raises(RuntimeError), stubborn:
        raise RuntimeError("start-up failed")
    elapsed = time.monotonic() - started
    assert [c.proc.returncode for c in stubborn.children] == [-signal.SIGTERM] * 3
    assert elapsed < 6.0, elapsed              # one after another: 9 s and more
