"""A judged run shown: the formation figure (Fig. 16/24-like: each robot's track from
the truth, the pairs of the plan) and the result table with the verdict
(:mod:`tools.harness.judge` computes both from the ground truth)."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path
from typing import Any

from agent.core.formation.shape.verdict import R_D_MAX, R_PHI_MAX
from tools.harness.observe import Observer


def moved(result: dict[str, Any]) -> float:
    """The longest straight-line displacement start → final of any robot (m), from truth."""
    starts, finals = result.get("starts") or {}, result.get("finals") or {}
    return max(
        (math.dist(starts[i][:2], finals[i][:2]) for i in starts if i in finals), default=0.0
    )


def plot(obs: Observer, result: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 7))
    ids = sorted(obs.truth[-1][1]) if obs.truth else []
    colours = plt.get_cmap("tab10")
    for k, i in enumerate(ids):
        xs = [poses[i][0] for _, poses in obs.truth if i in poses]
        ys = [poses[i][1] for _, poses in obs.truth if i in poses]
        c = colours(k % 10)
        ax.plot(xs, ys, "-", color=c, lw=1.2, alpha=0.8)
        ax.plot(xs[0], ys[0], "o", mfc="white", mec=c, ms=10)
        x, y, h = obs.truth[-1][1][i]
        ax.add_patch(plt.Circle((x, y), 0.2, color=c, alpha=0.35))
        ax.annotate("", (x + 0.25 * math.cos(h), y + 0.25 * math.sin(h)), (x, y),
                    arrowprops={"arrowstyle": "->", "color": c})  # fmt: skip
        ax.text(x + 0.06, y + 0.06, str(i), fontsize=11, weight="bold")
        ax.text(xs[0] + 0.06, ys[0] - 0.12, f"{i} start", fontsize=8, color="grey")
    final = obs.truth[-1][1] if obs.truth else {}
    k0 = result.get("march_start_sample")
    if k0 is not None:  # the pyramid at the start of the march
        first = obs.truth[k0][1]
        for row in result.get("pairs", []):
            c, p = row["child"], row["parent"]
            if c in first and p in first:
                ax.plot([first[c][0], first[p][0]], [first[c][1], first[p][1]], "--",
                        color="grey", lw=0.8)  # fmt: skip
        for i in ids:
            if i in first:
                ax.add_patch(plt.Circle(first[i][:2], 0.2, fill=False, ec="grey", lw=0.8))
    # no agent made a plan (a safe stop before planning): the pairs of the evaluator's
    # plan would only mislead; the reason and how far anybody moved say what happened
    unplanned = not any(result.get("plan_digests", {}).values())
    for row in [] if unplanned else result.get("pairs", []):
        c, p = row["child"], row["parent"]
        if c in final and p in final:
            ax.plot([final[c][0], final[p][0]], [final[c][1], final[p][1]], "k--", lw=0.8)
    if "obstacles" in result:
        from tools.lib.obstacle_scenario import draw_obstacles

        draw_obstacles(ax, result)
    leader = None if unplanned else result.get("leader")
    if leader in final:
        ax.plot(final[leader][0], final[leader][1], "*", color="green", ms=16)
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("world x (m)")
    ax.set_ylabel("world y (m), north")
    ok = "success" if result.get("success") else "FAILED"
    detail = (
        f"max |r_d| {result.get('max_abs_r_d', float('nan')):.1%}, "
        f"max |r_phi| {result.get('max_abs_r_phi', float('nan')):.1%}, "
        f"contacts {result.get('contacts')}"
    )
    if unplanned and not result.get("success"):
        ok = "stopped safely before any plan"
        errors = result.get("errors") or {}
        why = str(errors[min(errors)]) if errors else "no agent planned"
        detail = (
            f"{textwrap.shorten(why.removeprefix('AgentFailure: '), 64)}\n"
            f"moved at most {moved(result):.2f} m, contacts {result.get('contacts')}"
        )
    ax.set_title(
        f"{len(ids)} NAOs, seed {result.get('seed')}: {ok}\n"
        + detail
        + (
            f"\nmarch {result['march_distance']:.2f} m (route {math.hypot(*result['march_route']):.2f} m), "
            f"worst during: |r_d| {result['march_worst_abs_r_d']:.1%}, "
            f"|r_phi| {result['march_worst_abs_r_phi']:.1%}"
            if "march_distance" in result
            else ""
        )
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def print_table(r: dict[str, Any]) -> None:
    p = print
    p(f"\nnao-formation demo: {r['robots']} robots, seed {r['seed']}, "
      f"d_e {r['d_e']:.2f} m, phi_e {r['phi_e_deg']:.0f} deg")  # fmt: skip
    p(f"{'child':>5} {'parent':>6} {'side':>5} {'dist (m)':>9} {'angle (deg)':>11} {'r_d':>8} "
      f"{'r_phi':>8}  ok   robot's own check (r_d, r_phi)")  # fmt: skip
    checks = r.get("own_checks", {})
    for row in r["pairs"]:
        ok = abs(row["r_d"]) <= R_D_MAX and abs(row["r_phi"]) <= R_PHI_MAX
        own = checks.get(str(row["child"]))
        mine = f"{own[1]:+8.1%} {own[2]:+8.1%}" if own else "       -"
        p(f"{row['child']:>5} {row['parent']:>6} {row.get('side', '-'):>5} "
          f"{row['distance']:9.3f} {row['angle_deg']:11.1f} "
          f"{row['r_d']:+8.1%} {row['r_phi']:+8.1%}  {'yes' if ok else 'NO ':3s}   {mine}")  # fmt: skip
    if not r["pairs"]:
        p(
            "  (no pairs evaluated"
            + (f": {r['evaluation_error']}" if "evaluation_error" in r else "")
            + ")"
        )
    for name, rep in r.get("rogues", {}).items():
        if not rep.get("connected"):
            p(f"rogue {name}: could not connect ({rep.get('reason', '')[:70]})")
        else:
            p(f"rogue {name}: sent {sum(rep.get('sent', {}).values())} messages/requests, "
              f"{rep.get('commands_executed')} commands executed, "
              f"{rep.get('claims_granted')} claims granted")  # fmt: skip
    if "rogues" in r:
        p(f"plan digest recomputed from the signed records: "
          f"{'same' if r['plan_matches_records'] else 'DIFFERENT'}")  # fmt: skip
    for why in r.get("untrusted", []):
        p(f"not defended: {why}")
    if r.get("route"):
        if "march_distance" in r:
            p(f"march: leader displaced {r['march_distance']:.2f} m for a route of "
              f"{math.hypot(*r['march_route']):.2f} m (error {r['march_error']:.1%}, "
              f"{'ok' if r['march_ok'] else 'NOT within 10 %'}); worst during the march "
              f"|r_d| {r['march_worst_abs_r_d']:.1%}, |r_phi| {r['march_worst_abs_r_phi']:.1%}")  # fmt: skip
        else:
            p(f"march: not judged ({r.get('march_error_reason', 'no plan')})")
    p(f"contacts: {r['contacts']} (robot-robot {r['robot_contacts']}), "
      f"min centre separation {r['min_separation']:.2f} m")  # fmt: skip
    if "obstacle_contacts" in r:
        err = r.get("obstacle_position_error", [])
        p(f"obstacles: {len(r['obstacles'])} in the way, {r.get('obstacles_seen', 0)} planned "
          f"around (position error {', '.join(f'{e:.2f}' for e in err) or '-'} m), "
          f"contacts {r['obstacle_contacts']}, min gap {r['min_obstacle_gap']:.2f} m")  # fmt: skip
    p("phase       wall max (s)  sim max (s)")
    for ph, t in r["phases"].items():
        p(f"  {ph:9s} {t['wall_max']:12.1f} {t['sim_max']:12.1f}")
    p(f"wall total {r.get('wall_total', float('nan')):.1f} s, sim end {r['t_sim_end']:.1f} s")
    p("bytes published per agent (record + digest = exchange; status for viewers):")
    for i, b in r["bytes"].items():
        p(f"  robot {i}: total {b['total']} B, exchange {r['exchange_bytes'][i]} B, "
          f"status {b.get('status', 0)} B")  # fmt: skip
    for i, c in r.get("camera", {}).items():
        p(f"  robot {i}: camera {c['frames']} frames, {c['bytes']} B, "
          f"{c['kB_per_s']:.1f} kB/s while streaming ({c['frames_per_s']:.2f} frames/s), "
          f"{c['kB_per_s_run']:.1f} kB/s over the run")  # fmt: skip
    same = "yes" if r["identical_digests"] else "NO"
    p(f"identical plan digests: {same} ({next(iter(r['plan_digests'].values()))[:12]})")
    for i, e in r["errors"].items():
        p(f"  robot {i} error: {e}")
    if "timeout" in r:
        p(f"  {r['timeout']}")
    p(f"exit codes: {r['exit_codes']}")
    p(f"figure: {r.get('figure', '-')}   recording: {r['recording']}")
    if "fleet_held" in r:
        fleet = "formation held (every agent done)" if r["fleet_held"] else "not held"
        truth = "within tolerance" if r["within_tolerance"] else "NOT within tolerance"
        p(f"verdicts: the fleet says {fleet}; the ground truth says {truth}"
          + ("  <- SILENT WRONG FORMATION" if r["silent_wrong"] else ""))  # fmt: skip
    if "outcome" in r:
        p(f"outcome: {r['outcome']} ({r.get('outcome_detail', '')})")
    degraded = r.get("outcome") == "degraded"
    p("RESULT: " + ("SUCCESS" if r["success"] else "DEGRADED" if degraded else "FAILURE"))
