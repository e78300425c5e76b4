"""``python -m tools.plan``: the planner's command-line contract (JSON records in, JSON plan out).

Reads one JSON scenario on stdin, writes one JSON plan on stdout, exit code 0; bad
input gives exit code 2 and a one-line reason on stderr.

Input::

    {"robots": [{"id": 7, "x": 0.1, "y": 2.0}, ...], "d_e": 2.0,
     "phi_e_deg": 30, "radius": 0.2, "strategy": "paper|optimal|capt|bottleneck|banded|default",
     "orientation": "pca|cp", "obstacles": [{"x": .., "y": ..}]}

Output (everything in the input's frame)::

    {"leader": 7, "axis_rad": a, "targets": [{"id", "x", "y", "order", "parent"}],
     "trajectories": [{"id", "heading_rad", "distance", "via": [[x, y], ...],
                       "wave": k, "after": [ids], "after_at": [m]}],
     "waves": [[7, 3], [9], ...], "digest": "hex", "strategy": "optimal"}

A robot may start once every robot of its ``after`` list has walked past the arc length
of its path given at the same place in ``after_at`` (its release point; empty: once it
holds its slot), the dependency rule of ``agent.core.formation.waves.execution``; waiting for
every robot of the earlier waves to hold is safe too.

``--png FILE`` also draws the plan (starts, paths coloured by wave, slots, leader, axis).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

import numpy as np

from agent.core.formation.params import PlanParams
from agent.core.formation.plan import Plan, plan_from_positions

_KEYS = {"robots", "d_e", "phi_e_deg", "radius", "strategy", "orientation", "obstacles"}


class InputError(ValueError):
    pass


def _num(obj: dict[str, Any], key: str, where: str) -> float:
    if key not in obj:
        raise InputError(f"{where}: missing {key!r}")
    v = obj[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise InputError(f"{where}: {key!r} must be a finite number, got {v!r}")
    return float(v)


def parse_scenario(
    doc: Any,
) -> tuple[list[int], np.ndarray, PlanParams, np.ndarray]:
    """Validate a scenario document; returns (ids, positions, params, obstacles)."""
    if not isinstance(doc, dict):
        raise InputError("the scenario must be a JSON object")
    unknown = sorted(set(doc) - _KEYS)
    if unknown:
        raise InputError(f"unknown keys {unknown}; allowed: {sorted(_KEYS)}")
    robots = doc.get("robots")
    if not isinstance(robots, list) or not robots:
        raise InputError("'robots' must be a non-empty list of {id, x, y}")
    ids: list[int] = []
    pos: list[tuple[float, float]] = []
    for k, r in enumerate(robots):
        where = f"robots[{k}]"
        if not isinstance(r, dict):
            raise InputError(f"{where} must be an object with id, x, y")
        rid = r.get("id")
        if isinstance(rid, bool) or not isinstance(rid, int) or rid < 0:
            raise InputError(f"{where}: 'id' must be a non-negative integer, got {rid!r}")
        ids.append(rid)
        pos.append((_num(r, "x", where), _num(r, "y", where)))
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise InputError(f"duplicate robot ids {dup}")
    d_e = _num(doc, "d_e", "scenario")
    phi = (
        math.radians(_num(doc, "phi_e_deg", "scenario")) if "phi_e_deg" in doc else PlanParams.phi_e
    )
    radius = _num(doc, "radius", "scenario") if "radius" in doc else 0.2
    strategy = doc.get("strategy", "default")
    orientation = doc.get("orientation", "pca")
    for name, val in (("strategy", strategy), ("orientation", orientation)):
        if not isinstance(val, str):
            raise InputError(f"{name!r} must be a string, got {val!r}")
    obstacles = doc.get("obstacles", [])
    if not isinstance(obstacles, list):
        raise InputError("'obstacles' must be a list of {x, y}")
    obs: list[tuple[float, float]] = []
    for k, o in enumerate(obstacles):
        if not isinstance(o, dict):
            raise InputError(f"obstacles[{k}] must be an object with x, y")
        obs.append((_num(o, "x", f"obstacles[{k}]"), _num(o, "y", f"obstacles[{k}]")))
    try:
        params = PlanParams(
            d_e=d_e, phi_e=phi, radius=radius, strategy=strategy, orientation=orientation
        )
    except ValueError as exc:
        raise InputError(str(exc)) from None
    return (
        ids,
        np.array(pos, dtype=np.float64),
        params,
        np.array(obs, dtype=np.float64).reshape(-1, 2),
    )


def plan_to_json(plan: Plan) -> dict[str, Any]:
    targets = [r.target.tolist() for r in plan.robots]
    return {
        "leader": plan.leader,
        "axis_rad": plan.axis,
        "targets": [
            {
                "id": r.robot_id,
                "x": t[0],
                "y": t[1],
                "order": r.order,
                "parent": r.parent,
            }
            for r, t in zip(plan.robots, targets, strict=True)
        ],
        "trajectories": [
            {
                "id": r.robot_id,
                "heading_rad": r.heading,
                "distance": r.distance,
                "via": [v.tolist() for v in r.via],
                "wave": r.wave,
                "after": list(r.after),
                "after_at": list(r.after_at),
            }
            for r in plan.robots
        ],
        "waves": [list(w) for w in plan.waves],
        "digest": plan.digest,
        "strategy": plan.strategy,
    }


def draw_plan(plan: Plan, path: str, title: str = "", radius: float = 0.2) -> None:
    """PNG of a plan: starts (red), paths coloured by wave, slots (black rings), leader (green)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 7))
    draw_on(ax, plan, radius)
    ax.set_title(
        title or f"{len(plan.robots)} robots, {len(plan.waves)} waves, leader {plan.leader}"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def draw_on(ax: Any, plan: Plan, radius: float = 0.2, labels: bool | None = None) -> None:
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    n_waves = max(len(plan.waves), 1)
    cmap = plt.get_cmap("viridis")
    show_labels = len(plan.robots) <= 30 if labels is None else labels
    for r in plan.robots:
        p = r.path()
        col = cmap(r.wave / max(n_waves - 1, 1))
        ax.plot(p[:, 0], p[:, 1], "-", color=col, lw=1.2, zorder=2)
        ax.add_patch(Circle(tuple(r.start), radius, color="tab:red", alpha=0.5, zorder=3))
        is_lead = r.robot_id == plan.leader
        ax.add_patch(
            Circle(
                tuple(r.target),
                radius,
                fill=is_lead,
                facecolor="tab:green",
                edgecolor="k",
                lw=1.0,
                zorder=4,
            )
        )
        if show_labels:
            ax.annotate(
                str(r.robot_id), tuple(r.start), fontsize=7, ha="center", va="center", zorder=5
            )
    for o in plan.obstacles:
        ax.add_patch(Circle(tuple(o), radius, color="tab:blue", alpha=0.8, zorder=3))
    lead = plan.robot(plan.leader)
    span = (
        float(np.ptp(np.vstack([plan.starts(), plan.targets()]), axis=0).max())
        if len(plan.robots) > 1
        else 1.0
    )
    L = 0.15 * max(span, 1.0)
    ax.annotate(
        "",
        xy=(lead.target[0] + L * math.cos(plan.axis), lead.target[1] + L * math.sin(plan.axis)),
        xytext=tuple(lead.target),
        arrowprops={"arrowstyle": "->", "color": "tab:green", "lw": 2},
    )
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.plan", description=__doc__.splitlines()[0])
    ap.add_argument("--png", help="also draw the plan into this PNG file")
    args = ap.parse_args(argv)
    try:
        text = sys.stdin.read()
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(
                f"invalid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}"
            ) from None
        ids, pos, params, obs = parse_scenario(doc)
        plan = plan_from_positions(ids, pos, params, obstacles=obs)
    except ValueError as exc:
        print(f"error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    if args.png:
        draw_plan(plan, args.png, radius=params.radius)
    sys.stdout.write(json.dumps(plan_to_json(plan)) + "\n")  # one write: fast at 10^5+
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
