"""``python -m tools.bench agent``: cost of the agreement (agent/core/agreement.py) in messages,
bytes and rounds, for fleets of N agents over a lossy broadcast medium (seeded).

Each agent runs the real :class:`agent.core.agreement.Agreement`; the medium delivers every
publication to every other agent independently with probability 1 - loss, in 50 ms
ticks. Prints, per (N, loss): runs agreed, time to agreement (simulated seconds) and the
record + digest bytes each agent published (mean and max). Writes a PNG with ``--out``.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np

from agent.core.agreement import Agreement, DigestNote
from agent.wire import DigestMsg, NeighborRecordMsg, canonical_digest, encode


def record(i: int, n: int) -> NeighborRecordMsg:
    k = min(n - 1, 6)  # a few neighbours each, like the simulated fleets
    nb = tuple((0.8 + 0.01 * i, 0.1 * j) for j in range(k))
    return NeighborRecordMsg(sender=i, round=0, neighbours=nb, confidences=(0.9,) * k)


def simulate(
    n: int,
    loss: float,
    rng: np.random.Generator,
    limit: float = 120.0,
    stagger: float = 0.0,
    latency: float = 0.0,
) -> dict[str, float]:
    """One fleet: agent i starts exchanging at ``U(0, stagger)`` s (its search ends then);
    before that it only collects what it hears, as the runner's early records and digests.
    Every agent is a live member from the start (liveliness tokens outlive the search).
    A publication reaches the others ``latency`` s after it is sent (a loaded host: at
    50 NAOs on 2 cores, digests sent before a record arrived keep arriving after it)."""
    starts = {i: float(rng.uniform(0.0, stagger)) if stagger > 0 else 0.0 for i in range(n)}
    agents: dict[int, Agreement[NeighborRecordMsg]] = {}
    early: dict[int, dict[int, NeighborRecordMsg | DigestNote]] = {i: {} for i in range(n)}
    sent = dict.fromkeys(range(n), 0)
    t, dt, agreed_at = 0.0, 0.05, dict.fromkeys(range(n), -1.0)
    flight: list[tuple[float, int, int, NeighborRecordMsg | DigestNote]] = []
    while t < limit:
        t += dt
        for i in range(n):
            if i not in agents and t >= starts[i]:
                a = Agreement(
                    i, record(i, n), t, fleet_size=n, timeout=limit, digest_fn=canonical_digest
                )
                for j in range(n):
                    a.member_joined(j, t)
                for _j, m in sorted(early[i].items(), key=lambda kv: kv[0]):
                    if isinstance(m, NeighborRecordMsg):
                        a.on_record(m, t)
                for _j, m in sorted(early[i].items(), key=lambda kv: kv[0]):
                    if isinstance(m, DigestNote):
                        a.on_digest(m, t)
                agents[i] = a
        arrived = [f for f in flight if f[0] <= t + 1e-9]
        flight = [f for f in flight if f[0] > t + 1e-9]
        for _, j, i, note in arrived:
            b = agents.get(j)
            if b is None:  # still searching: kept for later, newest wins
                early[j][i + (0 if isinstance(note, NeighborRecordMsg) else n)] = note
            elif isinstance(note, NeighborRecordMsg):
                b.on_record(note, t)
            else:
                b.on_digest(note, t)
        for i, a in list(agents.items()):
            due = a.due(t)
            for what in due:
                msg = a.records[i] if what == "record" else DigestMsg(**asdict(a.digest_note()))
                sent[i] += len(encode(msg))
                note = a.records[i] if what == "record" else a.digest_note()
                for j in range(n):
                    if j != i and rng.random() >= loss:
                        flight.append((t + latency, j, i, note))
            a.sent(due, t)
            if a.decide(t).kind == "agreed" and agreed_at[i] < 0:
                agreed_at[i] = t
                for b in agents.values():
                    b.on_peer_phase(i, "plan")  # its next status acknowledges
        if (
            len(agents) == n
            and not flight
            and all(v >= 0 for v in agreed_at.values())
            and not any(a.due(t + 100.0) for a in agents.values())
        ):
            break
    ok = len(agents) == n and all(v >= 0 for v in agreed_at.values())
    digests = {a.decide(t).digest for a in agents.values()}
    last_start = max(starts.values())
    return {
        "agreed": float(ok and len(digests) == 1),
        "t_agree": max(agreed_at.values()) - last_start if ok else float("nan"),
        "bytes_mean": float(np.mean(list(sent.values()))),
        "bytes_max": float(max(sent.values())),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m tools.bench agent", description=__doc__.split("\n\n")[0]
    )
    p.add_argument("--sizes", type=int, nargs="+", default=[3, 6, 10, 15])
    p.add_argument("--losses", type=float, nargs="+", default=[0.0, 0.1, 0.3])
    p.add_argument("--runs", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--stagger",
        type=float,
        default=0.0,
        metavar="S",
        help="agents finish their search at U(0, S) s (0: all at once)",
    )
    p.add_argument("--out", type=Path, default=None, help="PNG of bytes per agent vs N")
    a = p.parse_args(argv)
    if any(n < 1 for n in a.sizes) or any(not 0 <= x < 1 for x in a.losses) or a.runs < 1:
        p.error("sizes >= 1, losses in [0, 1), runs >= 1")
    rng = np.random.default_rng(a.seed)
    rows = []
    print(
        f"{'N':>3} {'loss':>5} {'agreed':>7} {'t_agree s':>9} {'B/agent mean':>12} {'B/agent max':>11}"
    )
    for n in a.sizes:
        for loss in a.losses:
            rs = [simulate(n, loss, rng, stagger=a.stagger) for _ in range(a.runs)]
            row = {
                "n": n,
                "loss": loss,
                "agreed": sum(r["agreed"] for r in rs),
                "t": float(np.nanmedian([r["t_agree"] for r in rs])),
                "mean": float(np.mean([r["bytes_mean"] for r in rs])),
                "max": float(max(r["bytes_max"] for r in rs)),
            }
            rows.append(row)
            print(
                f"{n:3d} {loss:5.2f} {int(row['agreed']):3d}/{a.runs:<3d} {row['t']:9.2f} "
                f"{row['mean']:12.0f} {row['max']:11.0f}"
            )
            print(f"  N={n} loss={loss} done", file=sys.stderr)
    if a.out is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 4))
        for loss in a.losses:
            sel = [r for r in rows if r["loss"] == loss]
            ax.plot([r["n"] for r in sel], [r["mean"] for r in sel], "o-", label=f"loss {loss:.0%}")
        ax.set_xlabel("fleet size N")
        ax.set_ylabel("record + digest bytes per agent")
        ax.grid(True, alpha=0.3)
        ax.legend()
        fig.tight_layout()
        a.out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(a.out, dpi=100)
        print(f"wrote {a.out}")
    return 0
