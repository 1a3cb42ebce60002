"""The run folder written by ``sim`` and ``sitl`` and read by ``report``.

Layout (every file and key is described in docs/formats.md)::

    DIR/metrics.json        metrics
    DIR/trajectories.csv    one row per robot and control period:
                            t [s], id, x [m], y [m], theta [rad], v [m/s], u [rad/s],
                            mode (0 TRACK, 1 AVOID, 2 ROTATE), x_d [m], y_d [m]
    DIR/distances.csv       t [s], d_min [m], clearance_min [m] at every physics step
    DIR/scenario.toml       the scenario the run used (verbatim copy)
    DIR/figures/            the paper's seven figures (PNG)

Both CSV files have one header line and read directly with ``numpy.loadtxt(...,
delimiter=",", skiprows=1)`` or ``pandas.read_csv``.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from firmware_sim.batch import TRAJECTORY_COLUMNS, SimResult

METRICS = "metrics.json"
TRAJECTORIES = "trajectories.csv"
DISTANCES = "distances.csv"
SCENARIO = "scenario.toml"
FIGURES = "figures"


class RunFolderError(ValueError):
    """A run folder is missing a file or holds a malformed one."""


@dataclass(frozen=True)
class RunData:
    """A recorded run as arrays: R control periods x N robots."""

    ids: np.ndarray          # (N,)
    t: np.ndarray            # (R,) s
    pose: np.ndarray         # (R, N, 3)
    v: np.ndarray            # (R, N)
    u: np.ndarray            # (R, N)
    mode: np.ndarray         # (R, N) int
    ref: np.ndarray          # (R, N, 2)
    dist_t: np.ndarray       # (S,) s
    d_min: np.ndarray        # (S,) m, nan where no pair was in sensing range
    clearance_min: np.ndarray  # (S,) m, nan where no obstacle was in sensing range

    @classmethod
    def from_result(cls, res: SimResult) -> "RunData":
        m = res.metrics
        return cls(ids=res.ids, t=res.t, pose=res.pose, v=res.v, u=res.u, mode=res.mode,
                   ref=res.ref, dist_t=np.asarray(m.geometry_t),
                   d_min=finite_or_nan(m.geometry_dmin),
                   clearance_min=finite_or_nan(m.geometry_clear))


def finite_or_nan(values: list) -> np.ndarray:
    """Distances as an array, with nan where none was observed (inf)."""
    arr = np.asarray(values, dtype=float)
    return np.where(np.isfinite(arr), arr, np.nan)


def write_run(out: Path, metrics: dict, data: RunData, scenario_text: str | None) -> None:
    """Write metrics, trajectories, distances and the scenario copy into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    (out / METRICS).write_text(json.dumps(_json_safe(metrics), indent=2) + "\n")
    r, n = data.v.shape
    rows = np.column_stack([
        np.repeat(data.t, n), np.tile(data.ids, r),
        data.pose[..., 0].ravel(), data.pose[..., 1].ravel(), data.pose[..., 2].ravel(),
        data.v.ravel(), data.u.ravel(), data.mode.ravel(),
        data.ref[..., 0].ravel(), data.ref[..., 1].ravel()])
    np.savetxt(out / TRAJECTORIES, rows, delimiter=",", header=",".join(TRAJECTORY_COLUMNS),
               comments="", fmt=["%.4f", "%d"] + ["%.6f"] * 5 + ["%d"] + ["%.6f"] * 2)
    np.savetxt(out / DISTANCES, np.column_stack([data.dist_t, data.d_min, data.clearance_min]),
               delimiter=",", header="t,d_min,clearance_min", comments="", fmt="%.6f")
    if scenario_text is not None:
        (out / SCENARIO).write_text(scenario_text)


def read_run(run: Path) -> RunData:
    """Read a run folder written by :func:`write_run`."""
    traj = _load_csv(run / TRAJECTORIES, TRAJECTORY_COLUMNS)
    dist = _load_csv(run / DISTANCES, ("t", "d_min", "clearance_min"))
    t, ids = np.unique(traj[:, 0]), np.unique(traj[:, 1].astype(int))
    r, n = len(t), len(ids)
    if len(traj) != r * n:
        raise RunFolderError(f"{run / TRAJECTORIES}: expected one row per robot and time "
                             f"({r} x {n}), got {len(traj)} rows")
    order = np.lexsort((traj[:, 1], traj[:, 0]))
    g = traj[order].reshape(r, n, len(TRAJECTORY_COLUMNS))
    return RunData(ids=ids, t=t, pose=g[..., 2:5], v=g[..., 5], u=g[..., 6],
                   mode=g[..., 7].astype(int), ref=g[..., 8:10], dist_t=dist[:, 0],
                   d_min=dist[:, 1], clearance_min=dist[:, 2])


def _load_csv(path: Path, columns: tuple[str, ...]) -> np.ndarray:
    try:
        header = path.open().readline().strip()
    except OSError as exc:
        raise RunFolderError(f"{path}: cannot read: {exc.strerror}") from None
    if header != ",".join(columns):
        raise RunFolderError(f"{path}: expected header {','.join(columns)!r}, got {header!r}")
    try:
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    except ValueError as exc:
        raise RunFolderError(f"{path}: malformed row: {exc}") from None
    if data.shape[1] != len(columns):
        raise RunFolderError(f"{path}: expected {len(columns)} columns, got {data.shape[1]}")
    return data


def _json_safe(obj):
    """Replace non-finite floats (JSON has none) by null, recursively."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    return obj
