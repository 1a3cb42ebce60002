"""``boundswarm sitl``: the SITL swarm on a scenario, recorded into a run folder."""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.console import Console

from hil.cli.console import summary_table
from hil.cli.exit_codes import EXIT_LOST, EXIT_NOT_RUN, EXIT_OK, EXIT_UNSAFE, BadInput
from hil.cli.options import Subparsers, add_can_options, positive, priority
from hil.sitl.host_cpu import rt_limit

if TYPE_CHECKING:
    from firmware_sim.world import WorldParams
    from hil.sitl.swarm import SitlRun


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("sitl", help="SITL swarm: router, plant, an agent process per robot "
                       "(or per --agents-per-process robots)")
    p.add_argument("scenario", help="scenario file (TOML)")
    p.add_argument("--out", required=True, help="run folder to write")
    p.add_argument("--duration", type=float, help="override the scenario's duration [s]")
    add_can_options(p)
    p.add_argument("--can-base-port", type=int, default=43200,
                   help="udp_multicast: robot ID's bus on port BASE + ID")
    p.add_argument("--robot", metavar="FILE",
                   help="robot profile (robots/*.toml) instead of the scenario's [robot]: the "
                        "emulated drivers' limits and the agents' robot settings (default: "
                        "the scenario's [robot] if it has one, else robots/cart.toml, a real "
                        "robot: 3 m/s, 2 m/s^2)")
    p.add_argument("--robots-per-plant", type=int, default=0,
                   help="robots hosted by one plant process (0: all in one)")
    p.add_argument("--no-live", action="store_true", help="no live status table")
    p.add_argument("--gcs-port", type=int, default=14550,
                   help="UDP port of the ground station on 127.0.0.1 (0: no MAVLink)")
    p.add_argument("--mavlink-key", metavar="FILE",
                   help="MAVLink 2 signing key of every agent (32 bytes, or a passphrase "
                        "as MAVProxy's 'signing key' hashes it); unsigned commands refused")
    p.add_argument("--realtime-priority", type=priority, default=10, metavar="P",
                   help="agents' control loops run SCHED_FIFO at priority P (1..99; needs "
                        "root or RLIMIT_RTPRIO, else a warning; 0: normal scheduling)")
    p.add_argument("--startup-timeout", type=positive, default=40.0, metavar="S",
                   help="seconds for the plant, then for every agent, to come up (a loaded "
                        "machine starts dozens of Python processes slowly)")
    p.add_argument("--record-periods", action="store_true",
                   help="each agent records every period it runs (what it knew and did) in "
                        "OUT/periods/robot_<id>.periods, for replay (docs/formats.md)")
    p.add_argument("--near-radius", type=float, default=0.0, metavar="M",
                   help="agents take full-rate states only from robots within M metres "
                        "and 5 Hz beacons from the rest (0: every robot at full rate)")
    from common.schema import add_arguments
    from hil.sitl.launch import LaunchSettings
    add_arguments(p.add_argument_group("data path (the router's process) and age bound"),
                  LaunchSettings)
    p.set_defaults(func=run)


def sharing_hint(robots: int, cores: int, agents_per_process: int) -> str | None:
    """What to try when data came too old: with a process per robot and more than two
    robots per core, shared processes as the launcher lays them out beyond 8 a core."""
    from hil.sitl.launch import SHARED_GROUPS, shared_per_process
    if agents_per_process > 1 or robots <= 2 * cores:
        return None
    per = shared_per_process(robots, cores, SHARED_GROUPS)
    return (f"{robots} agent processes on {cores} cores: --agents-per-process {per} runs "
            f"them in {-(-robots // per)} (docs/performance.md, \"Agents sharing a "
            f"process\")")


def _percentiles(values: list[float | None]) -> dict[str, float | None]:
    import numpy as np
    a = np.asarray([v for v in values if v is not None], dtype=float)
    if not a.size:
        return {"p50": None, "p99": None, "max": None}
    return {"p50": float(np.percentile(a, 50)), "p99": float(np.percentile(a, 99)),
            "max": float(a.max())}


def _mavlink_key(path: str | None) -> str | None:
    """The absolute path of a readable signing key, BadInput if it is not one."""
    if not path:
        return None
    from transport.mavlink_signing import load_signing_key
    try:
        load_signing_key(Path(path))
    except (OSError, ValueError) as exc:
        raise BadInput(f"--mavlink-key: {exc}") from None
    return str(Path(path).resolve())


