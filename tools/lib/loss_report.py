"""The rows and report of ``tools.eval_loss`` (docs/faults.md "Loss tolerance"): a run's result
(:class:`RunResult`), why it failed (:func:`run_reason`), its row of the shared report
(:func:`run_row`, :mod:`tools.harness.report`), and per loss rate the success rate, the
agreement time and the bytes each agent published, as a table and a figure.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from tools.harness import report
from tools.harness.judge import outcome


@dataclass
class RunResult:
    loss: float
    seed: int
    robots: int
    success: bool
    reason: str
    agree_s: float | None  # last agent entering exchange -> last agent agreed (wall s)
    wall_s: float
    bytes_per_agent: list[int]  # everything each agent published (record+digest+status)
    exchange_bytes_per_agent: list[int]  # records + digests only
    exit_codes: list[int | None]
    phases: list[str]
    same_plan: bool
    contacts: int
    max_abs_r_d: float
    max_abs_r_phi: float
    dropped_packets: int
    out: str


def run_reason(res: dict[str, Any], robots: int) -> str:
    """Why a run failed by the loss tool's strict reading of the monitor's ``result.json``
    (``ok`` when it succeeded)."""
    if res.get("timeout"):
        return str(res["timeout"])
    codes = list(res.get("exit_codes", {}).values())
    if len(codes) != robots or any(c != 0 for c in codes):
        errors = "; ".join(sorted(set(res.get("errors", {}).values())))[:160]
        return f"agent exit codes {codes}" + (f": {errors}" if errors else "")
    if set(res.get("final_phase", {}).values()) != {"done"}:
        return f"final phases {res.get('final_phase')}"
    if not res.get("identical_digests"):
        return "plan digests differ"
    if res.get("contacts", 0):
        return f"{res['contacts']} contacts"
    if not res.get("within_tolerance"):
        return (
            f"outside tolerance: max|r_d| {res.get('max_abs_r_d', math.nan):.1%}, "
            f"max|r_phi| {res.get('max_abs_r_phi', math.nan):.1%}"
        )
    return "ok"


def run_row(r: RunResult, res: dict[str, Any]) -> dict[str, Any]:
    """One run in the rows of :mod:`tools.harness.report` (the JSON schema shared with
    ``tools.eval_faults``): its outcome and detail by :func:`tools.harness.judge.outcome`
    from the monitor's ``result.json`` (``res``; empty: ``no_result``, a failure)."""
    oc, detail = outcome(res or {"no_result": r.reason})
    return {
        "seed": r.seed,
        "loss": r.loss,
        "outcome": oc,
        "contacts": r.contacts,
        "wall_s": round(r.wall_s, 1),
        "detail": detail,
    }


