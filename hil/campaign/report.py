"""A campaign's report: DIR/report.md and DIR/figures/ from its rows.

Per group (overall, then each value of each swept dimension): runs, safety and convergence
rates with 95 % Wilson intervals, deadlocks, mean convergence time, the closest pair and
the smallest clearance; then the worst runs, each with the command that replays it into a
run folder with figures. Figures (matplotlib, Agg): the rates against each swept dimension,
histograms of the smallest pair distance and obstacle clearance.
"""
from __future__ import annotations

import math
import shlex
from pathlib import Path
from typing import Any, Iterable, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (backend chosen first)

REPORT, FIGURES = "report.md", "figures"
Z95 = 1.959963984540054
DIMENSION_PREFIXES = ("family_", "world_", "control_")
DIMENSIONS = ("micro", "profile", "kill")
NOT_DIMENSIONS = ("world_seed",)
WORST = 5


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of k successes in n trials ((0, 1) when n = 0)."""
    if n == 0:
        return 0.0, 1.0
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def dimensions(rows: Sequence[dict[str, Any]]) -> list[str]:
    """The spec columns that take more than one value among ``rows``, in column order."""
    names: dict[str, None] = {}
    for row in rows:
        names.update(dict.fromkeys(
            k for k in row if (k.startswith(DIMENSION_PREFIXES) or k in DIMENSIONS)
            and k not in NOT_DIMENSIONS))
    return [n for n in names if len({_hashable(r.get(n)) for r in rows}) > 1]


def _hashable(value: Any) -> Any:
    return tuple(value) if isinstance(value, list) else value


def _order(value: Any) -> tuple:
    if value is None:
        return (0, "", 0)
    if isinstance(value, (bool, int, float)):
        return (1, "", float(value))
    return (2, str(value), 0)


def _label(value: Any) -> str:
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


class Group:
    """The tallies of a set of rows."""

    def __init__(self, rows: Iterable[dict[str, Any]]):
        rows = list(rows)
        ok = [r for r in rows if r.get("status") == "ok"]
        self.runs, self.failed, self.n = len(rows), len(rows) - len(ok), len(ok)
        self.safe = sum(bool(r.get("safe")) for r in ok)
        self.converged = sum(bool(r.get("converged")) for r in ok)
        self.deadlock = sum(bool(r.get("deadlock")) for r in ok)
        times = [r["convergence_time"] for r in ok if r.get("convergence_time") is not None]
        self.mean_time = sum(times) / len(times) if times else None
        self.dmin = min((r["min_pair_distance"] for r in ok
                         if r.get("min_pair_distance") is not None), default=None)
        self.cmin = min((r["min_obstacle_clearance"] for r in ok
                         if r.get("min_obstacle_clearance") is not None), default=None)

    def rate(self, k: int) -> str:
        if not self.n:
            return "–"
        lo, hi = wilson(k, self.n)
        return f"{100 * k / self.n:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]"

    def cells(self) -> list[str]:
        return [str(self.runs), str(self.failed), self.rate(self.safe),
                self.rate(self.converged), self.rate(self.deadlock),
                "–" if self.mean_time is None else f"{self.mean_time:.2f}",
                "–" if self.dmin is None else f"{self.dmin:.3f}",
                "–" if self.cmin is None else f"{self.cmin:.3f}"]


HEADER = ["runs", "failed", "safe % [95 % CI]", "converged % [95 % CI]",
          "deadlocked % [95 % CI]", "mean convergence time [s]", "closest pair [m]",
          "smallest clearance [m]"]


def _table(first: str, groups: list[tuple[str, Group]]) -> list[str]:
    lines = ["| " + " | ".join([first, *HEADER]) + " |",
             "|" + "---|" * (len(HEADER) + 1)]
    lines += ["| " + " | ".join([label, *g.cells()]) + " |" for label, g in groups]
    return lines


def _describe(row: dict[str, Any], dims: Sequence[str]) -> str:
    """The run's scenario (family keys or micro case, seed), profile and swept values."""
    shown = [k for k in row if k.startswith("family_") or k in ("micro", "seed", "profile")
             or k in dims]
    return " ".join(f"{k.split('_', 1)[1] if k.startswith(DIMENSION_PREFIXES) else k}="
                    f"{_label(row[k])}" for k in shown
                    if row[k] is not None and row[k] is not False)


def replay_command(folder: Path, key: str) -> str:
    """The command that replays run ``key`` of the campaign in ``folder`` into a run folder."""
    return (f"boundswarm campaign {shlex.quote(str(folder))} --replay {key} --out "
            f"{shlex.quote(str(folder / 'replay' / key))}")


def _worst(title: str, rows: list[dict[str, Any]], value: str, folder: Path,
           dims: Sequence[str], extra: Sequence[str] = ()) -> list[str]:
    if not rows:
        return []
    lines = ["", f"### {title}", ""]
    for r in rows:
        facts = [f"{k} = {_label(r.get(k))}" for k in (value, *extra)
                 if r.get(k) is not None]
        lines += [f"- `{r['key']}` {r.get('scenario') or ''} ({_describe(r, dims)}): "
                  f"{', '.join(facts)}",
                  f"  `{replay_command(folder, r['key'])}`"]
    return lines