def run(args: argparse.Namespace, console: Console) -> int:
    """Check the options, run the swarm, turn its recording into metrics and figures."""
    from agent.settings import near_radius_problem
    from common.schema import ConfigError, section_from_args
    from hil.cli.sim import state_envelope
    from hil.files import run_folder
    from hil.files.figures import draw_figures
    from hil.files.robot_profile import SITL_DEFAULT, load_robot_profile
    from hil.files.scenario import load_scenario
    from hil.sitl.host_cpu import machine_cores
    from hil.sitl.launch import LaunchSettings
    from hil.sitl.report import analyse_recording
    from hil.sitl.swarm import SitlError, SitlOptions, run_sitl
    sc = load_scenario(args.scenario)
    if args.duration:
        sc = dataclasses.replace(sc, duration=args.duration)
    profile = args.robot
    if profile is None and not sc.robot_given and SITL_DEFAULT.is_file():
        profile = str(SITL_DEFAULT)
    if profile:
        sc = dataclasses.replace(sc, robot=load_robot_profile(profile))
        console.print(f"robot: {profile}")
    out = Path(args.out)
    try:
        launch = section_from_args(LaunchSettings, args)
    except ConfigError as exc:
        raise BadInput(str(exc)) from None
    opts = SitlOptions(can_interface=args.can_interface, can_channel=args.can_channel,
                       can_base_port=args.can_base_port, launch=launch,
                       robots_per_plant=args.robots_per_plant, live=not args.no_live,
                       gcs_port=args.gcs_port, near_radius=args.near_radius,
                       mavlink_key=_mavlink_key(args.mavlink_key),
                       realtime_priority=args.realtime_priority,
                       startup_timeout=args.startup_timeout,
                       robot_profile=str(Path(profile).resolve()) if profile else None,
                       record_periods=args.record_periods)
    if problem := near_radius_problem(opts.near_radius, sc.sensing_range):
        raise BadInput(f"--near-radius {problem}")
    state_envelope(console, sc)
    started = time.perf_counter()
    try:
        swarm = run_sitl(sc, out, opts, console)
    except SitlError as exc:
        print(f"boundswarm sitl: {exc}", file=sys.stderr)
        return EXIT_NOT_RUN
    data, result, extra = analyse_recording(out / "run.mcap", sc, killed=swarm.killed)
    metrics = result.summary(sc.name, sc.duration)
    metrics["robot"] = dataclasses.asdict(sc.robot)
    metrics["world"] = dataclasses.asdict(sc.world)
    metrics["mocap"] = dataclasses.asdict(sc.mocap) if sc.mocap is not None else None
    metrics["pose_error"] = extra["pose_error"]
    metrics.update(governor_from_agents(swarm.agent_stats))
    metrics["sitl"] = _sitl_metrics(swarm, extra["epoch"], sc.duration,
                                    time.perf_counter() - started)
    metrics["sitl"]["truth_gap"] = gap = extra["truth_gap"]
    run_folder.write_run(out, metrics, data, sc.source.read_text() if sc.source else None)
    draw_figures(data, sc.obstacles, sc.control.a, sc.control.b, out / run_folder.FIGURES)
    console.print(summary_table(metrics, f"SITL {sc.name}: {len(sc.ids)} agents"))
    console.print(f"world: {describe_world(sc.world)}")
    worst = max(metrics["pose_error"].items(), key=lambda kv: kv[1]["p99"])
    console.print(f"pose error (agent's belief vs truth) p99: worst {worst[1]['p99']:.3f} m "
                  f"(robot {worst[0]}), max {metrics['max_pose_error']:.3f} m; pose source: "
                  + (f"simulated motion capture at {sc.mocap.rate:g} Hz" if sc.mocap
                     else "odometry alone"))
    s = metrics["sitl"]
    console.print(f"deadline misses: {s['deadline_misses_in_mission']} in the mission, "
                  f"{s['deadline_misses']} in all (start-up included), watchdog trips: "
                  f"{sum(s['watchdog_trips'].values())}, lost: {s['lost_processes'] or 'none'}")
    if (worst := s["neighbour_age_worst"]) and worst["p99_ms"] > launch.age_bound * 1e3:
        console.print(f"[yellow]warning: neighbour data too old: robot {worst['robot']}'s "
                      f"neighbour-state age p99 is {worst['p99_ms']:.0f} ms, above the bound "
                      f"of {launch.age_bound * 1e3:g} ms (--age-bound); its oldest 1 % spent "
                      f"most of it in {describe_stage(worst)}: the safety governor brakes "
                      f"on such data, so this run says more about this machine than about "
                      f"the swarm[/yellow]")
        if hint := sharing_hint(len(sc.ids), machine_cores(), swarm.agents_per_process):
            console.print(f"  {hint}")
    if (missing := s["recording"]["states_missing"]):
        console.print(f"[yellow]warning: the recording lacks {sum(missing.values())} of the "
                      f"{s['recording']['states_published']} states published "
                      f"(per robot: {missing})[/yellow]")
    if gap["seconds"] > TRUTH_GAP_WARN:
        console.print(f"[yellow]warning: no truth for {gap['seconds']:.2f} s from t = "
                      f"{gap['at']:.1f} s: this machine stalled or its clock jumped (a paused "
                      f"VM); the robots stood still while their reference moved on, so this "
                      f"run's convergence and distances say nothing about the swarm; run it "
                      f"again[/yellow]")
    if s["clock_step"] > CLOCK_STEP_WARN:
        console.print(f"[yellow]warning: this machine's wall clock stepped by "
                      f"{s['clock_step']:.2f} s against its monotonic clock during the mission "
                      f"(NTP, a paused VM): the formation's reference, set on the wall clock, "
                      f"jumped with it, so this run's convergence says nothing about the "
                      f"swarm; run it again[/yellow]")
    if (s["cpu_steal"] or 0.0) > CPU_STEAL_WARN:
        console.print(f"[yellow]warning: this machine's host stole {s['cpu_steal']:.0%} of "
                      f"its CPU during the mission (a busy virtual machine's host): the "
                      f"agents ran starved, so this run says more about the host than about "
                      f"the swarm; run it again when the host is quieter[/yellow]")
    if s["deadline_misses_in_mission"]:
        console.print(f"[yellow]warning: {s['deadline_misses_in_mission']} control periods "
                      f"missed in the mission: this machine could not run {len(sc.ids)} agents "
                      f"in real time{saturation(s['cpu_busy'])}; late periods and stale "
                      f"neighbour data eat the braking margin, so the safety of this run is "
                      f"not representative (fewer robots, or more cores)[/yellow]")
    console.print(f"metrics: {out / run_folder.METRICS}\nfigures: {out / run_folder.FIGURES}/"
                  f"\nrecording: {out / 'run.mcap'} (Foxglove, mcap tools)")
    if metrics["collisions"]:
        return EXIT_UNSAFE
    return EXIT_LOST if swarm.lost else EXIT_OK


