"""A run judged from ground truth: per child-parent pair of the formation (the pyramid by
default, any shape of ``--shape``) r_d and r_φ (NAO paper 5.1.1: (d - d_e)/d_e and
(φ - φ_e)/φ_e for the pyramid; against the pair's distance and angle in the shape's tree
for any shape), contacts, the march, phase times, bytes,
identical plan digests (the result table and the formation figure:
:mod:`tools.harness.run_report`).

Success: the run's :func:`outcome` is ``complete`` (every agent the fleet kept exited 0
in ``done``, identical plan digests, zero contacts, nobody moved off the shared plan, the
true shape in tolerance: every pair within |r_d| <= 12.5 % and |r_φ| <= 30 % on its own
side, the leader in front; any robot left out carries the injected fault), and, with a
march, the leader's displacement within 10 % of the route; with rogues, none of their
attacks worked. Who moved and the shape come from the truth alone
(:mod:`tools.harness.truth`); the evaluator's plan, recomputed from the signed records,
only names the robots the fleet left out and judges the march and the rogues.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agent.config import AgentConfig, load_shape
from agent.core.formation.shape.spec import PYRAMID
from agent.core.formation.shape.spec import Shape as FormationShape
from agent.core.formation.shape.verdict import R_D_MAX, R_PHI_MAX
from agent.wire import PHASES
from tools.harness.observe import AgentView, Observer
from tools.harness.pairs import evaluate, plan_pairs
from tools.harness.procs import rogue_reports
from tools.harness.run_report import plot, print_table
from tools.harness.truth import MOVED_M, excursions, judge_shape, settled_at
from tools.lib.frame_fit import common_frame_pose
from tools.lib.reshape import final_shape_spec, judge_reshapes

#: The phases of docs/design.md §1 in order (the wire's list, less the terminal "failed").
PHASE_ORDER = tuple(p for p in PHASES if p != "failed")


# ===================================================================== evaluation


def plan_meta(cfg: AgentConfig) -> dict[str, Any]:
    """What a run's ``result.json`` says of the fleet's planning parameters besides the
    pyramid's d_e and φ_e, so that :func:`summarise` plans and judges the run as the agents
    did: their ``orientation``, ``strategy`` and shape (``shape_spec``: the name or file
    :func:`agent.config.load_shape` loads it from again; ``shape_digest``)."""
    return {
        "orientation": cfg.orientation,
        "strategy": cfg.strategy,
        "shape_spec": cfg.shape.source,
        "shape_digest": cfg.shape.digest,
    }


def plan_from_agreed(
    obs: Observer,
    d_e: float,
    phi_e: float,
    orientation: str = "pca",
    strategy: str = "default",
    shape: FormationShape = PYRAMID,
) -> Any:
    """(the adapter, the plan, the plan the robots started on), recomputed from the records
    the agents exchanged with the fleet's parameters. With the orientation ``cp``: the
    formation's from the records' circle (agent/core/formation/reshape.py), started on
    the circle's; else both are the same."""
    from agent.adapters import FormationAdapter
    from agent.core.formation.params import PlanParams
    from agent.core.formation.reshape import from_circle

    fa = FormationAdapter()
    recs = tuple(obs.records[i] for i in sorted(obs.records))
    params = PlanParams(
        d_e=d_e, phi_e=phi_e, orientation=orientation, strategy=strategy, shape=shape
    )
    first = fa.plan(recs, params)
    if orientation == "cp" and len(first.robots) > 1:
        return fa, from_circle(first, params), first
    return fa, first, first


def plan_params(result: dict[str, Any], d_e: float, phi_e: float, shape: FormationShape) -> Any:
    """The fleet's planning parameters as ``result`` records them."""
    from agent.core.formation.params import PlanParams

    orientation, strategy = result.get("orientation", "pca"), result.get("strategy", "default")
    return PlanParams(d_e=d_e, phi_e=phi_e, orientation=orientation, strategy=strategy, shape=shape)


MARCH_TOLERANCE = 0.10  # the leader's displacement within 10 % of the route


