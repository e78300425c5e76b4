"""``python -m tools.eval_render``: the demo on test hosts with render workers (the world spread
over hosts).

    sudo python -m tools.eval_render --robots 3 --seed 1 --workers 2 --out out/render_hosts

Lays one run out on network-namespace hosts as :class:`tools.harness.hosts.HostFleet` does
(router on host 1, the world on host 2, the monitor on host 3, one agent per host from
host 4) and adds ``--workers`` K render workers, each on a host of its own
(``python -m sim.server.render_worker --shard i/K``, on the router's world port): the world keeps
the physics, the clock and the poses, the workers draw every camera picture, zenoh routes
each query to the worker whose key it matches. Secure by default (a fleet made under
``--out``); ``--insecure`` for plain TCP. Prints one line: the monitor's verdict, the
pairs' errors, what each worker and the world served; writes ``render_hosts.json`` into
``--out``. Exit status 0 when the formation is complete. Needs root, iproute2, iptables.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path
from typing import Any

from tools import netns
from tools.harness.fleet import FleetSpec
from tools.harness.fleet_flags import add_agent_arguments, agent_settings


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m tools.eval_render", description=__doc__.split("\n")[0]
    )
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--workers", type=int, default=2, help="render workers, one host each")
    p.add_argument("--timeout", type=float, default=600.0, help="wall limit for the agents (s)")
    p.add_argument("--out", type=Path, default=Path("out/render_hosts"))
    p.add_argument("--prefix", default="nr", help="name prefix of the test hosts")
    p.add_argument("--insecure", action="store_true", help="plain TCP, no signatures")
    add_agent_arguments(p)
    a = p.parse_args(argv)
    a.agent = agent_settings(p, a, timeout=a.agree_timeout)
    if not 1 <= a.robots <= 20 or not 0 <= a.workers <= 4:
        p.error("--robots must be in [1, 20] and --workers in [0, 4]")
    return a


def world_cameras(log: Path) -> int:
    """Camera requests the world itself served, from its summary line."""
    found = re.findall(r"camera=(\d+)", log.read_text(errors="replace")) if log.is_file() else []
    return int(found[-1]) if found else 0


def run(a: argparse.Namespace) -> dict[str, Any]:
    from tools.harness.hosts import HostFleet, Hosts, host_fleet_credentials

    a.out.mkdir(parents=True, exist_ok=True)
    creds = "" if a.insecure else host_fleet_credentials(a.out, a.robots)
    spec = FleetSpec(robots=a.robots, seed=a.seed, agent=a.agent,
                     agent_log_level=a.agent_log_level, journal=True, render_workers=a.workers,
                     insecure=a.insecure, credentials=Path(creds) if creds else None,
                     timeout=a.timeout)  # fmt: skip
    t0 = time.monotonic()
    with HostFleet(spec, a.out, Hosts(a.prefix)) as fleet:
        t_ready = fleet.t_agents - t0
        fleet.wait()
        res = fleet.judge()
    cut = fleet.cut
    served = fleet.render_served()
    return {
        "robots": a.robots,
        "seed": a.seed,
        "workers": a.workers,
        "secure": bool(creds),
        "success": bool(res.get("success")),
        "outcome": res.get("outcome", ""),
        "pairs": res.get("pairs", []),
        "contacts": res.get("contacts"),
        "exit_codes": fleet.exit_codes(),
        "render_served": served,
        "world_served_camera": world_cameras(a.out / "world.log"),
        "wall_ready_s": round(t_ready, 1),
        "wall_s": round(time.monotonic() - t0, 1),
        "cut": cut,
    }


def main(argv: list[str] | None = None) -> int:
    a = parse_args(argv)
    why = netns.unavailable_reason()
    if why is not None:
        print(f"eval_render: test hosts unavailable: {why}", file=sys.stderr)
        return 2
    doc = run(a)
    (a.out / "render_hosts.json").write_text(json.dumps(doc, indent=1))
    pairs = ", ".join(
        f"{p.get('child')}->{p.get('parent')} r_d {100 * p.get('r_d', 0):+.1f}% "
        f"r_phi {100 * p.get('r_phi', 0):+.1f}%"
        for p in doc["pairs"]
    )
    print(
        f"{'SUCCESS' if doc['success'] else 'FAILURE'}: {a.robots} NAOs, seed {a.seed}, "
        f"{a.workers} render worker(s) on hosts of their own; wall {doc['wall_s']} s; "
        f"pairs {pairs or '-'}; contacts {doc['contacts']}; served {doc['render_served']}, "
        f"world {doc['world_served_camera']}"
    )
    return 0 if doc["success"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
