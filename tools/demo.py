"""``python -m tools.demo``: the world and N agents as separate processes, end to end.

    python -m tools.demo --robots 3 --seed 1 [--json FILE] [--out DIR]
    python -m tools.demo --robots 3 --seed 1 --batch 20 [--out DIR]   (seeds 1..20)
    python -m tools.demo --scenario sim/scenarios/paper3.json    (robots from the file)
    python -m tools.demo --robots 4 --orientation cp [--strategy S] [--isolated]
    python -m tools.demo --robots 6 --shape wedge     (or line, column, circle, grid, FILE)
    python -m tools.demo --robots 8 --reshape line --reshape wedge   (pyramid, then line, wedge)
    python -m tools.demo --view     (watch it live in a browser: http://127.0.0.1:8080/)

Starts ``python -m sim`` and N ``python -m agent`` processes (peers over loopback
TCP, no multicast so that concurrent runs never mix), shows one live status line per
agent, and when the agents have finished prints the result table from ground truth:
per child–parent pair of the pyramid the distance and the angle off the pyramid's
backward axis, r_d = (d - d_e)/d_e and r_φ = (φ - φ_e)/φ_e (NAO paper 5.1.1; for
another shape the same against the pair's distance and angle in the shape's tree);
collisions; wall and sim time per phase; bytes each agent published; whether every
agent computed the same plan digest. Writes ``DIR/result.json``, a Fig. 16/24-like
``DIR/formation.png`` (starts, walked paths, final pyramid, ids) and ``DIR/run.mcap``
(truth, statuses, records, digests, contacts; replay with ``python -m tools.replay``).

Success (exit 0): every agent exited 0, identical plan digests, zero contacts, and
every pair within |r_d| <= 12.5 % and |r_φ| <= 30 %.

Marching in formation: ``--march D`` (metres along the pyramid's axis) or ``--march-to
X,Y`` (common frame) is given to every agent; after ``hold`` the fleet marches. The
world's room is then enlarged by the route's length (the demo generates the seed's
scenario, widens its room and starts the world with ``--scenario``), so the march
never meets a wall. The pairs are judged at the end of the march; the leader's measured
displacement (``march_distance``) must be within 10 % of the route (|displacement − V|
<= 0.1·|V|); the worst |r_d| and |r_φ| over the truth samples of the march are
reported (``march_worst_abs_r_d``, ``march_worst_abs_r_phi``); the figure shows the
pyramid at the start of the march (grey) and at its end, and the tracks in between.

Reshaping on command (docs/formation.md "Reshaping"): ``--reshape SHAPE`` (repeat it:
``--reshape line --reshape wedge``) makes the demo the operator too: once the fleet
holds, it sends the signed command for each shape in turn (the ``operator`` key of the
run's fleet), waits until the fleet holds it, and prints each transition's sim and wall
time (``reshapes`` in the result); the agents stay ``--reshape-wait`` s (default 20) for
a command, and the ground truth is judged against the last shape. Success also needs
every reshape held.

Fleet parameters: ``--d-e``, ``--phi-e-deg``, ``--orientation pca|cp``, ``--strategy`` and
``--shape NAME|FILE`` (a built-in or a formation file, docs/formation.md "Shapes") are
given to every agent and used by the evaluator's plan and its judge of the truth. ``--scenario FILE`` starts the
world on a scenario file (robot count and ids from the file); ``--isolated`` generates
the seed's scenario with one robot 2-3 m from every other (``sim.scenarios.generate``).

Camera frames for viewers: the demo's agents run with ``--publish-camera`` (turn it off
with ``--no-publish-camera``), so ``run.mcap`` holds each robot's camera thumbnails with
their detections (``/nao/ID/camera``, ``/nao/ID/camera/annotations``); the table gives
their kB/s per robot, apart from the fleet's own bytes.

Watching (docs/view.md): ``--live [HOST:PORT]`` serves the run's scene over the
Foxglove WebSocket protocol (default 127.0.0.1:8765) for Foxglove or Lichtblick;
``--view [HOST:PORT]`` also serves the page in the browser (default 127.0.0.1:8080) and
opens it where there is a desktop.

This tool is an evaluator: it reads ground truth (``world/truth/**``); agents never do.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from agent.wire import INSECURE_WARNING
from tools.harness.fleet import FleetSpec, run_fleet
from tools.harness.fleet_flags import add_fleet_arguments, fleet_spec
from tools.harness.progress import Progress
from tools.harness.view.live import DEFAULT_LIVE, serve
from tools.harness.view.webpage import DEFAULT_WEB, serve_page

# ===================================================================== CLI


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The demo's flags; ``.spec`` is the run they describe (:class:`FleetSpec`)."""
    p = argparse.ArgumentParser(prog="python -m tools.demo", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=Path("out/demo"))
    p.add_argument("--json", type=Path, default=None, help="also write the result JSON here")
    p.add_argument("--batch", type=int, default=0, help="run seeds seed..seed+K-1, print totals")
    add_fleet_arguments(p)
    p.add_argument(
        "--view",
        nargs="?",
        const=DEFAULT_WEB,
        default=None,
        metavar="HOST:PORT",
        help=(
            f"watch the run in a browser: serves the page on {DEFAULT_WEB} and the live "
            f"server (--live, default {DEFAULT_LIVE})"
        ),
    )
    a = p.parse_args(argv)
    if a.view is not None and a.live is None:
        a.live = DEFAULT_LIVE
    if a.scenario is not None and a.batch:
        p.error("--scenario fixes the robots and the seed: no --batch")
    if a.batch < 0:
        p.error("--batch must be >= 0")
    a.spec = fleet_spec(p, a)
    return a


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    if args.insecure:
        print(INSECURE_WARNING, file=sys.stderr)
    page = None
    if args.view is not None:
        page = serve_page(args.view, serve(args.live).url)
        open_browser(page.url)
    try:
        if args.batch:
            return batch(args)
        try:
            result = run_fleet(args.spec, args.out, quiet=False)
        except RuntimeError as exc:
            print(f"demo failed: {exc}", file=sys.stderr)
            return 1
    finally:
        if page is not None:
            page.close()
    for t in result.get("reshapes", []):
        print(
            f"reshape {t['command']} to {t['shape']}: {t['outcome']} ({t['detail']}); "
            f"sim {t['sim_s']:.1f} s, wall {t['wall_s']:.1f} s"
        )
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2, default=float))
    return 0 if result["success"] else 1