def judge_march(
    obs: Observer,
    result: dict[str, Any],
    plan: Any,
    axis: float,
    pairs: Sequence[tuple[int, int] | tuple[int, int, float, float]],
    d_e: float,
    phi_e: float,
) -> None:
    """The march from ground truth: from the moment every agent was ready to march (its
    first ``march`` status, after its correction) to the end.

    Sets ``march_distance`` (the leader's displacement, m), ``march_route`` (V, m),
    ``march_error`` (|displacement − V| / |V|), ``march_ok`` and the worst |r_d|, |r_φ|
    over every truth sample of the march."""
    from agent.core.formation.view.route import Route, route_vector

    rt = result["route"]
    route = Route(distance=rt["distance"]) if "distance" in rt else Route(to=tuple(rt["to"]))
    v = route_vector(plan, route, axis)
    leader = int(plan.leader)
    ready = [obs.agents[i].march_sample if i in obs.agents else None for i in plan.ids]
    result["march_route"] = [float(v[0]), float(v[1])]
    result["march_ok"] = False
    if any(k is None for k in ready) or not obs.truth:
        result["march_error_reason"] = "the march never started"
        return
    k0 = min(max(k for k in ready if k is not None), len(obs.truth) - 1)
    result["march_start_t_sim"] = obs.truth[k0][0]
    result["march_start_sample"] = k0
    first, last = obs.truth[k0][1], obs.truth[-1][1]
    disp = np.array(last[leader][:2]) - np.array(first[leader][:2])
    length = float(np.hypot(*v))
    result["march_distance"] = float(np.hypot(*disp))
    result["march_displacement"] = [float(disp[0]), float(disp[1])]
    result["march_error"] = float(np.hypot(*(disp - v))) / max(length, 1e-9)
    worst_d = worst_phi = 0.0
    for _, poses in obs.truth[k0:]:
        if all(pr[0] in poses and pr[1] in poses for pr in pairs):
            for row in evaluate(poses, pairs, axis, d_e, phi_e):
                worst_d = max(worst_d, abs(row["r_d"]))
                worst_phi = max(worst_phi, abs(row["r_phi"]))
    result["march_worst_abs_r_d"] = worst_d
    result["march_worst_abs_r_phi"] = worst_phi
    result["march_ok"] = result["march_error"] <= MARCH_TOLERANCE


def min_separation(obs: Observer) -> float:
    best = math.inf
    for _, poses in obs.truth:
        pts = np.array([p[:2] for p in poses.values()])
        if len(pts) < 2:
            continue
        dd = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
        dd[np.diag_indices(len(pts))] = np.inf
        best = min(best, float(dd.min()))
    return best


def fleet_verdict(
    views: dict[int, AgentView], ids: list[int], all_done: bool, truth_ok: bool, judged: bool = True
) -> dict[str, Any]:
    """The fleet's own verdict beside the ground truth's (docs/design.md §9 "Honest results").

    The fleet says "formation held" when every agent reports ``done``; each child's own
    check of its pair (``StatusMsg.r_d``/``r_phi``) is reported too. ``silent_wrong``: every
    agent reported done while the ground truth fails - as bad as a contact (only when the
    ground truth could be ``judged``: the evaluator recomputed the plan).
    """
    checks = {str(i): list(c) for i in ids if (c := views[i].check) is not None}
    out_of_tol = sorted(
        int(i) for i, (_, rd, rp) in checks.items() if abs(rd) > R_D_MAX or abs(rp) > R_PHI_MAX
    )
    return {
        "fleet_held": all_done,
        "own_checks": checks,
        "own_checks_out_of_tolerance": out_of_tol,
        "verdicts_agree": all_done == truth_ok,
        "silent_wrong": all_done and not truth_ok and judged,
    }


#: Every outcome of a run (:func:`outcome`); :data:`FAILURES` fail an evaluation tool.
OUTCOMES = ("complete", "degraded", "safe_abort", "unsafe", "unjudged", "no_result")
FAILURES = ("degraded", "unsafe", "no_result")


def injected_faults(result: dict[str, Any]) -> list[int]:
    """The robots whose agent ran with the injected ``--sensor-fault`` (the harness gave
    it: ``agent_args`` ``ID:--sensor-fault=...``), sorted."""
    args = result.get("agent_args") or []
    out = set()
    for arg in args if isinstance(args, list) else []:
        rid, _, rest = str(arg).partition(":")
        if rest.startswith("--sensor-fault") and rid.isdigit():
            out.add(int(rid))
    return sorted(out)


