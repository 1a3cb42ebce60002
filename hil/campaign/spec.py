"""Campaign specs (TOML): families and micro cases crossed with seeds, robot profiles, world
settings and controller sweeps, expanded into runs.

Format (every key, with its unit and default, in docs/campaigns.md)::

    name = "smoke"
    duration = 30.0                 # s per run (default: the family's or micro case's own)
    seeds = 3                       # seeds 0..2, or [first, count]
    profiles = ["../robots/cart.toml", "none"]    # relative to the spec; "none": the
                                    # scenario's default robot and ideal plant
    [[family]]                      # kind, robots, spacing, slots, field, speed: each a
    kind = ["line", "grid"]         # value or a list of values (crossed)
    [[family]]
    micro = ["head_on_swap"]        # micro cases instead of family keys
    [world]                         # link_delay, ... : each a value or a list (crossed)
    [mocap]                         # a pose source (MocapParams, no outages) for the runs
                                    # whose world has wheel slip or encoder noise
    kill_share = 0.333              # share of runs with one robot killed at a time drawn
    kill_at = [5.0, 20.0]           # uniformly in this range [s]
    [control]                       # ControlParams fields: each a value or a list (crossed)

A run is a plain description (JSON-able dict); its key is a short hash of its canonical
JSON, so results are cached by what was run. The family generation seed is the run's seed;
the world seed and the kill draw derive from the seed and the family (or micro case) only,
so the runs of one scenario under other profiles, world settings or gains are paired.
Every problem raises :class:`~hil.files.scenario.ScenarioError` naming the spec file and field.
"""
from __future__ import annotations

import hashlib
import importlib
import itertools
import json
import math
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

from agent.config import ControlParams
from common.schema import ConfigError, TableReader, fields, from_table, load_toml
from hil.files import toml_text
from hil.files.scenario import ScenarioError

TOP_KEYS = {"name", "description", "duration", "seeds", "profiles", "family", "world",
            "mocap", "control"}
FAMILY_TEXT = ("kind", "slots", "field", "assign")   # family keys holding strings
FAMILY_KEYS = ("kind", "robots", "spacing", "slots", "field", "speed", "assign")
WORLD_KEYS = ("link_delay", "link_jitter", "link_loss", "loss_burst", "wheel_slip",
              "encoder_noise", "detection_noise", "detection_dropout")
KILL_KEYS = ("kill_share", "kill_at")
NO_PROFILE = "none"
PROFILES_DIR = "profiles"          # the profiles' copies in a campaign folder
SPEC_COPY = "spec.toml"


@dataclass(frozen=True)
class Run:
    """One run: its key and its description (everything that makes its result)."""

    key: str
    description: dict[str, Any]


@dataclass(frozen=True)
class CampaignSpec:
    name: str
    doc: dict[str, Any]                       # the spec as read (validated)
    profiles: dict[str, Path | None]          # name -> profile file (None: "none")
    runs: tuple[Run, ...]
    source: Path | None = None
    checked_families: int = field(default=0, compare=False)


