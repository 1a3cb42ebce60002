"""The paper's seven figures from a recorded run (matplotlib, Agg backend, PNG files).

x(t), y(t), theta(t), u(t), v(t), minimum pair distance d_min(t), and the XY paths with
obstacles, references and the modes marked (AVOID crosses, ROTATE dots).
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (backend chosen first)
import numpy as np  # noqa: E402

from common.vocabulary import Mode  # noqa: E402
from firmware_sim.world import Obstacles  # noqa: E402
from hil.files.run_folder import RunData  # noqa: E402

FIGURE_FILES = ("x.png", "y.png", "theta.png", "u.png", "v.png", "dmin.png", "xy.png")


def _colours(n: int) -> list:
    cmap = plt.get_cmap("tab10" if n <= 10 else "viridis")
    return [cmap(i if n <= 10 else i / max(n - 1, 1)) for i in range(n)]


def _time_plot(path: Path, t: np.ndarray, values: np.ndarray, ids: np.ndarray,
               ylabel: str, title: str, legend: bool) -> None:
    fig, ax = plt.subplots(figsize=(7, 4))
    for i, colour in enumerate(_colours(len(ids))):
        ax.plot(t, values[:, i], color=colour, lw=1.2, label=f"robot {ids[i]}")
    ax.set_xlabel("t [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if legend:
        ax.legend(fontsize=7, ncol=2, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def draw_figures(data: RunData, obstacles: Obstacles, a: float, b: float, out: Path
                 ) -> list[Path]:
    """Write the seven figures into ``out`` and return their paths."""
    out.mkdir(parents=True, exist_ok=True)
    legend = len(data.ids) <= 12
    paths = [out / f for f in FIGURE_FILES]
    series = [(data.pose[..., 0], "x [m]", "Evolution of the x coordinates"),
              (data.pose[..., 1], "y [m]", "Evolution of the y coordinates"),
              (data.pose[..., 2], "theta [rad]", "Evolution of the heading angles"),
              (data.u, "u [rad/s]", "Evolution of the angular speeds"),
              (data.v, "v [m/s]", "Evolution of the linear speeds")]
    for path, (values, ylabel, title) in zip(paths, series):
        _time_plot(path, data.t, values, data.ids, ylabel, title, legend)

    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(data.dist_t, data.d_min, color="k", lw=1.2, label="min distance between robots")
    if np.isfinite(data.clearance_min).any():
        ax.plot(data.dist_t, data.clearance_min, color="tab:brown", lw=1.0, ls="--",
                label="min clearance to obstacles")
    ax.axhline(a, color="r", lw=1, ls=":", label=f"a = {a:g} m (collision)")
    ax.axhline(b, color="orange", lw=1, ls=":", label=f"b = {b:g} m (avoidance)")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("distance [m]")
    ax.set_title("Evolution of the minimum distance among agents")
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(paths[5], dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(8, 6))
    for centre, radius in zip(obstacles.centers, obstacles.radii):
        ax.add_patch(plt.Circle(centre, radius, color="0.6", alpha=0.6, zorder=1))
    for i, colour in enumerate(_colours(len(data.ids))):
        x, y = data.pose[:, i, 0], data.pose[:, i, 1]
        ax.plot(x, y, color=colour, lw=1.2, zorder=2,
                label=f"robot {data.ids[i]}" if legend else None)
        ax.plot(x[0], y[0], "o", color=colour, ms=4, zorder=3)
        ax.plot(data.ref[-1, i, 0], data.ref[-1, i, 1], "s", mfc="none", color=colour, ms=6)
        for mode, marker in ((Mode.AVOID, "x"), (Mode.ROTATE, ".")):
            sel = data.mode[:, i] == mode
            ax.plot(x[sel], y[sel], marker, color=colour, ms=4, alpha=0.7, zorder=4)
    ax.plot([], [], "kx", label="AVOID")
    ax.plot([], [], "k.", label="ROTATE")
    ax.plot([], [], "ks", mfc="none", label="final reference")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title("Evolution of the agents")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=2, loc="best")
    fig.tight_layout()
    fig.savefig(paths[6], dpi=110)
    plt.close(fig)
    return paths
