"""The launcher's child processes: ended by PID, together when asked."""
import signal
import subprocess
import sys
import time

from hil.processes import Child, Children

STUBBORN = ("import signal, sys, time; signal.signal(signal.SIGINT, signal.SIG_IGN); "
            "print('ready', flush=True); time.sleep(60)")


def test_children_ended_together_wait_one_grace_period_not_one_each(tmp_path):
    children = Children(tmp_path)
    for k in range(3):              # each ignores SIGINT: only SIGTERM, after the grace, ends it
        proc = subprocess.Popen([sys.executable, "-c", STUBBORN], stdout=subprocess.PIPE,
                                start_new_session=True, text=True)
        children.children.append(Child(f"stubborn_{k}", proc, tmp_path / f"{k}.log"))
    try:
        for child in children.children:
            assert child.proc.stdout.readline().strip() == "ready"
        started = time.monotonic()
        children.terminate_together(children.children, grace=1.0)
        elapsed = time.monotonic() - started
        assert [c.proc.returncode for c in children.children] == [-signal.SIGTERM] * 3
        assert elapsed < 2.5, elapsed              # one after another: 3 s and more
        assert not children.failed()               # asked to end: not failures
    finally:
        for child in children.children:
            if child.proc.poll() is None:
                child.proc.kill()
            child.proc.wait()
            child.proc.stdout.close()


def test_an_interrupt_while_ending_the_children_kills_every_one_left(tmp_path, monkeypatch):
    """A second Ctrl-C (or any error) while the launcher ends its children one by one: the
    ones not yet ended get SIGKILL at once, and the interrupt goes on."""
    children = Children(tmp_path)
    for k in range(3):
        proc = subprocess.Popen([sys.executable, "-c", STUBBORN], stdout=subprocess.PIPE,
                                start_new_session=True, text=True)
        children.children.append(Child(f"stubborn_{k}", proc, tmp_path / f"{k}.log"))
    ended = []

    def interrupted(child, grace=3.0):
        if ended:
            raise KeyboardInterrupt
        ended.append(child.name)
        child.expected_exit = True
        child.proc.terminate()
        child.proc.wait()

    monkeypatch.setattr(children, "terminate", interrupted)
    try:
        for child in children.children:
            assert child.proc.stdout.readline().strip() == "ready"
        try:
            children.terminate_all()
            raise AssertionError("the interrupt was swallowed")
        except KeyboardInterrupt:
            pass
        assert ended == ["stubborn_2"]                              # newest first
        assert [c.proc.poll() for c in children.children] == [-signal.SIGKILL,
                                                              -signal.SIGKILL,
                                                              -signal.SIGTERM]
        assert not children.failed()
    finally:
        for child in children.children:
            if child.proc.poll() is None:
                child.proc.kill()
            child.proc.wait()
            child.proc.stdout.close()