def run_key(description: Mapping[str, Any]) -> str:
    """12 hex digits of the SHA-256 of the description's canonical JSON."""
    text = json.dumps(description, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def derived_seed(*parts: Any) -> int:
    """A 32-bit seed from JSON-able ``parts`` (stable across machines and Python versions)."""
    text = json.dumps(parts, sort_keys=True, separators=(",", ":"))
    return int(hashlib.sha256(text.encode()).hexdigest()[:8], 16)


def families_module() -> Any:
    """``hil.campaign.families``, imported when first needed."""
    try:
        return importlib.import_module("hil.campaign.families")
    except ImportError as exc:
        raise RuntimeError(f"the scenario families (hil/campaign/families.py) cannot be imported: "
                           f"{exc}") from None


def load_spec(path: str | Path, check_families: bool = True,
              profiles: list[str] | None = None) -> CampaignSpec:
    """Read, validate and expand the spec at ``path`` (a file, or a campaign folder);
    ``profiles`` (robot profile files) replace the spec's own."""
    path = Path(path)
    if path.is_dir():
        path = path / SPEC_COPY
    doc = load_toml(path, "campaign spec", ScenarioError)
    if profiles:
        doc["profiles"] = [str(Path(p).resolve()) for p in profiles]
    return parse_spec(doc, str(path), path.parent, source=path, check_families=check_families)


def parse_spec(doc: dict[str, Any], where: str, base: Path, source: Path | None = None,
               check_families: bool = True) -> CampaignSpec:
    """Validate a spec already parsed from TOML and expand it into runs; profile paths are
    relative to ``base``. ``check_families``: generate each family once (seed 0) so that a
    value the generator refuses is reported here, naming the spec's field."""
    rd = TableReader(where, ScenarioError)
    rd.only(doc, TOP_KEYS, "top level")
    name = rd.string(doc, "name", "name")
    if "description" in doc:
        rd.string(doc, "description", "description")
    duration = rd.number(doc, "duration", "duration", positive=True) \
        if "duration" in doc else None
    seeds = _seeds(rd, doc.get("seeds", 1))
    profiles = _profiles(rd, doc.get("profiles", [NO_PROFILE]), base)
    blocks = rd.array_of_tables(doc, "family", required=True)
    world_combos, kill_share, kill_at = _world(rd, rd.table(doc, "world"))
    _check_worlds(world_combos, kill_share, kill_at, where)
    control_combos = _control(rd, rd.table(doc, "control"), where)
    mocap = _mocap(rd, rd.table(doc, "mocap"))

    runs: dict[str, Run] = {}
    checked = 0
    for i, block in enumerate(blocks):
        cases, block_duration = _block(rd, block, f"family[{i}]", duration)
        if check_families:
            checked += _check_cases(cases, f"{where}: family[{i}]", block_duration,
                                    control_combos)
        for case in cases:
            for seed in seeds:
                world_seed = derived_seed("world", seed, _drawn(case))
                killed = bool(np.random.default_rng([world_seed, 1]).random() < kill_share)
                for (profile, _, robot), world, (control, _) in itertools.product(
                        profiles, world_combos, control_combos):
                    desc: dict[str, Any] = {**case, "seed": seed, "duration": block_duration,
                                            "profile": profile, "robot": robot,
                                            "control": control}
                    if world or killed:
                        desc["world"] = {**world, "seed": world_seed}
                    if mocap and (world.get("wheel_slip", 0) > 0
                                  or world.get("encoder_noise", 0) > 0):
                        desc["mocap"] = mocap
                    if killed:
                        desc["kill_at"] = list(kill_at)
                    key = run_key(desc)
                    runs.setdefault(key, Run(key, desc))
    return CampaignSpec(name=name, doc=doc, runs=tuple(runs.values()), source=source,
                        profiles={name: path for name, path, _ in profiles},
                        checked_families=checked)


def _drawn(case: Mapping[str, Any]) -> Mapping[str, Any]:
    """The case as far as it is drawn: a family without the keys that leave its scene as
    it is (``hil.campaign.families.NOT_DRAWN``), so that such variants of a scene meet the same
    world (delays, losses, kill)."""
    family = case.get("family", {})
    kept = {k: v for k, v in family.items() if k not in families_module().NOT_DRAWN}
    return case if len(kept) == len(family) else {**case, "family": kept}


# --- the parts of a spec ------------------------------------------------------------------
def _seeds(rd: TableReader, value: Any) -> range:
    if isinstance(value, list):
        if len(value) != 2:
            raise rd.fail("seeds", f"expected a count or [first, count], got {value!r}")
        first = rd.integer({"s": value[0]}, "s", "seeds[0] (first)", lo=0)
        count = rd.integer({"s": value[1]}, "s", "seeds[1] (count)", lo=1)
        return range(first, first + count)
    return range(rd.integer({"s": value}, "s", "seeds", lo=1))


def _profiles(rd: TableReader, value: Any, base: Path
              ) -> list[tuple[str, Path | None, dict[str, float] | None]]:
    """(name, file, robot table) of each profile; "none": (none, None, None)."""
    from hil.files.robot_profile import load_robot_profile
    items = value if isinstance(value, list) else [value]
    if not items:
        raise rd.fail("profiles", "expected at least one profile (or \"none\")")
    out: list[tuple[str, Path | None, dict[str, float] | None]] = []
    for i, item in enumerate(items):
        where = f"profiles[{i}]" if isinstance(value, list) else "profiles"
        if not isinstance(item, str) or not item:
            raise rd.fail(where, f"expected a profile file or \"none\", got {item!r}")
        if item == NO_PROFILE:
            out.append((NO_PROFILE, None, None))
            continue
        path = base / item
        try:
            params = load_robot_profile(path)
            raw = load_toml(path, "the robot profile")
        except ConfigError as exc:
            raise rd.fail(where, str(exc)) from None
        name = str(raw.get("name") or path.stem)
        if name in [n for n, _, _ in out]:
            raise rd.fail(where, f"a second profile named {name!r}: profile names (their "
                                 f"`name`, else the file name) must differ")
        out.append((name, path, {f.key: getattr(params, f.name)
                                 for f in fields(type(params))}))
    return out


def _values(rd: TableReader, table: Mapping[str, Any], key: str, field: str) -> list[Any]:
    """A key's value, or its list of values to cross."""
    value = table[key]
    values = value if isinstance(value, list) else [value]
    if not values:
        raise rd.fail(field, "an empty list: give a value or a list of values")
    return values


def _number(rd: TableReader, value: Any, field: str, lo: float = 0.0,
            hi: float = math.inf, open_lo: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value):
        raise rd.fail(field, f"expected a finite number, got {value!r}")
    if value < lo or (open_lo and value == lo) or value > hi:
        low = f"> {lo:g}" if open_lo else f">= {lo:g}"
        raise rd.fail(field, f"must be {low}" + (f" and <= {hi:g}" if hi < math.inf else "")
                      + f", got {value!r}")
    return float(value)


def _block(rd: TableReader, block: Mapping[str, Any], where: str, duration: float | None
           ) -> tuple[list[dict[str, Any]], float | None]:
    """The cases of one [[family]] block (each {"family": {...}} or {"micro": name}) and
    its duration."""
    rd.only(block, {*FAMILY_KEYS, "micro", "duration"}, where)
    if "duration" in block:
        duration = rd.number(block, "duration", f"{where}.duration", positive=True)
    if "micro" in block:
        extra = sorted(set(block) & set(FAMILY_KEYS))
        if extra:
            raise rd.fail(f"{where}.micro", f"a block of micro cases takes no family keys "
                                            f"(got {', '.join(extra)}): use another block")
        names = _values(rd, block, "micro", f"{where}.micro")
        known = tuple(getattr(families_module(), "MICRO_CASES", ()))
        for name in names:
            if name not in known:
                raise rd.fail(f"{where}.micro", f"expected one of {', '.join(known)}, "
                                                f"got {name!r}")
        return [{"micro": n} for n in names], duration
    keys = [k for k in FAMILY_KEYS if k in block]
    columns = []
    for k in keys:
        field = f"{where}.{k}"
        values = _values(rd, block, k, field)
        if k in FAMILY_TEXT:
            for v in values:
                if not isinstance(v, str) or not v:
                    raise rd.fail(field, f"expected a string, got {v!r}")
        elif k == "robots":
            values = [rd.integer({"n": v}, "n", field, lo=1) for v in values]
        else:
            values = [_number(rd, v, field) for v in values]
        columns.append(values)
    return [{"family": dict(zip(keys, combo))} for combo in itertools.product(*columns)], \
        duration


def _check_cases(cases: Iterable[Mapping[str, Any]], where: str, duration: float | None,
                 controls: list[tuple[dict[str, Any], ControlParams]]) -> int:
    """Generate each family case once (seed 0) with each controller setting: a value the
    generator refuses is a spec error. Micro cases were checked by name."""
    families = None
    count = 0
    for case, (overrides, control) in itertools.product(cases, controls):
        if "family" not in case:
            continue
        families = families or families_module()
        kwargs = {} if duration is None else {"duration": duration}
        place = where + ("".join(f" ([control] {k} = {v!r})" for k, v in overrides.items())
                         if len(controls) > 1 else "")
        try:
            families.family_doc(case["family"], 0, control=control, where=place, **kwargs)
        except ScenarioError:
            raise
        except (ConfigError, ValueError, KeyError, TypeError) as exc:
            raise ScenarioError(f"{place}: {exc}") from None
        count += 1
    return count


def _world(rd: TableReader, table: Mapping[str, Any]
           ) -> tuple[list[dict[str, float]], float, tuple[float, float]]:
    """The crossed world settings, the kill share and the kill time range."""
    rd.only(table, {*WORLD_KEYS, *KILL_KEYS}, "[world]")
    columns = []
    keys = [k for k in WORLD_KEYS if k in table]
    for k in keys:
        field = f"[world] {k}"
        hi = 1.0 if k in ("link_loss", "detection_dropout") else math.inf
        lo = 1.0 if k == "loss_burst" else 0.0
        columns.append([_number(rd, v, field, lo=lo, hi=hi)
                        for v in _values(rd, table, k, field)])
    combos = [dict(zip(keys, c)) for c in itertools.product(*columns)]
    share = _number(rd, table.get("kill_share", 0.0), "[world] kill_share", hi=1.0)
    kill_at = (0.0, 0.0)
    if share > 0:
        if "kill_at" not in table:
            raise rd.fail("[world] kill_at", "missing: with kill_share > 0, give the range "
                                             "[first, last] of kill times [s]")
        raw = rd.vector(table, "kill_at", "[world] kill_at", 2)
        if not 0 <= raw[0] <= raw[1]:
            raise rd.fail("[world] kill_at", f"expected 0 <= first <= last, got {list(raw)}")
        kill_at = (raw[0], raw[1])
    elif "kill_at" in table:
        rd.vector(table, "kill_at", "[world] kill_at", 2)
    return combos, share, kill_at


def _mocap(rd: TableReader, table: Mapping[str, Any]) -> dict[str, Any]:
    """The pose source of the runs with wrong odometry, checked as a scenario's [mocap]
    (without outages: they name robots)."""
    from firmware_sim.mocap_sim import MocapParams
    if "outage" in table:
        raise rd.fail("[mocap] outage", "outages name robots, which a campaign's families "
                                        "generate; give them in a scenario instead")
    try:
        from_table(MocapParams, table, "[mocap]")
    except ConfigError as exc:
        raise rd.fail("[mocap]", str(exc)) from None
    return dict(table)


def _check_worlds(combos: list[dict[str, float]], kill_share: float,
                  kill_at: tuple[float, float], where: str) -> None:
    """Check each world combination as a scenario's [world] (with a kill when there are
    kills)."""
    from hil.files.scenario import parse_scenario
    for world in combos:
        table: dict[str, Any] = dict(world)
        if not table and kill_share == 0:
            continue
        if kill_share > 0:
            table["kill"] = [{"robot": 1, "at": kill_at[0]}]
        parse_scenario({"name": "world", "duration": 1.0, "formation": {"kind": "line"},
                        "robots": [{"id": 1, "pose": [0.0, 0.0, 0.0]}], "world": table},
                       where)


def _control(rd: TableReader, table: Mapping[str, Any], where: str
             ) -> list[tuple[dict[str, Any], ControlParams]]:
    """The crossed controller overrides, each with the whole ControlParams it makes."""
    allowed = {f.key: f for f in fields(ControlParams)}
    rd.only(table, set(allowed), "[control]")
    keys = [k for k in allowed if k in table]
    columns = [_values(rd, table, k, f"[control] {k}") for k in keys]
    combos = []
    for combo in itertools.product(*columns):
        overrides = dict(zip(keys, combo))
        try:
            params = from_table(ControlParams, overrides, f"{where} [control]")
        except ConfigError as exc:
            raise ScenarioError(str(exc)) from None
        combos.append(({k: getattr(params, allowed[k].name) for k in keys}, params))
    return combos


# --- the campaign folder's copy ---------------------------------------------------------
def write_copy(spec: CampaignSpec, folder: Path) -> Path:
    """Write ``folder/spec.toml``, the spec with its profiles copied into
    ``folder/profiles/``: the folder alone then resumes the campaign and replays its runs
    (the copy expands to the same runs, with the same keys)."""
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / SPEC_COPY
    if spec.source is not None and spec.source.resolve() == out.resolve():
        return out                                  # resumed from the copy itself
    doc = dict(spec.doc)
    if spec.profiles:
        names = []
        for name, path in spec.profiles.items():
            if path is None:
                names.append(NO_PROFILE)
                continue
            target = folder / PROFILES_DIR / f"{name}.toml"
            target.parent.mkdir(exist_ok=True)
            if path.resolve() != target.resolve():
                shutil.copyfile(path, target)
            names.append(f"{PROFILES_DIR}/{name}.toml")
        doc["profiles"] = names
    where = f" (from {spec.source})" if spec.source else ""
    text = (f"# The spec of campaign {spec.name!r}{where}, written by boundswarm campaign;\n"
            f"# its robot profiles are copied into {PROFILES_DIR}/.\n" + toml_text.dumps(doc))
    if not out.exists() or out.read_text() != text:
        tmp = out.with_suffix(".tmp")
        tmp.write_text(text)
        tmp.replace(out)
    return out

