"""Running a campaign on Dask: a local cluster or an existing one, resumable, with progress.

A campaign folder holds (docs/campaigns.md)::

    DIR/spec.toml         the spec (its robot profiles in DIR/profiles/): the folder alone
                          resumes the campaign and replays any of its runs
    DIR/runs.jsonl        one row per finished run, appended (flushed and fsynced) as each
                          run finishes: what an interrupted campaign resumes from
    DIR/timings.jsonl     wall seconds, host and process of each run executed
    DIR/sessions.jsonl    one line per invocation: workers, start-up, runs, runs per minute
    DIR/runs.parquet      the spec's rows sorted by run key, when every run has finished:
                          the same bytes whatever the number or placement of the workers

Runs are submitted in the spec's order with a bounded number in flight; a run's exception
is its row (``status = "failed"``), a run lost with its worker is retried on the next
invocation. Rows are cached by run key: a rerun executes only the runs without a row.
"""
from __future__ import annotations

import contextlib
import datetime
import fcntl
import hashlib
import importlib.util
import itertools
import json
import logging
import os
import re
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

from rich.console import Console

from hil.campaign.spec import CampaignSpec, Run, write_copy
from hil.cli.exit_codes import BadInput
from hil.sitl.host_cpu import machine_cores

RUNS, TIMINGS, SESSIONS, PARQUET, LOCK = ("runs.jsonl", "timings.jsonl", "sessions.jsonl",
                                          "runs.parquet", ".lock")
CONNECT_TIMEOUT = 10.0          # s, to reach an existing scheduler
SCHEDULER = re.compile(r"^(tcp|tls)://\[?[\w.:-]+\]?:\d+$")
# what the results depend on besides a run's description (recorded per session)
CODE = ("agent", "firmware_sim", "hil/files/scenario.py", "hil/campaign/families.py",
        "hil/campaign/run.py")

log = logging.getLogger(__name__)


class CampaignError(RuntimeError):
    """The campaign could not run (not the spec's fault): e.g. no scheduler to reach."""


@dataclass
class Outcome:
    """What an invocation did, and the spec's rows (sorted by run key)."""

    rows: list[dict[str, Any]]
    total: int                      # runs in the spec
    executed: int = 0               # runs executed by this invocation
    failed: int = 0                 # rows with status "failed" among ``rows``
    lost: list[str] = field(default_factory=list)   # "key: error" of runs not finished
    workers: int = 0
    startup_seconds: float = 0.0    # cluster start (or connection) and warm-up
    run_seconds: float = 0.0        # first submission to last result

    @property
    def complete(self) -> bool:
        return len(self.rows) == self.total

    @property
    def runs_per_minute(self) -> float:
        return 60.0 * self.executed / self.run_seconds if self.run_seconds > 0 else 0.0


def check_scheduler(address: str) -> str:
    """``--scheduler``: tcp://HOST:PORT (or tls://)."""
    if not SCHEDULER.match(address):
        raise BadInput(f"--scheduler: expected tcp://HOST:PORT, got {address!r}")
    return address


def code_digest(root: Path | None = None) -> str:
    """A short hash of the sources the results depend on (recorded per session)."""
    root = root or Path(__file__).resolve().parents[2]
    digest = hashlib.sha256()
    for name in CODE:
        path = root / name
        files = sorted(path.rglob("*.py")) if path.is_dir() else [path]
        for f in files:
            if f.exists():
                digest.update(f.relative_to(root).as_posix().encode() + f.read_bytes())
    return digest.hexdigest()[:12]


# --- the folder -------------------------------------------------------------------------
def read_rows(folder: Path, repair: bool = False) -> dict[str, dict[str, Any]]:
    """The rows of ``folder/runs.jsonl`` by key, without a torn last line (a campaign killed
    while writing it); ``repair``: cut that line off the file (before appending to it)."""
    path = folder / RUNS
    if not path.exists():
        return {}
    data = path.read_bytes()
    end = data.rfind(b"\n") + 1
    if repair and end < len(data):
        with path.open("r+b") as f:
            f.truncate(end)
    rows = {}
    for line in data[:end].splitlines():
        try:
            row = json.loads(line)
        except ValueError:
            continue
        if isinstance(row, dict) and isinstance(row.get("key"), str):
            rows[row["key"]] = row
    return rows


class _Appender:
    """A JSON-lines file that each line reaches durably (flush and fsync)."""

    def __init__(self, path: Path, sync: bool = True):
        self._f = path.open("a", encoding="utf-8")
        self._sync = sync

    def write(self, obj: Any) -> None:
        self._f.write(json.dumps(obj) + "\n")
        self._f.flush()
        if self._sync:
            os.fsync(self._f.fileno())

    def close(self) -> None:
        self._f.close()


