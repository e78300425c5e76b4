"""One run of the demo: the world, a router for secure TLS fleets, optional render workers
(cameras drawn beside the world), one agent process per robot and optional rogues, observed on the
bus until the agents have finished, then judged (``tools.harness.judge``). ``args`` is
``tools.demo``'s argument namespace.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from tools.harness.judge import summarise
from tools.harness.live import live_sinks
from tools.harness.observe import AgentView, LiveView, Observer, Recorder, observe_for, observer_bus
from tools.harness.procs import (
    Proc,
    claimed_ids,
    fleet_network,
    robot_ids,
    start_agent,
    start_rogues,
    start_router,
    start_world,
    stop,
    wait_ready,
)
from tools.harness.render import served_by, start_render_workers


def route_length(args: argparse.Namespace) -> float:
    """An upper bound of the march's length (m): 0 without a march."""
    if getattr(args, "march", None) is not None:
        return float(args.march)
    if getattr(args, "march_to", None) is not None:
        x, y = (float(v) for v in args.march_to.split(","))
        return math.hypot(x, y) + 2.0  # the leader's target is near the fleet's centre
    return 0.0


def march_room(args: argparse.Namespace, n: int, seed: int, out: Path) -> list[str]:
    """World flags for the run's scenario, written to ``out/scenario.json``: the file of
    ``--scenario``, or the seed's generated one (with ``--isolated``: one robot 2-3 m
    from every other); with a march, its room's half-size enlarged by the route's length
    (sim/scenarios is not changed). [] when the world generates the default scenario
    itself, or when the caller chose a scenario with --world-arg."""
    extra = route_length(args)
    scenario = getattr(args, "scenario", None)
    isolated = bool(getattr(args, "isolated", False))
    headings = getattr(args, "headings", None)
    turned = headings is not None and headings.kind != "aligned"
    if (extra <= 0.0 and scenario is None and not isolated and not turned) or any(
        "--scenario" in a for a in (args.world_arg or [])
    ):
        return []
    from dataclasses import replace

    from sim import scenarios

    sc = scenarios.load(scenario) if scenario is not None else None
    if sc is None:
        sc = scenarios.generate(n, seed, isolated=isolated, headings=headings)
    if extra > 0.0:
        sc = replace(sc, room=min(100.0, math.ceil(2.0 * (sc.room + extra)) / 2.0))
    path = out / "scenario.json"
    scenarios.dump(sc, path)
    return ["--scenario", str(path)]


# ===================================================================== one run


