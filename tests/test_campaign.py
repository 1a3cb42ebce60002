"""boundswarm campaign: spec expansion and keys, resume, Dask clusters (local and separate
processes), the report and the replay of a run."""
from __future__ import annotations

import json
import os
import re
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from hil.cli import main

ROOT = Path(__file__).resolve().parent.parent
SMOKE = ROOT / "campaigns" / "smoke.toml"
REALISTIC = ROOT / "campaigns" / "realistic.toml"

TINY = """
name = "tiny"
duration = 6.0
seeds = 2
profiles = ["{root}/robots/cart.toml", "none"]
[[family]]
kind = ["line", "grid"]
robots = 5
field = "sparse"
[[family]]
micro = ["head_on_swap"]
"""


@pytest.fixture(scope="module")
def families():
    """The environment of the processes a test starts (Dask workers): this checkout first
    on PYTHONPATH, so that they run this code (hil.campaign.families among it)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    saved = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = env["PYTHONPATH"]        # LocalCluster workers inherit it
    try:
        yield env
    finally:
        if saved is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = saved


def write_spec(folder: Path, text: str, name: str = "spec.toml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(text.format(root=ROOT))
    return path


def children() -> list[psutil.Process]:
    """This process's children but multiprocessing's resource tracker (it lives as long as
    this process, whatever started it)."""
    return [c for c in psutil.Process().children(recursive=True)
            if "multiprocessing.resource_tracker" not in " ".join(c.cmdline())]


def stop(procs: list[subprocess.Popen]) -> None:
    """End the processes this test started, and their children, by PID."""
    family = []
    for p in procs:
        try:
            family += psutil.Process(p.pid).children(recursive=True)
        except psutil.NoSuchProcess:
            pass
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=15)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
    for c in family:
        try:
            c.kill()
        except psutil.NoSuchProcess:
            pass


# --- the spec -------------------------------------------------------------------------------
CROSSED = """
name = "crossed"
seeds = [10, 3]
profiles = ["{root}/robots/cart.toml", "{root}/robots/fast.toml"]
[[family]]
kind = ["line", "grid"]
robots = [5, 8]
[[family]]
micro = ["head_on_swap", "narrow_gap"]
[world]
link_delay = [0.0, 0.2]
loss_burst = 2
kill_share = 0.5
kill_at = [2.0, 4.0]
[control]
hysteresis = [0.0, 0.5]
"""


def test_robot_profiles_given_on_the_command_line_replace_the_specs(tmp_path, families):
    from hil.campaign.spec import load_spec
    root = Path(__file__).resolve().parent.parent
    spec = load_spec(write_spec(tmp_path, CROSSED),
                     profiles=[str(root / "robots" / "heavy.toml")])
    assert {r.description["profile"] for r in spec.runs} == {"heavy"}
    assert len(spec.runs) == 144 // 2


def test_a_spec_crosses_its_values_into_runs_with_stable_keys(tmp_path, families):
    from hil.campaign.spec import load_spec, run_key
    spec = load_spec(write_spec(tmp_path, CROSSED))
    # (2 kinds x 2 sizes + 2 micro cases) x 3 seeds x 2 profiles x 2 delays x 2 hysteresis
    assert len(spec.runs) == 6 * 3 * 2 * 2 * 2 == 144
    assert len({r.key for r in spec.runs}) == 144
    assert all(re.fullmatch(r"[0-9a-f]{12}", r.key) for r in spec.runs)
    assert {r.description["seed"] for r in spec.runs} == {10, 11, 12}
    assert {r.description["profile"] for r in spec.runs} == {"cart", "fast"}
    # the hash of the canonical JSON (pinned: keys are results' names in a folder)
    assert run_key({"seed": 1, "a": [1.0, "x"]}) == run_key({"a": [1.0, "x"], "seed": 1})
    assert run_key({"seed": 1}) == "fbe47f6d82b4"
    # parsed again: the same runs in the same order; an integer where a float is meant
    # (loss_burst = 2) does not change a key
    again = load_spec(write_spec(tmp_path, CROSSED.replace("loss_burst = 2",
                                                           "loss_burst = 2.0"), "b.toml"))
    assert [r.key for r in again.runs] == [r.key for r in spec.runs]
    # more seeds and another kind add runs and keep the keys of the others
    more = load_spec(write_spec(tmp_path, CROSSED.replace("[10, 3]", "[10, 4]").replace(
        '["line", "grid"]', '["line", "wedge", "grid"]'), "c.toml"))
    assert {r.key for r in spec.runs} < {r.key for r in more.runs}
    assert len(more.runs) == (3 * 2 + 2) * 4 * 2 * 2 * 2


def test_world_seed_and_kill_depend_on_the_seed_and_family_only(tmp_path, families):
    from hil.campaign.run import scenario_doc
    from hil.campaign.spec import load_spec
    spec = load_spec(write_spec(tmp_path, CROSSED))
    by_case: dict[str, set] = {}
    for r in spec.runs:
        d = r.description
        case = json.dumps([d.get("family"), d.get("micro"), d["seed"]], sort_keys=True)
        by_case.setdefault(case, set()).add(
            json.dumps([d["world"]["seed"], d.get("kill_at")]))
    # paired: every profile, delay and gain of one scenario has one world seed and kill
    assert len(by_case) == 18 and all(len(v) == 1 for v in by_case.values())
    killed = [json.loads(next(iter(v)))[1] is not None for v in by_case.values()]
    assert 0 < sum(killed) < len(killed)            # kill_share = 0.5 of 18 scenarios
    run = next(r for r in spec.runs if r.description.get("kill_at"))
    doc = scenario_doc(run.description)
    assert doc == scenario_doc(run.description)     # a pure function of the description
    kill = doc["world"]["kill"]
    assert len(kill) == 1 and kill[0]["robot"] in [r["id"] for r in doc["robots"]]
    assert 2.0 <= kill[0]["at"] <= 4.0
    assert doc["world"]["link_delay"] in (0.0, 0.2) and doc["world"]["loss_burst"] == 2.0
    assert doc["sim"]["plant"] == "wheels" and doc["robot"]["wheel_speed_limit"] > 0
    assert doc["control"]["hysteresis"] == run.description["control"]["hysteresis"]


def test_both_assignments_of_a_scene_meet_the_same_world(tmp_path, families):
    from hil.campaign.run import scenario_doc
    from hil.campaign.spec import load_spec
    from hil.files.scenario import parse_scenario
    spec = load_spec(write_spec(tmp_path, """