@contextlib.contextmanager
def _locked(folder: Path) -> Iterator[None]:
    with (folder / LOCK).open("w") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise BadInput(f"{folder}: another campaign is running in this folder") from None
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@contextlib.contextmanager
def _handlers(handler: Callable[[int, Any], None], *signums: int) -> Iterator[None]:
    """``handler`` for ``signums`` during the block (nothing outside the main thread)."""
    try:
        previous = {s: signal.signal(s, handler) for s in signums}
    except ValueError:                       # not the main thread
        yield
        return
    try:
        yield
    finally:
        for s, old in previous.items():
            signal.signal(s, old)


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """Ctrl-C and SIGTERM take effect when the block is done (main thread only)."""
    got: list[int] = []
    with _handlers(lambda signum, frame: got.append(signum), signal.SIGINT, signal.SIGTERM):
        yield
    if got:
        raise KeyboardInterrupt


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def _sigterm_interrupts() -> contextlib.AbstractContextManager[None]:
    """SIGTERM stops the campaign as Ctrl-C does (the cluster is closed on the way out)."""
    return _handlers(_interrupt, signal.SIGTERM)


# --- Dask -------------------------------------------------------------------------------
@contextlib.contextmanager
def dask_client(workers: int | None, scheduler: str | None) -> Iterator[Any]:
    """A Client of the cluster at ``scheduler``, else of a LocalCluster of ``workers``
    processes of one thread each, on 127.0.0.1, without dashboards; closed on exit."""
    from distributed import Client, LocalCluster
    if logging.getLogger().getEffectiveLevel() > logging.INFO:
        logging.getLogger("distributed").setLevel(logging.WARNING)
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise CampaignError(f"cannot reach the Dask scheduler at {scheduler}: "
                                f"{' '.join(str(exc).split())}") from None
        try:
            yield client
        finally:
            client.close()
        return
    cluster = LocalCluster(
        n_workers=workers or machine_cores(), threads_per_worker=1, processes=True,
        host="127.0.0.1", dashboard_address=None, worker_dashboard_address=None,
        scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
        env={"NUMBA_NUM_THREADS": "1"}, silence_logs=logging.ERROR)
    try:
        client = Client(cluster, set_as_default=False)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


def _execute(client: Any, runs: list[Run], in_flight: int,
             on_row: Callable[[dict[str, Any], dict[str, Any]], None]) -> list[str]:
    """Submit ``runs`` in order, at most ``in_flight`` at a time; ``on_row`` gets each
    finished run's row and timing. Returns "key: error" of the runs lost (their worker
    died, the scheduler went away)."""
    from distributed import as_completed

    from hil.campaign.run import run_timed
    pending = iter(runs)
    inflight: dict[Any, str] = {}          # future -> run key

    def submit(run: Run) -> Any:
        fut = client.submit(run_timed, run.description, key=f"boundswarm-run-{run.key}",
                            retries=0)
        inflight[fut] = run.key
        return fut

    done = as_completed([submit(r) for r in itertools.islice(pending, in_flight)],
                        loop=client.loop)
    lost = []
    try:
        for fut in done:
            key = inflight.pop(fut)
            try:
                row, timing = fut.result()
            except Exception as exc:
                lost.append(f"{key}: {type(exc).__name__}: {' '.join(str(exc).split())}")
            else:
                on_row(row, timing)
            fut.release()
            nxt = next(pending, None)
            if nxt is not None:
                done.add(submit(nxt))
    finally:
        if inflight:
            client.cancel(list(inflight))
    return lost


def _warm_up(client: Any) -> float:
    """Load the compiled kernels on every worker at once; the slowest worker's seconds. A
    worker lost meanwhile (restarted by its nanny, starved so long it missed its
    heartbeats) is left out: the runs load the kernels themselves, and Dask gives a lost
    worker's runs to the others."""
    from hil.campaign.run import warm_up
    took = client.run(warm_up, on_error="return")
    return max((t for t in took.values() if isinstance(t, float)), default=0.0)


# --- a campaign -------------------------------------------------------------------------
def run_campaign(spec: CampaignSpec, folder: Path, console: Console,
                 workers: int | None = None, scheduler: str | None = None,
                 retry_failed: bool = False, in_flight: int | None = None) -> Outcome:
    """Run the spec's runs that have no row in ``folder`` yet; return the outcome."""
    folder.mkdir(parents=True, exist_ok=True)
    with _locked(folder), _sigterm_interrupts():
        write_copy(spec, folder)
        done = read_rows(folder, repair=True)
        todo = [r for r in spec.runs if r.key not in done
                or (retry_failed and done[r.key].get("status") == "failed")]
        outcome = Outcome(rows=[], total=len(spec.runs))
        code = code_digest()
        _warn_other_code(folder, code, len(spec.runs) - len(todo), console)
        session: dict[str, Any] = {
            "started": datetime.datetime.now().isoformat(timespec="seconds"),
            "runs": len(spec.runs), "resumed": len(spec.runs) - len(todo),
            "scheduler": scheduler, "code": code}
        try:
            if todo:
                _run(todo, folder, console, workers, scheduler, in_flight, outcome, done,
                     spec.name)
        finally:
            session.update(workers=outcome.workers, executed=outcome.executed,
                           lost=len(outcome.lost),
                           startup_seconds=round(outcome.startup_seconds, 2),
                           run_seconds=round(outcome.run_seconds, 2),
                           runs_per_minute=round(outcome.runs_per_minute, 1))
            _Appender(folder / SESSIONS, sync=False).write(session)
        outcome.rows = [done[k] for k in sorted(r.key for r in spec.runs) if k in done]
        outcome.failed = sum(r.get("status") == "failed" for r in outcome.rows)
        if outcome.complete:
            write_parquet(outcome.rows, folder / PARQUET)
        return outcome