def outcome(result: dict[str, Any]) -> tuple[str, str]:
    """(outcome, detail) of a judged run, one rule for every evaluation tool; who moved and
    the shape come from the ground truth (:mod:`tools.harness.truth`), the exit codes from
    the processes.

    ``no_result``: no result at all: an empty one, or the stand-in ``{"no_result": why}``
    of a tool whose run gave none (a monitor that wrote nothing, a harness error); a
    failure.
    ``unsafe``: a contact; a robot that moved (the truth's ``movers``) without a plan
    digest, or while the robots that planned hold different ones; a robot the fleet left
    out that moved; or every agent done while the truth's shape fails (a silent wrong
    formation is as bad as a contact). ``complete``: every agent that the fleet kept
    (all but ``excluded``) exited 0 in ``done`` on identical plans, the true shape in
    tolerance, and each robot left out carries the injected fault (``injected_faults``).
    ``degraded``: the same, but the fleet left out a sound robot; a failure.
    ``unjudged``: every agent done on identical plans, but the truth holds no final pose
    of some member: nothing to judge; neither a success nor a silent wrong "done".
    Everything else is a ``safe_abort``.
    """
    if not result or "no_result" in result:
        return "no_result", str(result.get("no_result", "no result"))
    contacts = int(result.get("contacts", 0))
    if contacts:
        return "unsafe", f"{contacts} contact(s)"
    digests = result.get("plan_digests", {})
    planned = {d for d in digests.values() if d}
    movers = [int(i) for i in result.get("movers", [])]
    blind = [i for i in movers if not digests.get(str(i))]
    if blind:
        return "unsafe", f"robots {blind} moved without reporting a plan"
    if movers and len(planned) > 1:
        return "unsafe", f"robots {movers} moved; plan digests differ {sorted(planned)}"
    left_out = sorted(int(i) for i in result.get("excluded", []))
    strayed = [i for i in left_out if i in movers]
    if strayed:
        return "unsafe", f"robots {strayed} were left out of the plan but moved"
    codes, phases = result.get("exit_codes", {}), result.get("final_phase", {})
    out = {str(i) for i in left_out}  # left out by the fleet: they stand still
    all_done = bool(codes) and all(
        codes.get(i) == 0 and phases.get(i) == "done" for i in codes if i not in out
    )
    if all_done and result.get("identical_digests"):
        if result.get("within_tolerance"):
            sound = [i for i in left_out if i not in injected_faults(result)]
            if sound:
                return "degraded", f"formed without sound robots {sound} (left out of the plan)"
            rest = f" (robots {left_out} left out)" if left_out else ""
            return "complete", f"done, pairs within tolerance{rest}"
        missing = (result.get("shape") or {}).get("missing")
        if "shape" not in result or missing:
            return "unjudged", (
                f"every agent done, but the truth holds no final pose of {missing or 'any'}: "
                "no shape to judge"
            )
        worst = f"max |r_d| {result.get('max_abs_r_d', math.nan):.1%}, |r_phi| " + (
            f"{result.get('max_abs_r_phi', math.nan):.1%}"
        )
        front = "" if result["shape"].get("leader_in_front", True) else ", leader not in front"
        return "unsafe", f"every agent said done on a wrong formation ({worst}{front})"
    errors = "; ".join(f"{k}: {v[:90]}" for k, v in result.get("errors", {}).items())
    if "timeout" in result:
        errors = f"{result['timeout']}; {errors}"
    return "safe_abort", errors or f"exit codes {codes}, phases {phases}"


def camera_rate(v: AgentView, wall: float) -> dict[str, float]:
    """Frames, bytes and kB/s of one robot's camera frames: over the run's wall time
    (``kB_per_s_run``) and between its first and last frame (``kB_per_s``)."""
    first, last = v.camera_wall or (0.0, 0.0)
    span = last - first
    return {
        "frames": v.camera_frames,
        "bytes": v.camera_bytes,
        "kB_per_s": v.camera_bytes / 1000.0 / span if span > 0 else 0.0,
        "kB_per_s_run": v.camera_bytes / 1000.0 / wall if wall > 0 else 0.0,
        "frames_per_s": (v.camera_frames - 1) / span if span > 0 else 0.0,
    }


