"""What packet loss does to the formation (DESIGN.md §3 "Agree", §6 fault injection).

The NAO paper (4.1.2) sends every neighbour record once and assumes lossless WiFi; this
project re-publishes records until every agent holds the same record-set digest. This
tool measures that protocol under real IP packet loss. For every loss rate and seed it
builds ``robots + 3`` test hosts with :mod:`tools.netns` (all on this machine):

=========  ====================================================================
host 1     zenoh router (``python -m tools.router``), the rendezvous
host 2     the world (``python -m sim``)
host 3     a monitor (this module, ``--monitor``) that records what it sees on the bus
host 4..   one agent each (``python -m agent --id auto``)
=========  ====================================================================

Every process gets only the router's endpoint, multicast scouting off. On every agent
host :mod:`tools.packet_drop` drops packets with probability ``loss`` in both directions,
except traffic with the world host: on a real NAO the camera and the legs are on board,
only the robot-to-robot exchange crosses the radio (``--lossy-world`` drops that too).

Per run it records: success (every agent exits 0, reaches ``done``, all plan digests
equal, no contact), agreement time (wall seconds from the agents' start until the last
agent leaves the ``agree`` phase), bytes published per agent (the agents' own
``bytes_sent``; bytes the monitor received as a fallback) and the packets dropped. It
writes ``results.json`` and ``loss.png`` (success rate, agreement time and bytes vs loss)
under ``--out`` and prints a table.

``python -m tools.eval_loss --loss 0,0.1,0.3 --robots 3 --seeds 3 [--out out/eval_loss]``
Needs root, iproute2 and iptables (network namespaces).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from agent import protocol as P
from tools import netns
from tools.packet_drop import Dropper

REPO = Path(__file__).resolve().parents[1]
ROUTER_PORT = 7447
AGREED_PHASES = ("plan", "wait", "move", "hold", "done")
TERMINAL_PHASES = ("done", "failed")


# =========================================================================== monitor


@dataclass
class AgentSeen:
    """What the monitor saw of one agent."""

    first_phase_t: dict[str, float] = field(default_factory=dict)  # wall time.time()
    phase: str = ""
    plan_digest: str = ""
    error: str = ""
    bytes_sent: int = 0
    bytes_observed: int = 0
    records: int = 0
    digests: int = 0
    t_sim: float = 0.0


def monitor(connect: list[str], out_path: Path, stop: threading.Event) -> dict[str, Any]:
    """Subscribe to the agents' and the truth keys until ``stop``; write a JSON summary."""
    import zenoh  # tools may use zenoh; imported here so the orchestrator stays light

    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps("peer"))
    cfg.insert_json5("connect/endpoints", json.dumps(connect))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    samples: queue.Queue[tuple[str, bytes, float]] = queue.Queue()
    agents: dict[int, AgentSeen] = {}
    truth: dict[str, Any] = {}
    rejected = 0
    with zenoh.open(cfg) as session:
        subs = [
            session.declare_subscriber(
                key,
                lambda s: samples.put((str(s.key_expr), s.payload.to_bytes(), time.time())),
            )
            for key in ("nao/**", P.KEY_WORLD_TRUTH_ALL)
        ]
        print("monitor ready", flush=True)
        while not stop.is_set():
            try:
                key, data, t = samples.get(timeout=0.2)
            except queue.Empty:
                continue
            try:
                if key.startswith("world/truth/"):
                    msg = P.decode(data)
                    if isinstance(msg, P.TruthPosesMsg):
                        truth["poses"] = [list(p) for p in msg.poses]
                        truth["t_sim"] = msg.t_sim
                        truth["contacts"] = max(int(truth.get("contacts", 0)), msg.contacts)
                    elif isinstance(msg, P.ContactMsg):
                        truth["contact_msgs"] = int(truth.get("contact_msgs", 0)) + 1
                    continue
                if key.startswith("nao/alive/"):
                    continue
                rid = P.id_from_key(key)
                seen = agents.setdefault(rid, AgentSeen())
                seen.bytes_observed += len(data)
                msg = P.decode(data)
                if isinstance(msg, P.StatusMsg):
                    seen.phase = msg.phase
                    seen.first_phase_t.setdefault(msg.phase, t)
                    seen.plan_digest = msg.plan_digest or seen.plan_digest
                    seen.error = msg.error or seen.error
                    seen.bytes_sent = max(seen.bytes_sent, msg.bytes_sent)
                    seen.t_sim = max(seen.t_sim, msg.t_sim)
                elif isinstance(msg, P.NeighborRecordMsg):
                    seen.records += 1
                elif isinstance(msg, P.DigestMsg):
                    seen.digests += 1
            except P.ProtocolError:
                rejected += 1
        del subs
    summary = {
        "agents": {str(k): asdict(v) for k, v in sorted(agents.items())},
        "truth": truth,
        "rejected": rejected,
    }
    out_path.write_text(json.dumps(summary))
    return summary


