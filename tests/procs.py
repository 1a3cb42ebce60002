"""Process helpers shared by the tests that start swarms."""
import os


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie child of this process does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:
        done, _ = os.waitpid(pid, os.WNOHANG)
        return done == 0
    except ChildProcessError:              # not our child: it exists, so it runs
        return True
