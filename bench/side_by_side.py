"""Run one benchmark script from this checkout and from another commit, alternately.

    .venv/bin/python bench/side_by_side.py REV [--rounds 2] -- bench/batch_scaling.py --sizes 1000

The machine is shared and its speed drifts over minutes, so figures of two commits are only
comparable when measured in the same run, interleaved: this checks REV out into a temporary
git worktree, then runs ``SCRIPT ARGS`` from each checkout in turn (each importing its own
code: PYTHONPATH is the checkout; a script the other commit lacks is taken from this one),
``--rounds`` times, printing each output under a header. ``--this-script`` runs this
checkout's script on both (a benchmark improved since REV, on REV's code: it must use only
what both commits have).
The worktree is removed at the end, also on failure or Ctrl-C.
"""
from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Iterator

ROOT = Path(__file__).resolve().parent.parent


def run_in(checkout: Path, script: list[str], this_script: bool = False) -> str:
    """Run ``script`` with ``checkout``'s code; a script the checkout does not have (a
    benchmark newer than it), or any with ``this_script``, is taken from this one."""
    if this_script or not (checkout / script[0]).exists():
        script = [str(ROOT / script[0]), *script[1:]]
    env = dict(os.environ, PYTHONPATH=str(checkout))
    done = subprocess.run([sys.executable, *script], cwd=checkout, env=env,
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(script)} failed in {checkout} "
                         f"(exit {done.returncode}):\n{done.stderr}")
    return done.stdout


def short(rev: str) -> str:
    """The short hash of ``rev``."""
    return subprocess.run(["git", "rev-parse", "--short", rev], cwd=ROOT, check=True,
                          capture_output=True, text=True).stdout.strip()


@contextlib.contextmanager
def worktree(rev: str) -> Iterator[Path]:
    """A temporary detached git worktree of ``rev``, removed at the end (also on failure)."""
    with tempfile.TemporaryDirectory() as tmp:
        other = Path(tmp) / "other"
        subprocess.run(["git", "worktree", "add", "--detach", str(other), rev], cwd=ROOT,
                       check=True, capture_output=True)
        try:
            yield other
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(other)], cwd=ROOT,
                           check=False, capture_output=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rev", help="the other commit (hash, tag, branch)")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--this-script", action="store_true",
                    help="run this checkout's benchmark script on both commits")
    argv = sys.argv[1:]
    if "--" not in argv or argv.index("--") == len(argv) - 1:
        ap.error("give the benchmark after --, e.g. -- bench/batch_scaling.py")
    cut = argv.index("--")
    args, script = ap.parse_args(argv[:cut]), argv[cut + 1:]
    label = short(args.rev)
    with worktree(args.rev) as other:
        for r in range(args.rounds):
            for name, checkout in ((label, other), ("this checkout", ROOT)):
                print(f"=== round {r + 1}, {name}: {' '.join(script)}", flush=True)
                print(run_in(checkout, script, args.this_script), flush=True)


if __name__ == "__main__":
    main()
