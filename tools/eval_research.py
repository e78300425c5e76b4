"""``python -m tools.eval_research``: re-search (NAO paper 4.1.3 rule 2) over world seeds.

    python -m tools.eval_research [--scenario sim/scenarios/research_found.json]
                                  [--seeds 1,2,3] [--research-rounds K] [--out DIR]

Runs the fleet (:class:`tools.harness.fleet.Fleet`: world + one agent process per robot) on
a scenario file once per seed, with the scenario's ``seed`` (textures and the world's motion noise) replaced.
Prints per seed the outcome, the (re-)search round of the agreed records, the robots'
exit codes, the wall time in total and in the ``explore`` phase, and the stop reason;
writes ``DIR/research.json``, each run's ``DIR/seed-N/formation.png`` and
``DIR/research.png`` (wall time per seed, coloured by outcome).
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

from agent.config import AgentConfig
from sim import scenarios
from tools.harness.fleet import FleetSpec, run_fleet
from tools.harness.view.live import add_live_arguments, check_live_argument


def run(
    scenario: Path, seeds: list[int], rounds: int | None, out: Path, live: str | None = None
) -> list[dict[str, Any]]:
    base = scenarios.load(scenario)
    rows = []
    for seed in seeds:
        d = out / f"seed-{seed}"
        d.mkdir(parents=True, exist_ok=True)
        sc = scenarios.from_dict({**scenarios.to_dict(base), "seed": seed})
        scenarios.dump(sc, d / "scenario.json")
        # evaluation: the fleet's own traffic only (no camera frames for viewers)
        agent = AgentConfig(robot_id=0)
        if rounds is not None:
            agent = replace(agent, research_rounds=rounds)
        spec = FleetSpec(
            robots=len(sc.robots),
            seed=seed,
            agent=agent,
            world_args=(f"--scenario={d / 'scenario.json'}",),
            live=live,  # every run on one live server
        )
        try:
            r = run_fleet(spec, d)
        except RuntimeError as exc:
            r = {"success": False, "errors": {"demo": str(exc)}}
        rows.append(
            {
                "seed": seed,
                "success": bool(r.get("success")),
                "rounds": sorted(set(r.get("record_rounds", {}).values())),
                "exit_codes": r.get("exit_codes", {}),
                "wall_total": r.get("wall_total", math.nan),
                "wall_explore": r.get("phases", {}).get("explore", {}).get("wall_max", 0.0),
                "max_abs_r_d": r.get("max_abs_r_d", math.nan),
                "max_abs_r_phi": r.get("max_abs_r_phi", math.nan),
                "contacts": r.get("contacts", -1),
                "reason": next(iter(set(r.get("errors", {}).values())), ""),
            }
        )
        row = rows[-1]
        print(
            f"seed {seed:3d}: {'success' if row['success'] else 'FAILURE':7s} "
            f"rounds {row['rounds']} wall {row['wall_total']:6.1f} s "
            f"(explore {row['wall_explore']:5.1f} s) max|r_d| {row['max_abs_r_d']:.1%} "
            f"contacts {row['contacts']} {row['reason'][:90]}",
            flush=True,
        )
    return rows


def plot(rows: list[dict[str, Any]], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.5))
    xs = [str(r["seed"]) for r in rows]
    colours = ["tab:green" if r["success"] else "tab:red" for r in rows]
    ax.bar(xs, [r["wall_total"] for r in rows], color=colours, alpha=0.8, label="total")
    ax.bar(xs, [r["wall_explore"] for r in rows], color="grey", alpha=0.8, label="explore phase")
    ax.set_xlabel("world seed")
    ax.set_ylabel("wall time (s)")
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tools.eval_research", description=__doc__)
    p.add_argument("--scenario", type=Path, default=scenarios.builtin("research_found"))
    p.add_argument("--seeds", default="1,2,3", help="comma-separated world seeds")
    p.add_argument("--research-rounds", type=int, default=None)
    p.add_argument("--out", type=Path, default=Path("out/research"))
    add_live_arguments(p)
    a = p.parse_args(argv)
    check_live_argument(p, a.live)
    try:
        seeds = [int(s) for s in a.seeds.split(",") if s.strip()]
    except ValueError:
        p.error(f"--seeds wants integers, got {a.seeds!r}")
    if not seeds:
        p.error("--seeds is empty")
    rows = run(a.scenario, seeds, a.research_rounds, a.out, a.live)
    ok = sum(r["success"] for r in rows)
    walls = sorted(r["wall_total"] for r in rows)
    print(
        f"{a.scenario.name}: {ok}/{len(rows)} succeeded, median wall {walls[len(walls) // 2]:.1f} s"
    )
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "research.json").write_text(json.dumps(rows, indent=2, default=float))
    plot(rows, a.out / "research.png", f"{a.scenario.name}: {ok}/{len(rows)} succeeded")
    return 0 if ok == len(rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