def _monitor_main(connect: list[str], out: str) -> int:
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    monitor(connect, Path(out), stop)
    return 0


# =========================================================================== one run


@dataclass
class RunResult:
    loss: float
    seed: int
    robots: int
    success: bool
    reason: str
    agree_s: float | None  # wall seconds from agents' start until the last one agreed
    wall_s: float
    bytes_per_agent: list[int]
    exit_codes: list[int | None]
    phases: list[str]
    same_plan: bool
    contacts: int
    dropped_packets: int


def _wait_line(proc: subprocess.Popen[str], prefix: str, deadline_s: float) -> bool:
    """Read ``proc``'s stdout until a line starting with ``prefix`` (False on timeout/exit)."""
    lines: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.put(line)

    threading.Thread(target=pump, daemon=True).start()
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        try:
            if lines.get(timeout=0.2).startswith(prefix):
                return True
        except queue.Empty:
            if proc.poll() is not None:
                return False
    return False


def run_once(
    loss: float,
    seed: int,
    robots: int,
    timeout_s: float,
    workdir: Path,
    prefix: str,
    lossy_world: bool = False,
) -> RunResult:
    """One formation run with ``loss`` on every agent host; processes' logs in ``workdir``."""
    workdir.mkdir(parents=True, exist_ok=True)
    py = sys.executable
    env = dict(os.environ, PYTHONUNBUFFERED="1", MPLBACKEND="Agg")
    t_start = time.monotonic()
    with netns.Fabric(robots + 3, prefix=prefix) as fab, contextlib.ExitStack() as files:
        router_ep = f"tcp/{fab.address(1)}:{ROUTER_PORT}"
        common = ["--connect", router_ep, "--no-multicast-scouting"]

        def log(name: str) -> Any:
            return files.enter_context(open(workdir / f"{name}.log", "w"))

        router = fab.popen(
            1,
            [py, "-m", "tools.router", "--listen", router_ep, "--no-multicast-scouting"],
            stderr=log("router"),
            env=env,
            cwd=str(REPO),
        )
        if not _wait_line(router, "router ready", 30.0):
            raise RuntimeError(f"router did not start; see {workdir / 'router.log'}")
        fab.popen(
            2,
            [py, "-m", "sim", "--robots", str(robots), "--seed", str(seed), *common],
            stdout=log("world"),
            stderr=subprocess.STDOUT,
            env=env,
            cwd=str(REPO),
        )
        mon_out = workdir / "monitor.json"
        mon = fab.popen(
            3,
            [
                py,
                "-m",
                "tools.eval_loss",
                "--monitor",
                "--connect",
                router_ep,
                "--out",
                str(mon_out),
            ],
            stderr=log("monitor"),
            env=env,
            cwd=str(REPO),
        )
        if not _wait_line(mon, "monitor ready", 30.0):
            raise RuntimeError(f"monitor did not start; see {workdir / 'monitor.log'}")
        droppers = []
        for i in range(robots):
            d = Dropper(fab.name(4 + i))
            d.install(loss, "both", exempt=[] if lossy_world else [fab.address(2)])
            droppers.append(d)
        t_agents = time.time()
        agents = [
            fab.popen(
                4 + i,
                [py, "-m", "agent", "--id", "auto", "--fleet-size", str(robots), *common],
                stdout=log(f"agent{i + 1}"),
                stderr=subprocess.STDOUT,
                env=env,
                cwd=str(REPO),
            )
            for i in range(robots)
        ]
        end = time.monotonic() + timeout_s
        while time.monotonic() < end and any(a.poll() is None for a in agents):
            time.sleep(0.5)
        timed_out = any(a.poll() is None for a in agents)
        exit_codes = [a.poll() for a in agents]
        dropped = sum(d.dropped_packets() for d in droppers)
        time.sleep(1.0)  # let the last status/truth publications reach the monitor
        netns.stop(mon, timeout=10.0)
    wall = time.monotonic() - t_start
    seen = json.loads(mon_out.read_text()) if mon_out.exists() else {"agents": {}, "truth": {}}
    agents_seen: dict[str, Any] = seen["agents"]
    phases = [agents_seen[k]["phase"] for k in sorted(agents_seen, key=int)]
    digests = {agents_seen[k]["plan_digest"] for k in agents_seen}
    same_plan = len(agents_seen) == robots and len(digests) == 1 and "" not in digests
    agree_times = [
        min((v["first_phase_t"][p] for p in AGREED_PHASES if p in v["first_phase_t"]), default=None)
        for v in agents_seen.values()
    ]
    agree_s = (
        max(t for t in agree_times if t is not None) - t_agents
        if agree_times and len(agents_seen) == robots and all(t is not None for t in agree_times)
        else None
    )
    bytes_per_agent = [
        int(agents_seen[k]["bytes_sent"] or agents_seen[k]["bytes_observed"])
        for k in sorted(agents_seen, key=int)
    ]
    contacts = int(seen["truth"].get("contacts", 0)) + int(seen["truth"].get("contact_msgs", 0))
    if timed_out:
        reason = f"timeout after {timeout_s:.0f} s"
    elif any(c != 0 for c in exit_codes):
        reason = f"agent exit codes {exit_codes}"
    elif len(agents_seen) != robots:
        reason = f"monitor saw {len(agents_seen)} of {robots} agents"
    elif any(p != "done" for p in phases):
        reason = f"final phases {phases}"
    elif not same_plan:
        reason = "agents disagree on the plan digest"
    elif contacts:
        reason = f"{contacts} contacts"
    else:
        reason = "ok"
    return RunResult(
        loss=loss,
        seed=seed,
        robots=robots,
        success=reason == "ok",
        reason=reason,
        agree_s=agree_s,
        wall_s=wall,
        bytes_per_agent=bytes_per_agent,
        exit_codes=exit_codes,
        phases=phases,
        same_plan=same_plan,
        contacts=contacts,
        dropped_packets=dropped,
    )