def open_browser(url: str) -> None:
    """Open ``url`` in the desktop's browser, where there is a desktop (never a terminal
    browser: the status lines are on that terminal)."""
    desktop = sys.platform in ("darwin", "win32") or any(
        os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY")
    )
    if desktop:
        import webbrowser

        with contextlib.suppress(Exception):  # no browser: the URL is printed anyway
            webbrowser.open(url, new=2)


def batch(args: argparse.Namespace) -> int:
    results = []
    bar = Progress(args.batch, "batch")
    spec: FleetSpec = args.spec
    for k in range(args.batch):
        seed = args.seed + k
        try:
            r = run_fleet(replace(spec, seed=seed), args.out / f"seed-{seed:03d}")
        except RuntimeError as exc:
            r = {"seed": seed, "success": False, "error": str(exc), "contacts": -1,
                 "identical_digests": False, "pairs": []}  # fmt: skip
        results.append(r)
        bar.step(
            f"seed {seed} ({args.robots} robots): {'ok' if r['success'] else 'FAIL'} "
            f"max|r_d| {r.get('max_abs_r_d', math.nan):.1%} max|r_phi| {r.get('max_abs_r_phi', math.nan):.1%} "
            f"contacts {r.get('contacts')} digests {'same' if r.get('identical_digests') else 'DIFFER'} "
            f"march {r.get('march_distance', math.nan):.2f} m worst|r_d| {r.get('march_worst_abs_r_d', math.nan):.1%} "
            f"wall {r.get('wall_total', math.nan):.0f}s"
        )
    ok = sum(1 for r in results if r["success"])
    collisions = sum(1 for r in results if r.get("contacts", -1) != 0)
    same = sum(1 for r in results if r.get("identical_digests"))
    completed = sum(1 for r in results if set(r.get("final_phase", {}).values()) == {"done"})
    rds = [abs(p["r_d"]) for r in results for p in r.get("pairs", [])]
    rps = [abs(p["r_phi"]) for r in results for p in r.get("pairs", [])]
    walls = [r["wall_total"] for r in results if "wall_total" in r]
    exch = [v for r in results for v in r.get("exchange_bytes", {}).values()]
    tot = [b["total"] for r in results for b in r.get("bytes", {}).values()]
    summary: dict[str, Any] = {
        "robots": args.robots, "runs": len(results), "success": ok, "completed": completed,
        "runs_with_contacts": collisions, "identical_digests": same,
        "median_abs_r_d": float(np.median(rds)) if rds else math.nan,
        "max_abs_r_d": max(rds, default=math.nan),
        "median_abs_r_phi": float(np.median(rps)) if rps else math.nan,
        "max_abs_r_phi": max(rps, default=math.nan),
        "wall_median": float(np.median(walls)) if walls else math.nan,
        "exchange_bytes_max": max(exch, default=0), "published_bytes_max": max(tot, default=0),
    }  # fmt: skip
    if args.march is not None or args.march_to is not None:
        md = [r["march_worst_abs_r_d"] for r in results if "march_worst_abs_r_d" in r]
        mp = [r["march_worst_abs_r_phi"] for r in results if "march_worst_abs_r_phi" in r]
        me = [r["march_error"] for r in results if "march_error" in r]
        summary.update({
            "march_worst_abs_r_d": max(md, default=math.nan),
            "march_worst_abs_r_phi": max(mp, default=math.nan),
            "march_error_max": max(me, default=math.nan),
            "contacts_total": sum(r.get("contacts", 0) for r in results if r.get("contacts", 0) > 0),
        })  # fmt: skip
    print(f"\nbatch: {args.robots} robots, seeds {args.seed}..{args.seed + args.batch - 1}")
    for name, val in summary.items():
        print(f"  {name:22s} {val:.3f}" if isinstance(val, float) else f"  {name:22s} {val}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "batch.json").write_text(
        json.dumps({"summary": summary, "runs": results}, indent=2, default=float)
    )
    if args.json is not None:
        args.json.write_text(
            json.dumps({"summary": summary, "runs": results}, indent=2, default=float)
        )
    return 0 if ok == len(results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