def _warn_other_code(folder: Path, code: str, reused: int, console: Console) -> None:
    path = folder / SESSIONS
    if not reused or not path.exists():
        return
    codes = set()
    for line in path.read_text().splitlines():
        with contextlib.suppress(ValueError, AttributeError):
            codes.add(json.loads(line).get("code"))
    codes.discard(None)
    if codes - {code}:
        console.print(f"[yellow]note: {reused} rows in {folder} were computed by other "
                      f"sources of the simulator (code {', '.join(sorted(codes - {code}))}, "
                      f"now {code}); use a new folder to recompute them[/yellow]")


def _run(todo: list[Run], folder: Path, console: Console, workers: int | None,
         scheduler: str | None, in_flight: int | None, outcome: Outcome,
         done: dict[str, dict[str, Any]], name: str) -> None:
    from hil.cli.console import count_progress
    started = time.perf_counter()
    with dask_client(workers, scheduler) as client:
        if scheduler and not client.scheduler_info()["workers"]:
            try:
                client.wait_for_workers(1, timeout=CONNECT_TIMEOUT)
            except TimeoutError:
                raise CampaignError(f"the Dask scheduler at {scheduler} has no workers "
                                    f"(waited {CONNECT_TIMEOUT:g} s)") from None
        workers_info = client.scheduler_info()["workers"]
        threads = sum(w.get("nthreads", 1) for w in workers_info.values())
        outcome.workers = len(workers_info)
        warm = _warm_up(client)
        outcome.startup_seconds = time.perf_counter() - started
        console.print(f"campaign {name}: {len(todo)} runs to do on {outcome.workers} "
                      f"workers ({threads} threads); started in "
                      f"{outcome.startup_seconds:.1f} s (kernels loaded in {warm:.1f} s)")
        rows, timings = _Appender(folder / RUNS), _Appender(folder / TIMINGS, sync=False)
        run_started = time.perf_counter()
        try:
            with count_progress(console, f"campaign {name}", len(todo)) as advance:
                def on_row(row: dict[str, Any], timing: dict[str, Any]) -> None:
                    with _signals_deferred():       # a row and its timing, or neither
                        rows.write(row)
                        timings.write(timing)
                    done[row["key"]] = row
                    outcome.executed += 1
                    advance(row.get("status") == "failed")
                outcome.lost = _execute(client, todo, in_flight or max(4, 2 * threads),
                                        on_row)
        finally:
            outcome.run_seconds = time.perf_counter() - run_started
            rows.close()
            timings.close()


# --- parquet ----------------------------------------------------------------------------
def arrow_table(rows: list[dict[str, Any]]) -> Any:
    """The rows as an Arrow table: one column per key (identity and spec columns first, then
    in order of first appearance), typed by its values: bool, int64, float64 (ints and
    floats), string, or JSON text (lists, objects, mixed); missing values null."""
    import pyarrow as pa
    names: dict[str, None] = {}
    for row in rows:
        names.update(dict.fromkeys(row))
    order = sorted(names, key=_rank)            # stable: first appearance within a rank
    return pa.table({n: _column([row.get(n) for row in rows]) for n in order})


RANKS = ("key", "status", "error", "family_", "micro", "seed", "profile", "world_", "kill",
         "control_")


def _rank(name: str) -> int:
    """Identity first, then the spec's columns in the spec's order, then the results."""
    return next((i for i, p in enumerate(RANKS) if name.startswith(p)), len(RANKS))


def _column(values: list[Any]) -> Any:
    import pyarrow as pa
    kinds = {type(v) for v in values if v is not None}
    if not kinds:
        return pa.array(values, type=pa.null())
    if kinds == {bool}:
        return pa.array(values, type=pa.bool_())
    if kinds == {int}:
        return pa.array(values, type=pa.int64())
    if kinds <= {int, float}:
        return pa.array([None if v is None else float(v) for v in values], type=pa.float64())
    if kinds == {str}:
        return pa.array(values, type=pa.string())
    return pa.array([None if v is None else json.dumps(v, sort_keys=True) for v in values],
                    type=pa.string())


def write_parquet(rows: list[dict[str, Any]], path: Path) -> None:
    """Write the rows (already in their order) to ``path``, atomically."""
    import pyarrow.parquet as pq
    tmp = path.with_suffix(".tmp")
    pq.write_table(arrow_table(rows), tmp)
    tmp.replace(path)


def dask_available() -> bool:
    return importlib.util.find_spec("distributed") is not None
