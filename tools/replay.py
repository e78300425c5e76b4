"""``python -m tools.replay FILE.mcap [--out DIR] [--frames K]``: replay a demo recording.

Reads the MCAP written by ``tools.demo``: its msgpack channels (the wire messages of
agent/wire/, one channel per key; the JSON channels for Foxglove are skipped), validates
every message with the protocol codec, prints the
timeline (phase changes of every agent, records and digests exchanged, contacts) and
writes ``DIR/replay.png`` (paths walked from the truth stream, final poses) and ``K``
animation frames ``DIR/frame-XXX.png`` evenly spaced over the run. Times are wall
seconds since the first message (the messages' publish times).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agent.wire import (
    ContactMsg,
    DigestMsg,
    NeighborRecordMsg,
    StatusMsg,
    TruthPosesMsg,
    decode,
    reason,
)


@dataclass
class Replay:
    t0_ns: int = 0
    events: list[tuple[float, str]] = field(default_factory=list)
    truth: list[tuple[float, dict[int, tuple[float, float, float]]]] = field(default_factory=list)
    rejected: int = 0
    messages: int = 0


def load(path: Path) -> Replay:
    from mcap.reader import make_reader

    rp = Replay()
    last_phase: dict[int, str] = {}
    with path.open("rb") as f:
        reader = make_reader(f)
        for _, channel, message in reader.iter_messages(log_time_order=False):
            if channel.message_encoding != "msgpack":
                continue  # Foxglove's view of the run (tools/harness/view/scene.py)
            if rp.t0_ns == 0:
                rp.t0_ns = message.publish_time
            t = (message.publish_time - rp.t0_ns) / 1e9
            rp.messages += 1
            try:
                msg: Any = decode(message.data)
            except Exception as exc:  # ProtocolError, or anything unforeseen: count, go on
                rp.rejected += 1
                rp.events.append((t, f"rejected message on {channel.topic}: {reason(exc)}"))
                continue
            if isinstance(msg, TruthPosesMsg):
                rp.truth.append((t, {p[0]: (p[1], p[2], p[3]) for p in msg.poses}))
            elif isinstance(msg, StatusMsg):
                if last_phase.get(msg.sender) != msg.phase:
                    last_phase[msg.sender] = msg.phase
                    extra = msg.error or msg.detail
                    rp.events.append(
                        (t, f"robot {msg.sender}: {msg.phase:9s} t_sim {msg.t_sim:6.1f}s  {extra}")
                    )
            elif isinstance(msg, NeighborRecordMsg):
                n_nb, size = len(msg.neighbours), len(message.data)
                text = f"robot {msg.sender}: record round {msg.round}, {n_nb} neighbours, {size} B"
                rp.events.append((t, text))
            elif isinstance(msg, DigestMsg):
                rp.events.append(
                    (t, f"robot {msg.sender}: digest {msg.digest[:12]} over {list(msg.members)}")
                )
            elif isinstance(msg, ContactMsg):
                rp.events.append((t, f"CONTACT {msg.a} - {msg.b} at t_sim {msg.t_sim:.1f}s"))
    return rp


def draw(rp: Replay, path: Path, upto: float | None = None, title: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    truth = [(t, p) for t, p in rp.truth if upto is None or t <= upto]
    fig, ax = plt.subplots(figsize=(6, 6))
    cmap = plt.get_cmap("tab10")
    ids = sorted({i for _, p in rp.truth for i in p})
    allx = [p[i][0] for _, p in rp.truth for i in p]
    ally = [p[i][1] for _, p in rp.truth for i in p]
    for k, i in enumerate(ids):
        xs = [p[i][0] for _, p in truth if i in p]
        ys = [p[i][1] for _, p in truth if i in p]
        if not xs:
            continue
        c = cmap(k % 10)
        ax.plot(xs, ys, "-", color=c, lw=1.2)
        ax.plot(xs[0], ys[0], "o", mfc="white", mec=c, ms=9)
        x, y, h = truth[-1][1][i]
        ax.add_patch(plt.Circle((x, y), 0.2, color=c, alpha=0.35))
        ax.plot([x, x + 0.25 * math.cos(h)], [y, y + 0.25 * math.sin(h)], "-", color=c, lw=2)
        ax.text(x + 0.05, y + 0.05, str(i), weight="bold")
    if allx:
        pad = 0.5
        ax.set_xlim(min(allx) - pad, max(allx) + pad)
        ax.set_ylim(min(ally) - pad, max(ally) + pad)
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("world x (m)")
    ax.set_ylabel("world y (m)")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tools.replay", description=__doc__.split("\n\n")[0])
    p.add_argument("file", type=Path)
    p.add_argument("--out", type=Path, default=None, help="output directory (default: beside FILE)")
    p.add_argument("--frames", type=int, default=12, help="animation frames to write (0: none)")
    args = p.parse_args(argv)
    if not args.file.is_file():
        print(f"replay: no such file {args.file}", file=sys.stderr)
        return 2
    if args.frames < 0:
        p.error("--frames must be >= 0")
    out = args.out or args.file.parent / "replay"
    out.mkdir(parents=True, exist_ok=True)
    try:
        rp = load(args.file)
    except Exception as exc:  # a truncated or foreign file: say so, do not crash
        print(f"replay: cannot read {args.file}: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    for t, text in rp.events:
        print(f"[{t:7.2f}s] {text}")
    print(f"{rp.messages} messages, {len(rp.truth)} truth samples, {rp.rejected} rejected")
    if not rp.truth:
        print("no ground truth in the recording: no figure", file=sys.stderr)
        return 0 if rp.messages else 1
    draw(rp, out / "replay.png", title=f"replay of {args.file.name}")
    end = rp.truth[-1][0]
    for k in range(args.frames):
        t = end * (k + 1) / args.frames
        draw(rp, out / f"frame-{k:03d}.png", upto=t, title=f"t = {t:.1f} s (wall)")
        print(f"frame {k + 1}/{args.frames}", file=sys.stderr)
    print(f"wrote {out / 'replay.png'} and {args.frames} frames in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