name = "assign"
seeds = 4
[[family]]
kind = "circle"
robots = 8
assign = ["listed", "shortest"]
[world]
link_delay = 0.2
kill_share = 0.5
kill_at = [2.0, 4.0]
"""))
    assert len(spec.runs) == 8
    pairs: dict[int, list] = {}
    for r in spec.runs:
        pairs.setdefault(r.description["seed"], []).append(r.description)
    for listed, shortest in pairs.values():
        assert [listed["family"]["assign"], shortest["family"]["assign"]] == \
            ["listed", "shortest"]
        assert listed["world"] == shortest["world"]
        assert listed.get("kill_at") == shortest.get("kill_at")
        a, b = scenario_doc(listed), scenario_doc(shortest)
        assert a["robots"] == b["robots"] and b["formation"]["assign"] == "shortest"
        fa, fb = (parse_scenario(d, "t").formation for d in (a, b))
        assert sorted(fa.offsets.tolist()) == sorted(fb.offsets.tolist())


def test_mocap_goes_to_the_runs_whose_odometry_is_wrong(tmp_path, families):
    """A spec's [mocap] is the pose source of the runs with wheel slip (their scenario
    gets it); the other runs keep their description, hence their keys and cached rows."""
    from hil.campaign.run import scenario_doc
    from hil.campaign.spec import load_spec
    text = CROSSED.replace("loss_burst = 2", "loss_burst = 2\nwheel_slip = [0.0, 0.05]")
    plain = load_spec(write_spec(tmp_path / "a", text))
    spec = load_spec(write_spec(tmp_path / "b", text + "[mocap]\nrate = 50.0\n"))
    slipping = [r for r in spec.runs if r.description["world"].get("wheel_slip")]
    assert len(slipping) == len(spec.runs) // 2
    assert all(r.description["mocap"] == {"rate": 50.0} for r in slipping)
    assert all("mocap" not in r.description for r in spec.runs if r not in slipping)
    assert scenario_doc(slipping[0].description)["mocap"] == {"rate": 50.0}
    keys = {r.key for r in spec.runs}
    assert {r.key for r in plain.runs} & keys == keys - {r.key for r in slipping}


@pytest.mark.parametrize("change, field", [
    (("[control]", "[mocap]\nrate = 0.5\n[control]"), "[mocap]"),
    (("[control]", "[mocap]\n[[mocap.outage]]\nrobot = 1\nat = 1.0\nduration = 1.0\n"
                   "[control]"), "[mocap] outage"),
    (("name = \"crossed\"", "name = \"crossed\"\nrepeat = 2"), "top level: unknown field"),
    (("robots = [5, 8]", "robots = [5, 8]\nsize = 3"), "family[0]: unknown field"),
    (("kind = [\"line\", \"grid\"]", "kind = [\"line\", \"hexagon\"]"), "family[0]"),
    (("robots = [5, 8]", "robots = [5, 8.5]"), "family[0].robots"),
    (("\"narrow_gap\"]", "\"narrow_gap\", \"nope\"]"), "family[1].micro"),
    (("seeds = [10, 3]", "seeds = 0"), "seeds"),
    (("seeds = [10, 3]", "seeds = [1, 2, 3]"), "seeds"),
    (("hysteresis = [0.0, 0.5]", "hysteresis = [0.0, -1.0]"), "[control]"),
    (("hysteresis = [0.0, 0.5]", "gain = 2.0"), "[control]: unknown field"),
    (("link_delay = [0.0, 0.2]", "link_loss = [0.0, 1.5]"), "[world] link_loss"),
    (("link_delay = [0.0, 0.2]", "link_delay = []"), "[world] link_delay"),
    (("link_delay = [0.0, 0.2]", "link_loss = [0.1, 0.8]"), "[world]: WorldParams.loss_burst"),
    (("kill_at = [2.0, 4.0]", ""), "[world] kill_at"),
    (("kill_at = [2.0, 4.0]", "kill_at = [4.0, 2.0]"), "[world] kill_at"),
    (("fast.toml\"]", "nowhere.toml\"]"), "profiles[1]"),
])
def test_a_wrong_field_is_refused_naming_the_file_and_the_field(tmp_path, families, change,
                                                                field):
    from hil.campaign.spec import load_spec
    from hil.files.scenario import ScenarioError
    old, new = change
    assert old in CROSSED
    path = write_spec(tmp_path, CROSSED.replace(old, new))
    with pytest.raises(ScenarioError) as err:
        load_spec(path)
    assert str(err.value).startswith(str(path)) and field in str(err.value)


def test_a_bad_spec_exits_2_and_names_the_field(tmp_path, families, capsys):
    path = write_spec(tmp_path, CROSSED.replace("seeds = [10, 3]", "seeds = -1"))
    assert main(["campaign", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "seeds" in err
    assert not (tmp_path / "out").exists()


# --- rows and tables ------------------------------------------------------------------------
def test_a_run_that_raises_is_a_failed_row(monkeypatch):
    from hil.campaign import families
    from hil.campaign.run import run_one
    desc = {"family": {"kind": "line", "robots": 5}, "seed": 0, "duration": 5.0,
            "profile": "none", "robot": None, "control": {}}

    def broken(*args, **kwargs):
        raise ValueError("no room\nfor the robots")
    monkeypatch.setattr(families, "family_doc", broken)
    row = run_one(desc)
    assert row["status"] == "failed" and row["error"] == "ValueError: no room for the robots"
    assert row["family_kind"] == "line" and row["seed"] == 0 and "converged" not in row


@pytest.mark.parametrize("delay, held", [(0.0, True), (0.5, False)])
def test_a_row_says_whether_the_governor_lets_robots_keep_the_formation_s_pace(
        delay, held, families):
    """The realistic campaign's rotating ring of 20 sporty robots: its places 5 m apart
    move at up to 3.6 m/s, which with 0.5 s old data needs 5.2 m behind each robot
    (docs/controller.md A10): the row's pace_held is false, as sim warns; without delay,
    true."""
    from hil.campaign.run import run_one
    from hil.campaign.spec import load_spec
    spec = load_spec(ROOT / "campaigns" / "realistic-sparse.toml")
    desc = next(dict(r.description) for r in spec.runs
                if r.description["family"]["kind"] == "rotating_circle"
                and r.description["family"]["robots"] == 20
                and r.description["profile"] == "sporty"
                and r.description["world"]["link_delay"] == delay)
    desc["duration"] = 0.5
    row = run_one(desc)
    assert row["status"] == "ok" and row["pace_held"] is held


def test_the_report_counts_the_runs_whose_formation_cannot_be_held_apart(tmp_path):
    """With any run whose formation the governor cannot hold at its pace, the report
    tallies pace_held yes and no; without one, it has no such section."""
    from hil.campaign.report import write_report

    def row(key, held, converged):
        return {"key": key, "status": "ok", "profile": "sporty", "safe": True,
                "converged": converged, "deadlock": not converged, "pace_held": held,
                "min_pair_distance": 2.0, "min_obstacle_clearance": None, "a": 1.0}
    rows = [row("a", True, True), row("b", True, False), row("c", False, False)]
    report = write_report("t", rows, tmp_path / "one", 3).read_text()
    assert "## By pace_held" in report
    assert re.search(r"\| no \| 1 \| 0 \| 100\.0 % [^|]*\| 0\.0 % ", report)
    assert re.search(r"\| yes \| 2 \| 0 \| 100\.0 % [^|]*\| 50\.0 % ", report)
    held = [row("a", True, True), row("b", None, False)]
    assert "pace_held" not in write_report("t", held, tmp_path / "two", 2).read_text()


def test_warming_up_leaves_out_a_worker_lost_meanwhile():
    """A worker starved past its heartbeats during the warm-up is restarted by its nanny,
    and the broadcast to it fails: the campaign goes on with the others (a campaign run
    under another, at low priority, aborted there with CommClosedError)."""
    from distributed.comm.core import CommClosedError

    from hil.campaign.driver import _warm_up

    class Client:
        def run(self, function, on_error="raise"):
            assert on_error == "return"
            return {"tcp://127.0.0.1:1": 1.5, "tcp://127.0.0.1:2": CommClosedError("closed")}

    assert _warm_up(Client()) == 1.5


def test_rows_become_typed_arrow_columns():
    from hil.campaign.driver import arrow_table
    rows = [{"key": "a", "n": 1, "x": 1, "ok": True, "pairs": [[1, 2]], "t": None},
            {"key": "b", "n": 2, "x": 2.5, "ok": None, "pairs": [], "t": None, "new": "s"}]
    table = arrow_table(rows)
    types = {f.name: str(f.type) for f in table.schema}
    assert types == {"key": "string", "n": "int64", "x": "double", "ok": "bool",
                     "pairs": "string", "t": "null", "new": "string"}
    assert table.column("pairs").to_pylist() == ["[[1, 2]]", "[]"]
    assert table.column("new").to_pylist() == [None, "s"]


def test_wilson_interval():
    from hil.campaign.report import wilson
    lo, hi = wilson(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.2775, abs=1e-4)
    lo, hi = wilson(5, 10)
    assert (lo, hi) == (pytest.approx(0.2366, abs=1e-4), pytest.approx(0.7634, abs=1e-4))
    assert wilson(0, 0) == (0.0, 1.0)


# --- running --------------------------------------------------------------------------------
def rows_of(folder: Path) -> list[dict]:
    return [json.loads(line) for line in (folder / "runs.jsonl").read_text().splitlines()]


def timings_of(folder: Path) -> list[str]:
    return [json.loads(line)["key"] for line in
            (folder / "timings.jsonl").read_text().splitlines()]


def test_ctrl_c_stops_the_cluster_and_a_rerun_resumes_without_rerunning(tmp_path, families):
    """Interrupted (SIGINT) mid-way: exit 130 and no process left; a rerun runs only the
    runs without a row, and a campaign whose rows were partly deleted reruns exactly those
    and writes the same runs.parquet."""
    # 30 s runs (about 0.3 s each): the campaign is still running when the signal comes
    spec = write_spec(tmp_path, TINY.replace("seeds = 2", "seeds = 4")
                      .replace("duration = 6.0", "duration = 30.0"))
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "hil.cli", "campaign", str(spec), "--out", str(out),
           "--workers", "1"]
    # SIGINT at its default in the child, as from a shell: a child inherits an ignored
    # SIGINT, and Python then leaves it ignored (seen inside the full suite)
    proc = subprocess.Popen(cmd, env=families, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    started: list[psutil.Process] = []
    try:
        deadline = time.monotonic() + 600       # generous: compiling on a loaded machine
        while time.monotonic() < deadline and proc.poll() is None:
            if (out / "runs.jsonl").exists() and len(rows_of(out)) >= 2:
                break
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()[0]
        assert (out / "runs.jsonl").exists(), "no run finished in 600 s"
        started = psutil.Process(proc.pid).children(recursive=True)
        assert started, "the local cluster's worker processes"
        proc.send_signal(signal.SIGINT)
        output, _ = proc.communicate(timeout=60)
        assert proc.returncode == 130, output
        assert "interrupted" in output
        _, alive = psutil.wait_procs(started, timeout=10)
        assert not alive
    finally:
        stop([proc])
        for c in started:               # orphaned when the campaign exited before the test
            try:                        # could end it: they would load every later test
                c.kill()
            except psutil.NoSuchProcess:
                pass
    before = rows_of(out)
    assert 2 <= len(before) < 24 and not (out / "runs.parquet").exists()

    assert main(["campaign", str(spec), "--out", str(out), "--workers", "1"]) == 0
    done = timings_of(out)
    assert len(done) == len(set(done)) == 24               # no finished run ran twice
    assert {r["key"] for r in before} <= set(done[:len(before)])
    parquet = (out / "runs.parquet").read_bytes()
    assert not children()

    lines = (out / "runs.jsonl").read_text().splitlines()
    kept = lines[::3]
    (out / "runs.jsonl").write_text("\n".join(kept) + "\n" + lines[1][:40])   # torn tail
    assert main(["campaign", str(out), "--workers", "1"]) == 0           # the folder alone
    assert len(timings_of(out)) == 24 + 24 - len(kept)
    assert (out / "runs.parquet").read_bytes() == parquet
    assert not children()

    assert main(["campaign", str(out)]) == 0                       # nothing left to run
    assert len(timings_of(out)) == 24 + 24 - len(kept)
    sessions = [json.loads(s) for s in (out / "sessions.jsonl").read_text().splitlines()]
    assert [s["executed"] for s in sessions][-2:] == [24 - len(kept), 0]


def test_an_unreachable_scheduler_exits_1_and_a_malformed_one_2(tmp_path, families, capsys,
                                                                monkeypatch):
    from helpers import free_port

    from hil.campaign import driver
    monkeypatch.setattr(driver, "CONNECT_TIMEOUT", 1.0)
    spec = write_spec(tmp_path, TINY)
    address = f"tcp://127.0.0.1:{free_port()}"
    assert main(["campaign", str(spec), "--out", str(tmp_path / "o"),
                 "--scheduler", address]) == 1
    err = capsys.readouterr().err
    assert f"cannot reach the Dask scheduler at {address}" in err and "\n" == err[-1]
    assert main(["campaign", str(spec), "--out", str(tmp_path / "o"),
                 "--scheduler", "127.0.0.1"]) == 2
    assert "--scheduler" in capsys.readouterr().err


# --- the smoke campaign: local cluster, separate processes, report, replay -----------------
@pytest.fixture(scope="module")
def smoke_local(tmp_path_factory, families):
    """campaigns/smoke.toml on a local cluster of 2 workers."""
    out = tmp_path_factory.mktemp("smoke") / "local"
    started = time.monotonic()
    code = main(["campaign", str(SMOKE), "--out", str(out), "--workers", "2"])
    print(f"smoke, 2 local workers: {time.monotonic() - started:.1f} s")
    assert code == 0
    assert not children()
    return out


def test_smoke_on_separate_scheduler_and_workers_equals_the_local_run(tmp_path, families,
                                                                      smoke_local):
    """The acceptance test: a Dask scheduler and two workers, each its own process on
    127.0.0.1, run campaigns/smoke.toml through --scheduler; runs.parquet is byte-equal to
    the local cluster's."""
    from distributed import Client
    scheduler_file = tmp_path / "scheduler.json"
    py = sys.executable
    local = ["--host", "127.0.0.1", "--no-dashboard", "--dashboard-address", "127.0.0.1:0"]
    procs = [subprocess.Popen([py, "-m", "distributed.cli.dask_scheduler", "--port", "0",
                               "--scheduler-file", str(scheduler_file), *local],
                              env=families, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)]
    try:
        def written() -> str | None:          # the scheduler writes its file, not at once
            try:
                return json.loads(scheduler_file.read_text())["address"]
            except (OSError, ValueError, KeyError):
                return None

        deadline = time.monotonic() + 60
        while (address := written()) is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert address, f"no scheduler address in {scheduler_file} after 60 s"
        for _ in range(2):
            procs.append(subprocess.Popen(
                [py, "-m", "distributed.cli.dask_worker", "--scheduler-file",
                 str(scheduler_file), "--nworkers", "1", "--nthreads", "1", *local],
                env=families, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with Client(address, timeout=30, set_as_default=False) as client:
            client.wait_for_workers(2, timeout=60)
        # nothing of the cluster listens beyond this machine
        for p in procs:
            for proc in [psutil.Process(p.pid), *psutil.Process(p.pid).children(True)]:
                for conn in proc.net_connections(kind="inet"):
                    if conn.status == psutil.CONN_LISTEN:
                        assert conn.laddr.ip == "127.0.0.1", (proc.cmdline(), conn)
        out = tmp_path / "remote"
        assert main(["campaign", str(SMOKE), "--out", str(out), "--scheduler", address]) == 0
    finally:
        stop(procs)
    assert (out / "runs.parquet").read_bytes() == (smoke_local / "runs.parquet").read_bytes()
    assert len({json.loads(t)["pid"] for t in
                (out / "timings.jsonl").read_text().splitlines()}) == 2   # both workers ran


def test_smoke_report_has_groups_and_intervals_and_its_replay_writes_a_run_folder(
        tmp_path, smoke_local, capsys):
    import pyarrow.parquet as pq
    table = pq.read_table(smoke_local / "runs.parquet")
    keys = table.column("key").to_pylist()
    assert keys == sorted(keys) and len(keys) == len(set(keys))
    for column in ("family_kind", "micro", "seed", "profile", "world_link_delay", "kill",
                   "kill_robot", "safe", "converged", "deadlock", "pace_held",
                   "min_pair_distance",
                   "min_obstacle_clearance", "convergence_time", "stuck_robots"):
        assert column in table.column_names, column
    assert "seconds" not in table.column_names
    # the world reached the simulator: each kill within the run is in its killed robots
    rows = rows_of(smoke_local)
    killed = [r for r in rows if r["kill"] and r["kill_time"] <= r["duration"]]
    assert killed and all(r["killed_robots"] == [r["kill_robot"]] for r in killed)
    assert all(r["killed_robots"] == [] for r in rows if not r["kill"])
    assert {r["world_link_delay"] for r in rows} == {0.0, 0.2}
    report = (smoke_local / "report.md").read_text()
    for group in ("## Overall", "## By family_kind", "## By micro", "## By profile",
                  "## By world_link_delay", "## By kill", "## Worst runs"):
        assert group in report, group
    assert re.search(r"\| all \| \d+ \| 0 \| \d+\.\d % \[\d+\.\d, \d+\.\d\] \|", report)
    figures = {p.name for p in (smoke_local / "figures").iterdir()}
    assert {"rates_family_kind.png", "rates_profile.png", "min_distance.png",
            "min_clearance.png"} <= figures
    found = re.search(r"`(boundswarm campaign \S+ --replay \w+ --out \S+)`", report)
    assert found is not None, "the report names no replay command"
    command = found[1]
    argv = shlex.split(command)[1:]
    key = argv[argv.index("--replay") + 1]
    argv[argv.index("--out") + 1] = str(tmp_path / "replay")
    main(argv)
    run = tmp_path / "replay"
    metrics = json.loads((run / "metrics.json").read_text())
    row = next(r for r in rows_of(smoke_local) if r["key"] == key)
    assert metrics["min_pair_distance"] == row["min_pair_distance"]
    assert metrics["converged"] == row["converged"]
    assert "reproduces the campaign's row" in capsys.readouterr().out
    assert {p.name for p in (run / "figures").iterdir()} >= {"xy.png", "dmin.png"}
    assert (run / "trajectories.csv").exists() and (run / "scenario.toml").exists()
    # the run folder's scenario is the whole run: sim reproduces it from the file alone
    assert main(["report", str(run)]) == 0


@pytest.mark.parametrize("spec_file", sorted((ROOT / "campaigns").glob("*.toml")),
                         ids=lambda p: p.stem)
def test_every_shipped_campaign_expands(spec_file, families):
    """Each campaign in campaigns/ loads, its profiles and families included."""
    from hil.campaign.spec import load_spec
    spec = load_spec(spec_file)
    assert spec.runs and len({r.key for r in spec.runs}) == len(spec.runs)


def test_the_sparse_campaign_is_the_realistic_campaign_s_sparse_runs(families):
    """campaigns/realistic-sparse.toml runs issue 16's measure alone: the very runs (keys,
    so scenes and worlds) of the full campaign's sparse fields, and no others."""
    from hil.campaign.spec import load_spec
    full = load_spec(ROOT / "campaigns" / "realistic.toml")
    sparse = {r.key for r in full.runs
              if r.description.get("family", {}).get("field") == "sparse"}
    assert len(sparse) == 720
    assert {r.key for r in load_spec(ROOT / "campaigns" / "realistic-sparse.toml").runs} == sparse


def test_the_speed_up_campaign_sets_speed_up_on_one_of_each_pair(families):
    from hil.campaign.spec import load_spec
    spec = load_spec(ROOT / "campaigns" / "speed-up.toml")
    speed_up = {r.description["profile"]: r.description["robot"].get("speed_up", 0.0)
                for r in spec.runs}
    assert speed_up == {"sporty": 2.0, "sporty-ramp": 0.0, "fast": 2.0, "fast-ramp": 0.0}


def test_the_realistic_campaign_has_over_a_thousand_runs(families):
    from hil.campaign.spec import load_spec
    spec = load_spec(REALISTIC)
    assert len(spec.runs) >= 1000
    profiles = {r.description["profile"] for r in spec.runs}
    assert profiles == {"heavy", "cart", "fast", "sporty"}
    killed = sum(bool(r.description.get("kill_at")) for r in spec.runs) / len(spec.runs)
    assert 0.25 < killed < 0.42


def test_a_local_cluster_has_a_worker_per_core_this_process_may_run_on(monkeypatch):
    """By default a worker per core of this process's affinity (a container's or a
    taskset's share), not one per CPU of the machine, which would oversubscribe it."""
    import distributed

    from hil.campaign import driver
    made: dict = {}

    class Cluster:
        def __init__(self, **options):
            made.update(options)

        def close(self):
            made["closed"] = True

    class Client:
        def __init__(self, *args, **options):
            pass

        def close(self):
            pass

    monkeypatch.setattr(distributed, "LocalCluster", Cluster)
    monkeypatch.setattr(distributed, "Client", Client)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {3})
    assert os.cpu_count() != 1          # else this test could not tell the two apart
    with driver.dask_client(None, None):
        pass
    assert made["n_workers"] == 1 and made["closed"]
