"""``python -m tools.montecarlo``: the NAO paper's section 5.1 as numbers and figures.

For every noise level, strategy and common-frame method, ``--runs`` seeded runs (100 by
default) of ``--robots`` robots (10) with the paper's d_e = 2 m, φ_e = 30°, r = 0.2 m:

1. a random start (uniform in a square, starts >= 0.6·d_e apart, every robot sees the
   others within 1.5·d_e, the fleet connected through what it sees);
2. records with the paper's relative-position noise: each detection moved by a
   uniform random vector in a disc of radius δd_ij (footnote 2: "relative angle errors
   set unlimitedly", i.e. a position error within r_δ = max δd_ij);
3. the full pipeline ``plan_from_records`` (neighbour check, common frame, pyramid,
   assignment, waves);
4. execution with trajectory noise: every leg (η_i, d_i) walked as
   (η_i + δη_i, d_i + δd_i), δd_i uniform in ±δd, δη_i uniform in ±δη, from the
   robot's *true* start;
5. measures: r_d = (d_ij - d_e)/d_e and r_φ = (φ_ij - φ_e)/φ_e for every child-parent
   pair of the final (true) positions (φ_ij = angle of the child off the backward
   axis); crossings among the planned straight start->target segments (Lemma 1);
   safety violations of the planned paths and of the executed ones (same waves);
   total planned path over the exact min-sum optimum for the same estimated starts;
   mean error of the estimated common frame; the makespan (robots at unit speed) over
   CAPT's (the longest straight path of the min-sum-of-squares assignment to the same
   slots), under the dependency rule (a robot starts when the robots of its ``after``
   list hold) and under the wave rule (a wave starts when the previous one holds).

Noise levels (paper 5.1.1): ``none``; ``records`` (δd_ij = 0.1·d_e, case (1));
``paper`` (δd_ij = δd_i = 0.1·d_e, δη_i = 0.05·φ_e, case (2)).

``--json`` prints the summary as one JSON object; figures like Fig. 15 (histograms),
Fig. 16 (6, 10, 15 robots) and Fig. 17 (obstacles) go to ``--out`` (PNG).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from agent.core.formation.frame.common_frame import build_common_frame
from agent.core.formation.frame.neighbour_check import identify_neighbours
from agent.core.formation.frame.records import NeighborRecord
from agent.core.formation.params import PlanParams
from agent.core.formation.paths.assignment import optimal_assignment
from agent.core.formation.paths.geometry import paths_cross
from agent.core.formation.plan import Plan, plan_from_positions, plan_from_records
from agent.core.formation.shape.pyramid import parent_of
from agent.core.formation.waves.execution import (
    capt_makespan,
    dependency_makespan,
    path_lengths,
    wave_makespan,
)
from agent.core.formation.waves.safety import check_safety
from agent.core.perception.sighting_noise import SightingNoise

D_E = 2.0
PHI_E = math.radians(30)
RADIUS = 0.2
LEVELS: dict[str, tuple[float, float, float]] = {
    # name: (δd_ij, δd_i, δη_i) as fractions of d_e, d_e, φ_e
    "none": (0.0, 0.0, 0.0),
    "records": (0.1, 0.0, 0.0),
    "paper": (0.1, 0.1, 0.05),
}
STRATEGIES = ("paper", "optimal", "capt", "default")
FRAMES = ("bfs", "lsq")


def random_start(rng: np.random.Generator, n: int, d_e: float = D_E) -> np.ndarray:
    """Starts >= 0.6 d_e apart, connected under the 1.5 d_e visibility, in a square."""
    spacing, seen = 0.6 * d_e, 1.5 * d_e
    side = max(math.sqrt(n) * 0.9 * d_e, d_e)
    for _ in range(1000):
        pts: list[np.ndarray] = []
        tries = 0
        while len(pts) < n and tries < 20000:
            tries += 1
            p = rng.uniform(0.0, side, 2)
            if all(math.hypot(*(p - q)) >= spacing for q in pts):
                pts.append(p)
        if len(pts) < n:
            side *= 1.1
            continue
        pos = np.array(pts)
        d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).T)
        adj = d <= seen
        seen_set, stack = {0}, [0]
        while stack:
            u = stack.pop()
            for v in np.flatnonzero(adj[u]):
                if int(v) not in seen_set:
                    seen_set.add(int(v))
                    stack.append(int(v))
        if len(seen_set) == n:
            return pos
    raise RuntimeError("could not draw a connected start")  # pragma: no cover


def noisy_records(
    rng: np.random.Generator, pos: np.ndarray, noise: float, seen: float
) -> list[NeighborRecord]:
    recs = []
    for i in range(pos.shape[0]):
        rel = pos - pos[i]
        d = np.hypot(rel[:, 0], rel[:, 1])
        mask = (d > 0) & (d <= seen)
        nb = rel[mask]
        if noise > 0 and nb.shape[0]:
            r = noise * np.sqrt(rng.uniform(0, 1, nb.shape[0]))
            a = rng.uniform(-math.pi, math.pi, nb.shape[0])
            nb = nb + np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
        recs.append(NeighborRecord(i, nb))
    return recs


def execute(
    rng: np.random.Generator, plan: Plan, true_start: np.ndarray, dd: float, deta: float
) -> list[np.ndarray]:
    """Walk every leg with noise from the true start; returns executed polylines."""
    out = []
    for k, r in enumerate(plan.robots):
        p = true_start[k].copy()
        pts = [p.copy()]
        prev = r.start
        for w in r.waypoints():
            leg = w - prev
            dist = math.hypot(leg[0], leg[1])
            prev = w
            if dist < 1e-12:
                continue
            eta = math.atan2(leg[1], leg[0]) + rng.uniform(-deta, deta)
            dist = max(dist + rng.uniform(-dd, dd), 0.0)
            p = p + dist * np.array([math.cos(eta), math.sin(eta)])
            pts.append(p.copy())
        if len(pts) == 1:
            pts.append(p.copy())
        out.append(np.array(pts))
    return out


def pair_errors(plan: Plan, final: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """r_d and r_φ of every child-parent pair at the final positions."""
    row = {r.order: k for k, r in enumerate(plan.robots)}
    back = np.array([-math.cos(plan.axis), -math.sin(plan.axis)])
    rd, rp = [], []
    for k, r in enumerate(plan.robots):
        if r.order == 0:
            continue
        par = row[parent_of(r.order)]
        v = final[k] - final[par]
        d = math.hypot(v[0], v[1])
        rd.append((d - D_E) / D_E)
        cosang = float(np.clip(np.dot(v, back) / max(d, 1e-12), -1.0, 1.0))
        rp.append((math.acos(cosang) - PHI_E) / PHI_E)
    return np.array(rd), np.array(rp)


@dataclass
class Acc:
    rd: list[float]
    rp: list[float]
    crossings: list[int]
    viol_plan: list[int]
    viol_exec: list[int]
    ratio: list[float]
    frame_err: list[float]
    waves: list[int]
    makespan: list[float]
    wave_makespan: list[float]
    failures: int = 0


def _summary(acc: Acc) -> dict[str, Any]:
    rd, rp = np.array(acc.rd), np.array(acc.rp)

    def pct(a: np.ndarray) -> dict[str, float]:
        if a.size == 0:
            return {}
        q = np.percentile(a, [5, 25, 50, 75, 95])
        return {f"p{p}": round(float(v), 4) for p, v in zip((5, 25, 50, 75, 95), q, strict=True)}

    return {
        "runs": len(acc.crossings),
        "failures": acc.failures,
        "r_d": pct(rd),
        "r_phi": pct(rp),
        "r_d_within_20pct": round(float(np.mean(np.abs(rd) <= 0.2)), 4) if rd.size else None,
        "r_d_within_30pct": round(float(np.mean(np.abs(rd) <= 0.3)), 4) if rd.size else None,
        "r_phi_within_20pct": round(float(np.mean(np.abs(rp) <= 0.2)), 4) if rp.size else None,
        "r_phi_within_30pct": round(float(np.mean(np.abs(rp) <= 0.3)), 4) if rp.size else None,
        "crossings_per_run": round(float(np.mean(acc.crossings)), 4) if acc.crossings else None,
        "planned_violations_per_run": round(float(np.mean(acc.viol_plan)), 4)
        if acc.viol_plan
        else None,
        "executed_violations_per_run": round(float(np.mean(acc.viol_exec)), 4)
        if acc.viol_exec
        else None,
        "path_over_optimum": round(float(np.mean(acc.ratio)), 4) if acc.ratio else None,
        "frame_error_m": round(float(np.mean(acc.frame_err)), 4) if acc.frame_err else None,
        "waves_mean": round(float(np.mean(acc.waves)), 3) if acc.waves else None,
        "makespan_over_capt": round(float(np.median(acc.makespan)), 4) if acc.makespan else None,
        "makespan_over_capt_worst": round(float(np.max(acc.makespan)), 4) if acc.makespan else None,
        "wave_makespan_over_capt": round(float(np.median(acc.wave_makespan)), 4)
        if acc.wave_makespan
        else None,
    }


def one_run(
    seed: int, n: int, level: str, strategy: str, frame: str
) -> tuple[Plan, np.ndarray, list[np.ndarray], dict[str, Any]]:
    """One seeded run; the start and the record noise depend only on (seed, level)."""
    rng = np.random.default_rng([seed, n])
    pos = random_start(rng, n)
    dd_ij, dd_i, deta = LEVELS[level]
    recs = noisy_records(np.random.default_rng([seed, n, 1]), pos, dd_ij * D_E, 1.5 * D_E)
    params = PlanParams(
        d_e=D_E,
        phi_e=PHI_E,
        radius=RADIUS,
        strategy=strategy,
        frame_method=frame,
        epsilon=0.3 * D_E,
    )
    # the fault test's noise model is this Monte Carlo's (a disc of radius dd_ij·d_e), not
    # the rendered perception's
    disc = SightingNoise.synthetic(floor=max(dd_ij * D_E / 2.0, 1e-3))
    plan = plan_from_records(recs, params, noise=disc)
    true_c = pos - pos[plan.frame_robot]
    cf = build_common_frame(identify_neighbours(recs, params.epsilon), frame)
    frame_err = float(np.mean(np.hypot(*(cf.positions - true_c).T)))
    ex_rng = np.random.default_rng([seed, n, 2])
    executed = execute(ex_rng, plan, true_c, dd_i * D_E, deta * PHI_E)
    final = np.array([p[-1] for p in executed])
    rd, rp = pair_errors(plan, final)
    s, t = plan.starts(), plan.targets()
    a, b = np.triu_indices(n, 1)
    crossings = int(np.sum(paths_cross(s[a], t[a], s[b], t[b])))
    waves = plan.wave_of()
    viol_plan = len(check_safety(plan.paths(), waves, RADIUS))
    viol_exec = len(check_safety(executed, waves, RADIUS))
    # optimum: exact min-sum to the same slots
    perm = optimal_assignment(s, t)
    opt = float(np.sum(np.hypot(*(s - t[perm]).T)))
    total = float(sum(r.length() for r in plan.robots))
    lengths = path_lengths(plan.paths())
    row = {r.robot_id: k for k, r in enumerate(plan.robots)}
    after = [[row[j] for j in r.after] for r in plan.robots]
    # the release points the agents wait for (none: the robots waited for must hold)
    at = (
        [list(r.after_at) for r in plan.robots]
        if all(len(r.after_at) == len(r.after) for r in plan.robots)
        else None
    )
    capt = capt_makespan(s, t)
    stats = {
        "rd": rd,
        "rp": rp,
        "crossings": crossings,
        "viol_plan": viol_plan,
        "viol_exec": viol_exec,
        "ratio": total / opt if opt > 1e-9 else 1.0,
        "frame_err": frame_err,
        "waves": len(plan.waves),
        "makespan": dependency_makespan(lengths, after, waves, at) / capt if capt > 1e-9 else 1.0,
        "wave_makespan": wave_makespan(lengths, waves) / capt if capt > 1e-9 else 1.0,
    }
    return plan, true_c, executed, stats


def run_all(
    runs: int, n: int, levels: list[str], strategies: list[str], frames: list[str]
) -> dict[str, Any]:
    out: dict[str, Any] = {}
    from tools.harness.progress import Progress

    bar = Progress(len(levels) * len(strategies) * len(frames), "montecarlo")
    for level in levels:
        for strategy in strategies:
            for frame in frames:
                acc = Acc([], [], [], [], [], [], [], [], [], [])
                for seed in range(runs):
                    try:
                        _, _, _, st = one_run(seed, n, level, strategy, frame)
                    except ValueError:
                        acc.failures += 1
                        continue
                    acc.rd.extend(st["rd"].tolist())
                    acc.rp.extend(st["rp"].tolist())
                    acc.crossings.append(st["crossings"])
                    acc.viol_plan.append(st["viol_plan"])
                    acc.viol_exec.append(st["viol_exec"])
                    acc.ratio.append(st["ratio"])
                    acc.frame_err.append(st["frame_err"])
                    acc.waves.append(st["waves"])
                    acc.makespan.append(st["makespan"])
                    acc.wave_makespan.append(st["wave_makespan"])
                out[f"{level}/{strategy}/{frame}"] = _summary(acc)
                bar.step(f"{level}/{strategy}/{frame}")
    return out


def _figures(out_dir: str, runs: int, n: int, strategy: str) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tools.plan import draw_on

    os.makedirs(out_dir, exist_ok=True)
    written = []
    # Fig. 15: histograms of r_d and r_φ at the paper's noise
    rd_all, rp_all = [], []
    for seed in range(runs):
        try:
            _, _, _, st = one_run(seed, n, "paper", strategy, "lsq")
        except ValueError:
            continue
        rd_all.extend(st["rd"].tolist())
        rp_all.extend(st["rp"].tolist())
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, data, name, lim in ((axes[0], rd_all, "r_d", 0.2), (axes[1], rp_all, "r_φ", 0.3)):
        ax.hist(np.array(data) * 100, bins=40, color="tab:blue", alpha=0.8)
        for x in (-lim * 100, lim * 100):
            ax.axvline(x, color="tab:red", ls="--")
        inside = float(np.mean(np.abs(np.array(data)) <= lim)) * 100 if data else 0.0
        ax.set_title(f"{name} [%]: {inside:.1f}% within ±{int(lim * 100)}%")
        ax.set_xlabel(f"{name} (%)")
    fig.suptitle(f"Fig. 15: {n} robots, {runs} runs, paper noise, strategy {strategy}")
    fig.tight_layout()
    p = os.path.join(out_dir, "fig15_histograms.png")
    fig.savefig(p, dpi=100)
    plt.close(fig)
    written.append(p)
    # Fig. 16: 6, 10, 15 robots
    fig, axes = plt.subplots(1, 3, figsize=(15, 5))
    for ax, m in zip(axes, (6, 10, 15), strict=True):
        plan, true_c, executed, _ = one_run(1, m, "paper", strategy, "lsq")
        draw_on(ax, plan, RADIUS)
        for path in executed:
            ax.plot(path[:, 0], path[:, 1], ":", color="tab:red", lw=1)
        ax.plot(true_c[:, 0], true_c[:, 1], "x", color="tab:red")
        ax.set_title(f"{m} robots: planned (solid), executed (dotted)")
    fig.tight_layout()
    p = os.path.join(out_dir, "fig16_fleets.png")
    fig.savefig(p, dpi=100)
    plt.close(fig)
    written.append(p)
    # Fig. 17: 8 robots, 7 obstacles
    rng = np.random.default_rng(17)
    pts = random_start(rng, 15)
    plan = plan_from_positions(
        list(range(8)),
        pts[:8],
        PlanParams(d_e=D_E, radius=RADIUS, strategy=strategy),
        obstacles=pts[8:],
    )
    fig, ax = plt.subplots(figsize=(7, 7))
    draw_on(ax, plan, RADIUS)
    ax.set_title("Fig. 17: 8 robots (red), 7 obstacles (blue): match, move out, correct")
    fig.tight_layout()
    p = os.path.join(out_dir, "fig17_obstacles.png")
    fig.savefig(p, dpi=100)
    plt.close(fig)
    written.append(p)
    return written


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.montecarlo", description=__doc__.splitlines()[0]
    )
    ap.add_argument("--runs", type=int, default=100, help="seeded runs per configuration (100)")
    ap.add_argument("--robots", type=int, default=10)
    ap.add_argument("--levels", default=",".join(LEVELS), help=f"comma list of {list(LEVELS)}")
    ap.add_argument("--strategies", default=",".join(STRATEGIES))
    ap.add_argument("--frames", default=",".join(FRAMES))
    ap.add_argument("--out", default="out/montecarlo", help="directory for the PNG figures")
    ap.add_argument("--no-figures", action="store_true")
    ap.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    args = ap.parse_args(argv)
    levels = [x for x in args.levels.split(",") if x]
    strategies = [x for x in args.strategies.split(",") if x]
    frames = [x for x in args.frames.split(",") if x]
    bad = (
        [x for x in levels if x not in LEVELS]
        + [x for x in strategies if x not in STRATEGIES]
        + [x for x in frames if x not in FRAMES]
    )
    if bad or args.runs < 1 or args.robots < 2:
        print(f"error: bad option values {bad or ''} (runs >= 1, robots >= 2)", file=sys.stderr)
        return 2
    summary: dict[str, Any] = {
        "robots": args.robots,
        "runs": args.runs,
        "d_e": D_E,
        "phi_e_deg": math.degrees(PHI_E),
        "levels": {
            k: {"dd_ij": v[0], "dd_i": v[1], "deta": v[2]} for k, v in LEVELS.items() if k in levels
        },
        "results": run_all(args.runs, args.robots, levels, strategies, frames),
    }
    if not args.no_figures:
        summary["figures"] = _figures(args.out, args.runs, args.robots, "default")
    if args.json:
        json.dump(summary, sys.stdout)
        sys.stdout.write("\n")
    else:
        print(
            f"{'configuration':32s} {'rd±20%':>7s} {'rφ±30%':>7s} {'cross':>6s} {'viol':>5s} "
            f"{'exviol':>6s} {'path/opt':>8s} {'frame m':>8s} {'ms/capt':>7s} {'wave ms':>7s} "
            f"{'fail':>4s}"
        )
        for key, r in summary["results"].items():
            print(
                f"{key:32s} {r['r_d_within_20pct']!s:>7s} {r['r_phi_within_30pct']!s:>7s} "
                f"{r['crossings_per_run']!s:>6s} {r['planned_violations_per_run']!s:>5s} "
                f"{r['executed_violations_per_run']!s:>6s} {r['path_over_optimum']!s:>8s} "
                f"{r['frame_error_m']!s:>8s} {r['makespan_over_capt']!s:>7s} "
                f"{r['wave_makespan_over_capt']!s:>7s} {r['failures']:>4d}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