TRUTH_GAP_WARN = 0.25   # s between truth samples (published every 10 ms) worth a warning
CLOCK_STEP_WARN = 0.1   # s of wall-clock step during a mission worth a warning
CPU_STEAL_WARN = 0.15   # share of the CPU a VM's host steals during a mission worth a warning
SATURATED = 0.9         # share of the CPU busy in a mission at which the machine had no room


def saturation(busy: float | None) -> str:
    """Why periods were missed, when the machine was saturated: a clause for the warning."""
    if busy is None or busy < SATURATED:
        return ""
    limit = rt_limit()
    cap = (f"; real-time loops may use {limit:.0%} of each second "
           f"(/proc/sys/kernel/sched_rt_runtime_us), beyond which the kernel stalls them all "
           f"together once a second") if limit is not None else ""
    return f" (its CPUs were {busy:.0%} busy in the mission{cap})"


def describe_world(world: WorldParams) -> str:
    """One line saying which world ran: ``ideal``, or its imperfections and seed."""
    parts = [f"{k} {v:g}" for k, v in dataclasses.asdict(world).items()
             if k not in ("seed", "kill", "loss_burst") and v]
    if world.link_loss and world.loss_burst > 1:
        parts.append(f"loss_burst {world.loss_burst:g}")
    parts += [f"robot {k.robot} killed at {k.at:g} s" for k in world.kill]
    return f"{', '.join(parts)} (seed {world.seed})" if parts else "ideal"


STAGE_NAMES = {"publish_to_router": "publish -> router (the publishing agent's process and "
                                     "its link)",
               "router_to_agent": "router -> the agent's ring (the router and the receiving "
                                   "process)",
               "in_agent": "the agent, held while no newer state came (a beacon-only "
                           "neighbour, or newer states lost or late on the way)"}


def describe_stage(worst: dict) -> str:
    """The stage that made the worst agent's oldest data old, with its mean there [ms]."""
    stage = worst["stage"]
    if stage is None:
        return "an unknown stage (no router timestamps)"
    return f"{STAGE_NAMES[stage]}, {worst['stage_tail_ms'][stage]:.0f} ms on average"


def governor_from_agents(agent_stats: dict) -> dict[str, Any]:
    """The governor's share of the periods in which the law ran (in all and per robot id)
    and the least speed it allowed [m/s], as the agents counted them (the recording has no
    allowed speed); a killed agent wrote no statistics and is not among them."""
    counts = {int(r): st["agent"] for r, st in agent_stats.items()}
    steps = sum(c["law_steps"] for c in counts.values())
    allowed = [c["governor_min_allowed"] for c in counts.values()
               if c["governor_min_allowed"] is not None]
    return {"governor_share": (sum(c["governed"] for c in counts.values()) / steps
                               if steps else 0.0),
            "governor_share_by_robot": {r: c["governor_share"] for r, c in sorted(counts.items())},
            "governor_min_allowed": min(allowed) if allowed else None}