def write_report(name: str, rows: list[dict[str, Any]], folder: Path, total: int) -> Path:
    """Write ``folder/report.md`` and ``folder/figures/`` from the campaign's rows."""
    figures = folder / FIGURES
    figures.mkdir(parents=True, exist_ok=True)
    dims = dimensions(rows)
    ok = [r for r in rows if r.get("status") == "ok"]
    failures = len(rows) - len(ok)
    lines = [f"# Campaign {name}", "",
             f"{len(rows)} of {total} runs finished, {failures} of them failed (raised an "
             f"error). Safe: no two robots closer than a and no robot "
             f"centre within a of an obstacle surface. Converged: every robot within its "
             f"tolerance at the end and staying there. Deadlocked: the `deadlocked` metric, "
             f"else not converged. Rates are over the runs that did not fail, with 95 % "
             f"Wilson intervals; the convergence time is the mean over converged runs. The "
             f"group – holds the runs without that key (e.g. micro cases for a family key).",
             "", "## Overall", "", *_table("", [("all", Group(rows))])]
    for dim in dims:
        values = sorted({_hashable(r.get(dim)) for r in rows}, key=_order)
        groups = [(_label(v), Group(r for r in rows if _hashable(r.get(dim)) == v))
                  for v in values]
        path = _rates_figure(dim, groups, figures)
        lines += ["", f"## By {dim}", "", *_table(dim, groups), "",
                  f"![rates by {dim}]({FIGURES}/{path.name})"]
    held = sorted({_hashable(r.get("pace_held")) for r in ok}, key=_order)
    if False in held:
        groups = [(_label(v), Group(r for r in rows if r.get("pace_held") == v))
                  for v in held]
        lines += ["", "## By pace_held", "",
                  "Whether the governor lets a robot keep the formation's pace behind the "
                  "place ahead of its own with the run's data age (`pace_held`): where it "
                  "does not, that robot trails its place and the run cannot converge.", "",
                  *_table("pace_held", groups)]
    lines += ["", "## Distances", ""]
    for key, title, fname in (("min_pair_distance", "closest pair of robots", "min_distance"),
                              ("min_obstacle_clearance", "smallest obstacle clearance",
                               "min_clearance")):
        path = _histogram([r[key] for r in ok if r.get(key) is not None],
                          [r["a"] for r in ok if "a" in r], title, figures / f"{fname}.png")
        lines.append(f"![{title}]({FIGURES}/{path.name})")
    lines += ["", "## Worst runs", "",
              "Each with the command that replays it into a run folder with figures "
              "(as `boundswarm sim` writes)."]
    by_d = sorted((r for r in ok if r.get("min_pair_distance") is not None),
                  key=lambda r: (r["min_pair_distance"], r["key"]))[:WORST]
    by_c = sorted((r for r in ok if r.get("min_obstacle_clearance") is not None),
                  key=lambda r: (r["min_obstacle_clearance"], r["key"]))[:WORST]
    stuck = sorted((r for r in ok if not r.get("converged")),
                   key=lambda r: (-(r.get("final_max_tracking_error") or 0.0), r["key"]))
    failed = [r for r in rows if r.get("status") == "failed"]
    lines += _worst("Closest pairs", by_d, "min_pair_distance", folder, dims,
                    ("min_pair_time", "worst_pair", "a"))
    lines += _worst("Smallest clearances", by_c, "min_obstacle_clearance", folder, dims,
                    ("min_clearance_time", "worst_clearance_robot", "a"))
    lines += _worst(f"Not converged ({len(stuck)}; the {min(len(stuck), 2 * WORST)} farthest "
                    f"from their references)", stuck[:2 * WORST],
                    "final_max_tracking_error", folder, dims,
                    ("stuck_robots", "deadlocked_robots", "killed_robots"))
    lines += _worst(f"Failed ({len(failed)})", failed[:2 * WORST], "error", folder, dims)
    out = folder / REPORT
    out.write_text("\n".join(lines) + "\n")
    return out


def _rates_figure(dim: str, groups: list[tuple[str, Group]], figures: Path) -> Path:
    fig, ax = plt.subplots(figsize=(max(5.0, 0.9 * len(groups) + 2), 3.6))
    x = list(range(len(groups)))
    for shift, attr, label, colour in ((-0.08, "safe", "safe", "tab:green"),
                                       (0.08, "converged", "converged", "tab:blue")):
        ys, los, his = [], [], []
        for _, g in groups:
            k = getattr(g, attr)
            lo, hi = wilson(k, g.n)
            y = k / g.n if g.n else math.nan
            ys.append(100 * y)
            los.append(100 * max(0.0, y - lo) if g.n else 0.0)
            his.append(100 * max(0.0, hi - y) if g.n else 0.0)
        ax.errorbar([i + shift for i in x], ys, yerr=[los, his], fmt="o-", capsize=3,
                    color=colour, label=f"{label} (95 % CI)")
    ax.set_xticks(x, [label for label, _ in groups], rotation=30 if len(groups) > 5 else 0)
    ax.set_xlabel(dim)
    ax.set_ylabel("runs [%]")
    ax.set_ylim(-5, 105)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = figures / f"rates_{dim}.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _histogram(values: list[float], a_values: list[float], title: str, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(6, 3.6))
    if values:
        ax.hist(values, bins=min(40, max(5, len(values) // 4)), color="0.5")
    for a in sorted(set(a_values)):
        ax.axvline(a, color="r", ls=":", lw=1, label=f"a = {a:g} m")
    ax.set_xlabel(f"{title} [m]")
    ax.set_ylabel("runs")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if a_values:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