def run_once(args: argparse.Namespace, seed: int, out: Path, quiet: bool = False) -> dict[str, Any]:
    out.mkdir(parents=True, exist_ok=True)
    n = args.robots
    d_e, phi_e = args.d_e, math.radians(args.phi_e_deg)
    net = fleet_network(args, out, n, getattr(args, "scenario_ids", None))
    endpoint = net.endpoint
    t0 = time.monotonic()
    rec = Recorder(out / "run.mcap", sinks=live_sinks(getattr(args, "live", None)))
    obs = Observer(t0)
    procs: list[Proc] = []
    agents: dict[int, Proc] = {}
    result: dict[str, Any] = {"robots": n, "seed": seed, "d_e": d_e, "phi_e_deg": args.phi_e_deg}
    result["noise_scale"] = float(getattr(args, "noise_scale", 1.0))
    result["orientation"] = getattr(args, "orientation", "pca")
    result["strategy"] = getattr(args, "strategy", "default")
    shape = getattr(args, "shape", None)
    result["shape_spec"] = str(getattr(shape, "source", shape) or "pyramid")
    result["shape_digest"] = getattr(shape, "digest", "")
    if getattr(args, "scenario", None) is not None:
        result["scenario"] = str(args.scenario)
    if getattr(args, "isolated", False):
        result["isolated"] = True
    result["headings"] = str(getattr(args, "headings", None) or "aligned")
    if getattr(args, "agent_arg", None):
        result["agent_args"] = [f"{i}:{a}" for i, a in args.agent_arg]
    if getattr(args, "march", None) is not None:
        result["route"] = {"distance": float(args.march)}
    elif getattr(args, "march_to", None) is not None:
        result["route"] = {"to": [float(v) for v in args.march_to.split(",")]}
    err = sys.stderr
    result["secure"] = bool(net.credentials)
    result["tls"] = net.router
    if net.router:
        procs.append(start_router(endpoint, out, net.flags))
    world_net = ["--connect" if net.router else "--listen", endpoint, *net.flags]
    bus = observer_bus(net)
    try:
        naoqi = ["--naoqi"] if getattr(args, "body", "") == "naoqi" else []
        noise = [f"--noise-scale={getattr(args, 'noise_scale', 1.0):g}"]
        room = march_room(args, n, seed, out)
        if getattr(args, "obstacles", 0) > 0:  # 5.1.2: obstacles on the straight paths
            from tools.obstacle_scenario import obstacle_world_args

            room = obstacle_world_args(n, seed, args.obstacles, d_e, phi_e, out, result)
        kind = getattr(args, "renderer", None)  # tools.demo --renderer: world and workers
        drawn = ["--renderer", kind] if kind else []
        world = start_world(
            n,
            seed,
            endpoint,
            out,
            [*room, *(args.world_arg or []), *naoqi, *noise, *drawn],
            world_net,
        )
        procs.append(world)

        def take() -> None:
            for ev in bus.drain(0.1):
                obs.take_event(ev, rec)

        wait_ready(world, args.world_timeout, take)
        result["wall_world_ready"] = time.monotonic() - t0
        workers = int(getattr(args, "render_service", 0) or 0)
        if workers > 0:  # cameras drawn by render workers, not the world
            procs.extend(
                start_render_workers(
                    workers, ["--connect", endpoint, *net.flags], out, renderer=kind
                )
            )
            result["render_workers"] = workers
            result["wall_render_ready"] = time.monotonic() - t0
        ids = robot_ids(world.lines, n)
        result["ids"] = ids
        # with --body naoqi: each robot's virtual NAO, "sim naoqi robot=ID url=URL"
        args.nao_urls = {
            int(ln.split("robot=")[1].split()[0]): ln.split("url=")[1].strip()
            for ln in world.lines
            if ln.startswith("sim naoqi ")
        }
        agent_net = ["--connect", endpoint, *net.flags]
        agents.update({i: start_agent(i, n, endpoint, out, args, agent_net) for i in ids})
        procs.extend(agents.values())
        rogues = (
            start_rogues(net, out, ids, args.rogue, args.rogue_replay) if args.rogue > 0 else []
        )
        result["rogues_started"] = [r.name for r in rogues]
        live = LiveView(err, ids) if not quiet else None
        deadline = time.monotonic() + args.timeout
        while True:
            for ev in bus.drain(0.1):
                obs.take_event(ev, rec)
            if live is not None:
                live.update(obs, time.monotonic() - t0)
            if all(p.popen.poll() is not None for p in agents.values()):
                break
            if time.monotonic() > deadline:
                result["timeout"] = f"agents still running after {args.timeout:g} s"
                break
        observe_for(bus, obs, rec, 1.5)  # the last truth after the motions
        if live is not None:
            live.update(obs, time.monotonic() - t0, force=True)
        result["wall_total"] = time.monotonic() - t0
        result["rejected"] = {
            "bus": bus.stats.rejected, "untrusted": bus.stats.untrusted,
            "observer": obs.rejected,
        }  # fmt: skip
        result["dropped"] = bus.stats.dropped
        for r in rogues:  # they stop by themselves after --rogue seconds
            with contextlib.suppress(subprocess.TimeoutExpired):
                r.popen.wait(max(1.0, args.rogue + 30.0 - (time.monotonic() - t0)))
            stop(r)
    finally:
        for p in reversed(procs):
            stop(p)
        bus.close()
        rec.close()
    if result.get("render_workers"):
        result["render_served"] = served_by(out, result["render_workers"])
    if getattr(args, "auto_ids", False):
        agents = claimed_ids(agents, out)
        result["claimed_ids"] = sorted(agents)
    for i, p in agents.items():
        obs.agents.setdefault(i, AgentView()).exit_code = p.popen.returncode
    return summarise(obs, result, out, sorted(agents), d_e, phi_e, quiet)