def worst_age(agent_stats: dict) -> dict | None:
    """The agent whose neighbour-state age p99 [ms] is the highest, and ``stage``: of
    agent.node.AGE_STAGES, the one that took most of its oldest 1 % (None without router
    timestamps)."""
    ages = {r: st["agent"]["neighbour_age_ms"]["p99"] for r, st in agent_stats.items()
            if st["agent"]["neighbour_age_ms"]["p99"] is not None}
    if not ages:
        return None
    rid = max(ages, key=lambda r: ages[r])
    stages = agent_stats[rid]["agent"]["neighbour_age_stages_ms"]
    tails = {k: v["tail"] for k, v in (stages or {}).items() if v["tail"] is not None}
    return {"robot": rid, "p99_ms": ages[rid],
            "stage": max(tails, key=lambda k: tails[k]) if tails else None,
            "stage_tail_ms": tails}


def recording_check(run: SitlRun) -> dict[str, Any]:
    """States published by the agents that reported, recorded, and missing per robot (only
    robots with missing states are listed)."""
    published = {r: st["zenoh"]["published"] for r, st in run.agent_stats.items()}
    missing = {r: n - run.recorded.get(r, 0) for r, n in published.items()
               if n > run.recorded.get(r, 0)}
    return {"states_published": sum(published.values()),
            "states_recorded": sum(run.recorded.get(r, 0) for r in published),
            "states_missing": missing}


def _sitl_metrics(run: SitlRun, epoch: float, duration: float, wall: float) -> dict[str, Any]:
    """The ``sitl`` block of metrics.json: loops, links, drivers and CPU of every process."""
    from hil.sitl.report import missed_in
    loops = {rid: st["loop"] for rid, st in run.agent_stats.items()}
    mission_misses = {rid: missed_in(lp, epoch, epoch + duration) for rid, lp in loops.items()}
    return {
        "wall_seconds": round(wall, 2),
        "clock_step": round(run.clock_step, 3),
        "cpu_steal": None if run.cpu_steal is None else round(run.cpu_steal, 3),
        "cpu_busy": None if run.cpu_busy is None else round(run.cpu_busy, 3),
        "agents_reporting": len(run.agent_stats),
        "agent_processes": run.agent_processes,
        "agents_per_process": run.agents_per_process,
        "tick_groups": run.tick_groups,
        "lost_processes": run.lost,
        "killed_at": run.killed,
        "deadline_misses": sum(lp["overruns"] for lp in loops.values()),
        "deadline_misses_in_mission": sum(mission_misses.values()),
        "missed_in_mission_per_agent": mission_misses,
        "period_jitter_ms": _percentiles([lp["jitter"]["p99_ms"] for lp in loops.values()]),
        "jitter_p50_ms_per_agent": {r: lp["jitter"]["p50_ms"] for r, lp in loops.items()},
        "jitter_p99_ms_per_agent": {r: lp["jitter"]["p99_ms"] for r, lp in loops.items()},
        "jitter_max_ms_per_agent": {r: lp["jitter"]["max_ms"] for r, lp in loops.items()},
        "compute_p99_ms_per_agent": {r: lp["compute"]["p99_ms"] for r, lp in loops.items()},
        "neighbour_age_ms": {r: st["agent"]["neighbour_age_ms"]
                             for r, st in run.agent_stats.items()},
        "neighbour_age_stages_ms": {r: st["agent"]["neighbour_age_stages_ms"]
                                    for r, st in run.agent_stats.items()},
        "neighbour_age_worst": worst_age(run.agent_stats),
        "recording": recording_check(run),
        "failsafes": {r: st["failsafe"] for r, st in run.agent_stats.items() if st["failsafe"]},
        "agent_deadlocks": {r: st["agent"]["deadlocks"] for r, st in run.agent_stats.items()
                            if st["agent"]["deadlocks"]},
        "can": {r: st["can"] for r, st in run.agent_stats.items()},
        "zenoh_dropped": {r: {**st["zenoh"]["states"]["dropped"],
                              **{f"beacon_{k}": v for k, v in
                                 st["zenoh"].get("beacons", {}).get("dropped", {}).items()}}
                          for r, st in run.agent_stats.items()},
        "impairment": {r: st["impairment"] for r, st in run.agent_stats.items()
                       if "impairment" in st},
        "watchdog_trips": {k: v for p in run.plant_stats
                           for k, v in p.get("watchdog_trips", {}).items()},
        "plant_overruns": sum(p["overruns"] for p in run.plant_stats),
        "cpu_share": {**{f"agent_{r}": round(st["cpu_seconds"] / st["wall_seconds"], 3)
                         for r, st in run.agent_stats.items()},
                      **{f"plant_{k}": round(p["cpu_seconds"] / p["wall_seconds"], 3)
                         for k, p in enumerate(run.plant_stats)}},
    }