# =========================================================================== report


def summarise(results: list[RunResult]) -> list[dict[str, Any]]:
    """Per loss rate: success rate, mean/max agreement time, mean bytes per agent."""
    rows = []
    for loss in sorted({r.loss for r in results}):
        rs = [r for r in results if r.loss == loss]
        agree = [r.agree_s for r in rs if r.agree_s is not None]
        per_agent = [b for r in rs for b in r.bytes_per_agent]
        rows.append(
            {
                "loss": loss,
                "runs": len(rs),
                "success_rate": sum(r.success for r in rs) / len(rs),
                "agree_s_mean": sum(agree) / len(agree) if agree else None,
                "agree_s_max": max(agree) if agree else None,
                "bytes_per_agent_mean": sum(per_agent) / len(per_agent) if per_agent else None,
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
        ax.plot(loss, ys, "o-")
        ax.set_xlabel("packet loss per direction [%]")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].set_ylim(-0.05, 1.05)
    fig.suptitle("Formation under packet loss (iptables DROP on every agent host)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fmt(v: float | None, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.eval_loss", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--loss", default="0,0.1,0.3", help="comma-separated drop probabilities")
    ap.add_argument("--robots", type=int, default=3)
    ap.add_argument("--seeds", type=int, default=3, help="seeds 1..S per loss rate")
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per run")
    ap.add_argument("--out", default="out/eval_loss")
    ap.add_argument("--prefix", default="nel", help="namespace prefix (tools.netns)")
    ap.add_argument("--lossy-world", action="store_true", help="drop world traffic too")
    ap.add_argument("--monitor", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--connect", action="append", default=[], help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.monitor:
        return _monitor_main(args.connect, args.out)
    try:
        losses = [float(x) for x in args.loss.split(",") if x.strip()]
    except ValueError:
        print(
            f"eval_loss: --loss {args.loss!r} is not a comma-separated list of numbers",
            file=sys.stderr,
        )
        return 2
    if not losses or any(not 0.0 <= x <= 1.0 for x in losses):
        print("eval_loss: every --loss value must be a probability in [0, 1]", file=sys.stderr)
        return 2
    if not 1 <= args.robots <= 20 or args.seeds < 1:
        print("eval_loss: --robots must be in [1, 20] and --seeds >= 1", file=sys.stderr)
        return 2
    try:
        netns.preflight()
    except netns.NetnsError as exc:
        print(f"eval_loss: {exc}", file=sys.stderr)
        return 1
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results: list[RunResult] = []
    total = len(losses) * args.seeds
    for loss in losses:
        for seed in range(1, args.seeds + 1):
            n = len(results) + 1
            print(f"[{n}/{total}] loss {loss:g} seed {seed} ...", file=sys.stderr, flush=True)
            try:
                r = run_once(
                    loss, seed, args.robots, args.timeout,
                    out / f"loss{loss:g}_seed{seed}", args.prefix, args.lossy_world,
                )  # fmt: skip
            except (RuntimeError, netns.NetnsError, OSError) as exc:
                print(f"eval_loss: run failed to start: {exc}", file=sys.stderr)
                return 1
            results.append(r)
            print(
                f"[{n}/{total}] {'OK  ' if r.success else 'FAIL'} {r.reason}; agree "
                f"{_fmt(r.agree_s, '.1f')} s, bytes/agent {r.bytes_per_agent}, "
                f"dropped {r.dropped_packets} pkts, wall {r.wall_s:.0f} s",
                file=sys.stderr,
                flush=True,
            )
    rows = summarise(results)
    doc = {
        "robots": args.robots,
        "seeds": args.seeds,
        "lossy_world": args.lossy_world,
        "summary": rows,
        "runs": [asdict(r) for r in results],
    }
    (out / "results.json").write_text(json.dumps(doc, indent=2))
    plot(rows, out / "loss.png")
    print(
        f"{'loss':>6} {'runs':>5} {'success':>8} {'agree s':>8} {'max s':>7} {'B/agent':>9} {'dropped':>8}"
    )
    for row in rows:
        print(
            f"{row['loss']:6.2f} {row['runs']:5d} {row['success_rate']:8.0%} "
            f"{_fmt(row['agree_s_mean'], '8.1f')} {_fmt(row['agree_s_max'], '7.1f')} "
            f"{_fmt(row['bytes_per_agent_mean'], '9.0f')} {row['dropped_packets_mean']:8.0f}"
        )
    print(f"wrote {out / 'results.json'} and {out / 'loss.png'}")
    return 0 if all(r.success for r in results) else 3


if __name__ == "__main__":
    raise SystemExit(main())