def summarise(
    obs: Observer,
    result: dict[str, Any],
    out: Path,
    ids: list[int],
    d_e: float,
    phi_e: float,
    quiet: bool,
) -> dict[str, Any]:
    n = len(ids)
    views = {i: obs.agents.get(i, AgentView()) for i in ids}
    result["exit_codes"] = {str(i): views[i].exit_code for i in ids}
    result["final_phase"] = {str(i): views[i].phase for i in ids}
    result["errors"] = {str(i): views[i].error for i in ids if views[i].error}
    digests = {views[i].plan_digest for i in ids}
    result["plan_digests"] = {str(i): views[i].plan_digest for i in ids}
    result["identical_digests"] = len(digests) == 1 and "" not in digests
    result["bytes"] = {
        str(i): {**dict(views[i].bytes_by_kind), "total": sum(views[i].bytes_by_kind.values())}
        for i in ids
    }
    # camera frames for viewers (--publish-camera), apart from the fleet's bytes
    result["camera"] = {
        str(i): camera_rate(views[i], result.get("wall_total", 0.0))
        for i in ids
        if views[i].camera_frames
    }
    result["exchange_bytes"] = {
        str(i): views[i].bytes_by_kind.get("record", 0) + views[i].bytes_by_kind.get("digest", 0)
        for i in ids
    }
    robot_contacts = [c for c in obs.contacts if c[2] >= 0]
    result["contacts"] = max(len(obs.contacts), obs.truth_contacts)
    result["robot_contacts"] = len(robot_contacts)
    result["min_separation"] = min_separation(obs)
    # phases: the slowest agent's duration of each phase, wall and sim
    phases: dict[str, dict[str, float]] = {}
    for k, ph in enumerate(PHASE_ORDER[:-1]):
        walls, sims = [], []
        for v in views.values():
            if ph in v.phase_wall:
                later = [v.phase_wall[q] for q in PHASE_ORDER[k + 1 :] if q in v.phase_wall]
                later_s = [v.phase_sim[q] for q in PHASE_ORDER[k + 1 :] if q in v.phase_sim]
                if later:
                    walls.append(min(later) - v.phase_wall[ph])
                    sims.append(min(later_s) - v.phase_sim[ph])
        if walls:
            phases[ph] = {"wall_max": max(walls), "sim_max": max(sims)}
    result["phases"] = phases
    # the agreement's own cost: the last agent entering exchange -> the last one planning
    entered = [views[i].phase_wall for i in ids]
    if entered and all("exchange" in e and "plan" in e for e in entered):
        result["agreement_s"] = max(e["plan"] for e in entered) - max(
            e["exchange"] for e in entered
        )
    result["t_sim_end"] = obs.truth[-1][0] if obs.truth else 0.0
    # the building's sim time: from the last agent planning to every robot settled
    planned = [views[i].phase_sim["plan"] for i in ids if "plan" in views[i].phase_sim]
    result["t_sim_plan"] = max(planned) if planned else math.nan
    result["t_sim_settled"] = settled_at(obs.truth, ids)
    result["pairs"] = []
    # the (re-)search round of each robot's last record (NAO 4.1.3 rule 2)
    result["record_rounds"] = {str(i): obs.records[i].round for i in ids if i in obs.records}
    if obs.truth:
        result["starts"] = {str(i): list(obs.truth[0][1][i]) for i in ids if i in obs.truth[0][1]}
        result["finals"] = {str(i): list(obs.truth[-1][1][i]) for i in ids if i in obs.truth[-1][1]}
    result["records_observed"] = len(obs.records)
    shape = load_shape(result.get("shape_spec", "pyramid"))
    if obs.truth and len(obs.records) == n:
        try:
            fa, plan, first = plan_from_agreed(
                obs,
                d_e,
                phi_e,
                result.get("orientation", "pca"),
                result.get("strategy", "default"),
                shape,
            )
            result["evaluator_plan_digest"] = str(plan.digest)
            if result.get("reshape_specs"):  # the transitions, recomputed
                judge_reshapes(result, plan, plan_params(result, d_e, phi_e, shape))
            result["excluded"] = [int(i) for i in plan.excluded]
            result["verdict"] = plan.verdict
            result["leader"] = int(plan.leader)
            # in the common frame: where --march-to points are given
            result["leader_target"] = [float(v) for v in plan.robot(plan.leader).target]
            # the common frame is the frame robot's fixed frame: the world turned by that
            # robot's start heading off north (0 for the papers' aligned starts)
            starts = {r.robot_id: r.start for r in first.robots}
            frame = common_frame_pose(starts, obs.truth[0][1])
            axis = fa.axis_angle(plan) + frame[2] - math.pi / 2
            result["axis_deg"] = math.degrees(axis)
            if result.get("route"):  # the march against the plan's route and pairs
                pairs = plan_pairs(plan, [i for i in ids if i in plan.ids], shape, d_e, phi_e)
                judge_march(obs, result, plan, axis, pairs, d_e, phi_e)
            if "obstacles" in result:
                from tools.lib.obstacle_scenario import judge_obstacles

                judge_obstacles(result, obs.truth, obs.contacts, plan)
        except (ValueError, KeyError, AttributeError, ImportError) as exc:
            result["evaluation_error"] = f"{type(exc).__name__}: {exc}"
    # who moved, from the truth: from where each robot stood at its last search record
    far = excursions(obs.truth, ids, obs.record_sample)
    result["moved_m"] = {str(i): m for i, m in far.items()}
    result["movers"] = [i for i in ids if far.get(i, 0.0) > MOVED_M]
    result["injected_faults"] = injected_faults(result)
    # the shape, from the true final poses alone (the fleet's members: all but those it
    # left out)
    left_out = set(result.get("excluded", []))  # named by the fleet: they only stand still
    members = [i for i in ids if i not in left_out]
    judged = False
    if obs.truth and members:
        final = load_shape(final_shape_spec(result))  # the last shape taken
        verdict = judge_shape(obs.truth[-1][1], members, d_e, phi_e, final)
        result["pairs"], result["shape"] = verdict.rows, verdict.summary()
        result.setdefault("leader", verdict.leader)
        judged = not verdict.missing
    rows = result["pairs"]
    result["max_abs_r_d"] = max((abs(r["r_d"]) for r in rows), default=math.nan)
    result["max_abs_r_phi"] = max((abs(r["r_phi"]) for r in rows), default=math.nan)
    within = bool(result.get("shape", {}).get("ok"))
    result["within_tolerance"] = within
    ok_agents = all(
        views[i].exit_code == 0 and views[i].phase == "done" for i in ids if i not in left_out
    )
    result.update(fleet_verdict(views, ids, ok_agents, within, judged))
    # The agents planned from exactly the records the robots signed: the evaluator, which
    # accepts only verified envelopes, recomputes the same plan digest from them.
    result["plan_matches_records"] = bool(digests) and digests == {
        result.get("evaluator_plan_digest")
    }
    trusted = True
    rogues = rogue_reports(out)
    if result.get("rogues_started"):
        result["rogues"] = rogues
        result["untrusted"] = untrusted_because(result, rogues)
        trusted = not result["untrusted"]
        result["rogue_defeated"] = trusted
    marched = result.get("march_ok", True) and result.get("reshape_ok", True)
    result["outcome"], result["outcome_detail"] = outcome(result)
    result["success"] = bool(
        result["outcome"] == "complete" and "timeout" not in result and trusted and marched
    )
    if obs.truth:
        try:
            plot(obs, result, out / "formation.png")
            result["figure"] = str(out / "formation.png")
        except (ValueError, KeyError) as exc:
            result["figure_error"] = str(exc)
    result["recording"] = str(out / "run.mcap")
    (out / "result.json").write_text(json.dumps(result, indent=2, default=float))
    if not quiet:
        print_table(result)
    return result


def untrusted_because(result: dict[str, Any], rogues: dict[str, Any]) -> list[str]:
    """Why a run with rogues cannot be called defended, in words (empty: it can): the plan
    recomputed from the signed records differs, a rogue's report is missing, or a rogue had
    a command executed or a claim granted."""
    why = []
    if not result["plan_matches_records"]:
        why.append(
            "the plan recomputed from the signed records the observer holds "
            f"(robots {sorted(result.get('record_rounds', {}), key=int)}) differs from the agents'"
        )
    missing = sorted(set(result["rogues_started"]) - set(rogues))
    if missing:
        why.append(f"no report from rogue {', '.join(missing)}")
    for name, rep in sorted(rogues.items()):
        if rep.get("commands_executed", 0) or rep.get("claims_granted", 0):
            why.append(f"rogue {name} had a command executed or a claim granted")
    return why