def summarise(results: Sequence[RunResult]) -> list[dict[str, Any]]:
    """Per loss rate: success rate, mean/max agreement time, mean bytes per agent."""
    rows = []
    for loss in sorted({r.loss for r in results}):
        rs = [r for r in results if r.loss == loss]
        agree = [r.agree_s for r in rs if r.agree_s is not None]
        per_agent = [b for r in rs for b in r.bytes_per_agent]
        exch = [b for r in rs for b in r.exchange_bytes_per_agent]
        rows.append(
            {
                "loss": loss,
                "runs": len(rs),
                "success_rate": sum(r.success for r in rs) / len(rs),
                "agree_s_mean": sum(agree) / len(agree) if agree else None,
                "agree_s_max": max(agree) if agree else None,
                "bytes_per_agent_mean": sum(per_agent) / len(per_agent) if per_agent else None,
                "exchange_bytes_per_agent_mean": sum(exch) / len(exch) if exch else None,
                "dropped_packets_mean": sum(r.dropped_packets for r in rs) / len(rs),
            }
        )
    return rows


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    loss = [100.0 * r["loss"] for r in rows]
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    series = [
        ("success_rate", "success rate", 1.0),
        ("agree_s_mean", "agreement time [s] (mean)", 1.0),
        ("bytes_per_agent_mean", "bytes published per agent [kB]", 1e-3),
    ]
    for ax, (key, label, scale) in zip(axes, series):
        ys = [r[key] * scale if r[key] is not None else math.nan for r in rows]
        ax.plot(
            loss, ys, "o-", label="all (record+digest+status)" if key.startswith("bytes") else None
        )
        if key.startswith("bytes"):
            ex = [
                r["exchange_bytes_per_agent_mean"] * scale
                if r["exchange_bytes_per_agent_mean"] is not None
                else math.nan
                for r in rows
            ]
            ax.plot(loss, ex, "s--", label="exchange (record+digest)")
            ax.legend(fontsize=8)
        ax.set_xlabel("packet loss per direction [%]")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].set_ylim(-0.05, 1.05)
    fig.suptitle("Formation under packet loss (iptables DROP on every agent host)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def fmt(v: float | None, spec: str) -> str:
    """``format(v, spec)``, or a dash right-aligned to the spec's width when ``v`` is None."""
    if v is not None:
        return format(v, spec)
    width = spec.split(".")[0]
    return "-".rjust(int(width) if width.isdigit() else 0)


def print_summary(summary: list[dict[str, Any]]) -> None:
    """The per-loss table of :func:`summarise`."""
    print(
        f"{'loss':>6} {'runs':>5} {'success':>8} {'agree s':>8} {'max s':>7} {'B/agent':>9} "
        f"{'exch B':>8} {'dropped':>8}"
    )
    for srow in summary:
        print(
            f"{srow['loss']:6.2f} {srow['runs']:5d} {srow['success_rate']:8.0%} "
            f"{fmt(srow['agree_s_mean'], '8.2f')} {fmt(srow['agree_s_max'], '7.2f')} "
            f"{fmt(srow['bytes_per_agent_mean'], '9.0f')} "
            f"{fmt(srow['exchange_bytes_per_agent_mean'], '8.0f')} {srow['dropped_packets_mean']:8.0f}"
        )


def write_report(
    results: Sequence[RunResult],
    rows: Sequence[Mapping[str, Any]],
    out: Path,
    json_path: Path,
    settings: Mapping[str, Any],
) -> None:
    """The matrix's report: ``results.json`` (the settings, :func:`summarise` and every
    run), ``loss.png``, the shared ``outcomes.png`` and tables; ``settings``: the tool's
    flags (robots, seeds, seed_start, lossy_world, agent_mode, tcp_rto_max_ms, insecure)."""
    summary = summarise(results)
    keys = ("robots", "seeds", "lossy_world", "agent_mode", "tcp_rto_max_ms")
    doc = {**{k: settings[k] for k in keys}, "summary": summary,
           "runs": [asdict(r) for r in results]}  # fmt: skip
    (out / "results.json").write_text(json.dumps(doc, indent=2))
    plot(summary, out / "loss.png")
    s = settings
    first, last = s["seed_start"], s["seed_start"] + s["seeds"] - 1
    report.plot_outcomes(
        report.count_outcomes(
            sorted(rows, key=lambda r: float(r["loss"])), "loss", name=lambda x: f"{100 * x:g} %"
        ),
        out / "outcomes.png",
        f"{s['robots']} robots, seeds {first}..{last}, "
        f"{'insecure' if s['insecure'] else 'TLS router'}, world traffic "
        f"{'lossy' if s['lossy_world'] else 'exempt'}"
        + (f", TCP RTO <= {s['tcp_rto_max_ms']} ms" if s["tcp_rto_max_ms"] else ""),
        ylabel="packet loss per direction",
    )
    report.print_runs(rows, "loss", detail_width=70)
    print_summary(summary)
    print(f"wrote {json_path}, {out / 'results.json'}, {out / 'loss.png'}, {out / 'outcomes.png'}")
