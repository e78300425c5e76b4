"""What packet loss does to the formation (docs/design.md §1 "Agree", §6 fault injection).

The NAO paper (4.1.2) sends every neighbour record once and assumes lossless WiFi; this
project re-publishes records until every agent holds the same record-set digest. This
tool measures that protocol under real IP packet loss. For every loss rate and seed it
builds ``robots + 3`` test hosts with :mod:`tools.netns` (all on this machine):

=========  ====================================================================
host 1     zenoh router (``python -m tools.router``), the rendezvous
host 2     the world (``python -m sim``)
host 3     a monitor (this module, ``--monitor``) that records what it sees on the bus
host 4..   one agent each (``python -m agent --id I``, ids from the world's ready line)
=========  ====================================================================

Every process gets only the router's endpoint, multicast scouting off. On every agent
host :mod:`tools.packet_drop` drops packets with probability ``loss`` in both directions,
except traffic with the world host: on a real NAO the camera and the legs are on board,
only the robot-to-robot exchange crosses the radio (``--lossy-world`` drops that too).

A monitor on its own (lossless) host (:mod:`tools.harness.monitor`) observes the bus and
judges each run with ``tools.harness``'s criteria (every agent exits 0 in ``done``, identical
plan digests, no contact, every pair within |r_d| <= 12.5 % and |r_φ| <= 30 %). Per run
it also records the agreement time (wall seconds from the last agent entering
``exchange`` to the last agent leaving ``agree``: the cost of the protocol, not of the
search), the bytes each agent published (all, and records + digests only) and the
packets dropped. Each run's outcome is that of :func:`tools.harness.judge.outcome`,
reported as every evaluation tool does (:mod:`tools.harness.report`: ``--json``, the
table, ``outcomes.png``). It writes ``results.json`` and ``loss.png`` (success rate,
agreement time and bytes vs loss) under ``--out``, one directory per run with the
processes' logs, ``result.json``, ``formation.png`` and ``run.mcap``, and prints a table.

``python -m tools.eval_loss --loss 0,0.1,0.3 --robots 3 --seeds 3 [--out out/eval_loss]``
Needs root, iproute2 and iptables (network namespaces).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import signal
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from types import FrameType
from typing import Any

from agent import wire as P
from tools import netns
from tools.harness import report
from tools.harness.judge import outcome
from tools.harness.monitor import monitor
from tools.harness.procs import Lines
from tools.harness.progress import Progress
from tools.packet_drop import Dropper

REPO = Path(__file__).resolve().parents[1]


#: Bounds of Linux's ``net.ipv4.tcp_rto_max_ms`` (kernel >= 6.15; ms).
TCP_RTO_MAX_RANGE = (1000, 120000)


def cap_tcp_rto(fab: netns.Fabric, ms: int) -> None:
    """Cap TCP's retransmission timeout at ``ms`` on every host of ``fab``.

    TCP doubles its retransmission timeout after every lost retransmission, up to 120 s by
    default: at 50 % loss per direction (a segment and its ACK both get through with
    probability 1/4) six losses in a row, probability 0.75^6 ≈ 18 %, already stall a zenoh
    session for about 25 s, longer than the membership grace. With a cap the session
    keeps probing every ``ms``. ``net.ipv4.tcp_rto_max_ms`` is per network namespace, so
    only the test hosts change; on robots it is a deployment setting of their kernels.
    """
    lo, hi = TCP_RTO_MAX_RANGE
    if not lo <= ms <= hi:
        raise ValueError(f"tcp_rto_max_ms must be in [{lo}, {hi}], got {ms}")
    for i in range(1, fab.n + 1):
        fab.run(i, ["sysctl", "-q", "-w", f"net.ipv4.tcp_rto_max_ms={ms}"])


# =========================================================================== one run


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


def _reason(res: dict[str, Any], robots: int) -> str:
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


def run_once(
    loss: float,
    seed: int,
    robots: int,
    timeout_s: float,
    workdir: Path,
    prefix: str,
    lossy_world: bool = False,
    d_e: float = 0.8,
    phi_e_deg: float = 30.0,
    agent_mode: str = "client",
    credentials: str = "",
    tcp_rto_max_ms: int = 0,
) -> RunResult:
    """One formation run with ``loss`` on every agent host; logs and results in ``workdir``.

    ``credentials``: a fleet folder made for ``robots`` robots and the router's address
    (secure: TLS links, signatures); empty: insecure. ``tcp_rto_max_ms``: when > 0, every
    host's kernel caps TCP's retransmission timeout there (see :func:`cap_tcp_rto`)."""
    from tools.harness.procs import robot_ids, router_command, world_command

    workdir.mkdir(parents=True, exist_ok=True)
    py = sys.executable
    env = dict(os.environ, PYTHONUNBUFFERED="1", MPLBACKEND="Agg")
    t_start = time.monotonic()
    proto = "tls" if credentials else "tcp"
    with netns.Fabric(robots + 3, prefix=prefix) as fab, contextlib.ExitStack() as files:
        if tcp_rto_max_ms:
            cap_tcp_rto(fab, tcp_rto_max_ms)
        router_ep = f"{proto}/{fab.address(1)}:{P.BUS_PORT}"
        world_ep = f"{proto}/{fab.address(1)}:{P.WORLD_PORT}"
        sec = ["--credentials", credentials] if credentials else ["--insecure"]
        common = ["--connect", router_ep, "--no-multicast-scouting", *sec]
        world_net = ["--connect", world_ep, "--no-multicast-scouting", *sec]

        def log(name: str) -> Any:
            return files.enter_context(open(workdir / f"{name}.log", "w"))

        router = fab.popen(
            1,
            router_command(router_ep, ["--listen", world_ep, "--no-multicast-scouting", *sec]),
            stderr=log("router"),
            env=env,
            cwd=str(REPO),
        )
        if not Lines(router).wait_for("router ready", 30.0):
            raise RuntimeError(f"router did not start; see {workdir / 'router.log'}")
        mon = subprocess.Popen(
            netns.netns_cmd(
                fab.name(3),
                [
                    py, "-m", "tools.eval_loss", "--monitor", "--connect", router_ep,
                    "--out", str(workdir), "--d-e", str(d_e), "--phi-e-deg", str(phi_e_deg),
                    "--seed", str(seed), *sec,
                ],
            ),
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log("monitor"),
            text=True, env=env, cwd=str(REPO), start_new_session=True,
        )  # fmt: skip
        try:
            mon_lines = Lines(mon)
            if not mon_lines.wait_for("monitor ready", 30.0):
                raise RuntimeError(f"monitor did not start; see {workdir / 'monitor.log'}")
            world = fab.popen(
                2,
                world_command(robots, seed, world_net, []),
                stderr=log("world"),
                env=env,
                cwd=str(REPO),
            )
            world_lines = Lines(world)
            if not world_lines.wait_for("ready", 180.0):
                raise RuntimeError(f"world not ready; see {workdir / 'world.log'}")
            ids = robot_ids(world_lines.lines, robots)
            droppers = []
            for i in range(robots):
                d = Dropper(fab.name(4 + i))
                # the body sessions and the world's link use the router's world port
                d.install(loss, "both", exempt_ports=[] if lossy_world else [P.WORLD_PORT])
                droppers.append(d)
            agents = [
                fab.popen(
                    4 + i,
                    [
                        py,
                        "-m",
                        "agent",
                        "--id",
                        str(rid),
                        "--fleet-size",
                        str(robots),
                        "--mode",
                        agent_mode,
                        "--d-e",
                        str(d_e),
                        "--phi-e-deg",
                        str(phi_e_deg),
                        *common,
                        *([] if agent_mode == "peer" else ["--world-connect", world_ep]),
                    ],
                    stdout=log(f"agent-{rid}"),
                    stderr=subprocess.STDOUT,
                    env=env,
                    cwd=str(REPO),
                )
                for i, rid in enumerate(ids)
            ]
            end = time.monotonic() + timeout_s
            while time.monotonic() < end and any(a.poll() is None for a in agents):
                time.sleep(0.5)
            timed_out = any(a.poll() is None for a in agents)
            dropped = sum(d.dropped_packets() for d in droppers)
            order = {
                "ids": ids,
                "exit_codes": {str(i): a.poll() for i, a in zip(ids, agents)},
                "timeout": f"agents still running after {timeout_s:g} s" if timed_out else None,
            }
            assert mon.stdin is not None
            mon.stdin.write(json.dumps(order) + "\n")
            mon.stdin.flush()
            mon_lines.wait_for("monitor done", 60.0)
        finally:
            netns.stop(mon, timeout=10.0)
    wall = time.monotonic() - t_start
    res_path = workdir / "result.json"
    res: dict[str, Any] = json.loads(res_path.read_text()) if res_path.exists() else {}
    reason = _reason(res, robots) if res else "monitor wrote no result"
    bytes_tot = [int(b.get("total", 0)) for _, b in sorted(res.get("bytes", {}).items())]
    exch = [int(v) for _, v in sorted(res.get("exchange_bytes", {}).items())]
    return RunResult(
        loss=loss,
        seed=seed,
        robots=robots,
        success=bool(res.get("success")) and reason == "ok",
        reason=reason,
        agree_s=res.get("agree_s"),
        wall_s=wall,
        bytes_per_agent=bytes_tot,
        exchange_bytes_per_agent=exch,
        exit_codes=list(res.get("exit_codes", {}).values()),
        phases=list(res.get("final_phase", {}).values()),
        same_plan=bool(res.get("identical_digests")),
        contacts=int(res.get("contacts", 0)),
        max_abs_r_d=float(res.get("max_abs_r_d", math.nan)),
        max_abs_r_phi=float(res.get("max_abs_r_phi", math.nan)),
        dropped_packets=dropped,
        out=str(workdir),
    )


# =========================================================================== report


def summarise(results: list[RunResult]) -> list[dict[str, Any]]:
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


def _fmt(v: float | None, spec: str) -> str:
    """``format(v, spec)``, or a dash right-aligned to the spec's width when ``v`` is None."""
    if v is not None:
        return format(v, spec)
    width = spec.split(".")[0]
    return "-".rjust(int(width) if width.isdigit() else 0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.eval_loss", description=__doc__.split("\n")[0]
    )
    ap.add_argument("--loss", default="0,0.1,0.3", help="comma-separated drop probabilities")
    ap.add_argument("--robots", type=int, default=3)
    ap.add_argument("--seeds", type=int, default=3, help="seeds per loss rate")
    ap.add_argument("--seed-start", type=int, default=1, help="first seed (seeds S..S+K-1)")
    ap.add_argument(
        "--json",
        metavar="FILE",
        default=None,
        help='outcomes as {"runs": [{seed, loss, outcome, contacts, wall_s, detail}]} '
        "(default: OUT/runs.json)",
    )
    ap.add_argument("--seed", type=int, default=None, help="with --monitor: the run's seed")
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per run")
    ap.add_argument("--out", default="out/eval_loss")
    ap.add_argument("--prefix", default="nel", help="namespace prefix (tools.netns)")
    ap.add_argument("--lossy-world", action="store_true", help="drop world traffic too")
    ap.add_argument(
        "--tcp-rto-max-ms",
        type=int,
        default=0,
        metavar="MS",
        help="cap TCP's retransmission timeout on every test host (net.ipv4.tcp_rto_max_ms, "
        f"{TCP_RTO_MAX_RANGE[0]}-{TCP_RTO_MAX_RANGE[1]}; default 0: the kernel's 120 s)",
    )
    ap.add_argument(
        "--agent-mode",
        choices=("peer", "client"),
        default="client",
        help="zenoh mode of the agents: client (via the router, the default) or peer "
        "(mesh, docs/design.md §3; only with --insecure)",
    )
    ap.add_argument("--d-e", type=float, default=0.8, help="pyramid distance (m)")
    ap.add_argument("--phi-e-deg", type=float, default=30.0, help="pyramid angle (deg)")
    ap.add_argument(
        "--monitor", action="store_true", help="only observe and judge a run (see monitor())"
    )
    ap.add_argument(
        "--until-done", type=int, default=0, help="with --monitor: stop when N agents finished"
    )
    ap.add_argument("--connect", action="append", default=[], help="with --monitor: endpoint")
    ap.add_argument(
        "--credentials",
        metavar="DIR",
        default=None,
        help="with --monitor: fleet credentials folder, joins as 'observer' "
        f"(default: ${P.CREDENTIALS_ENV})",
    )
    ap.add_argument(
        "--insecure",
        action="store_true",
        help="no TLS or signatures (development only; prints a warning); runs are secure "
        "by default (a fleet made under OUT/fleet, a TLS router)",
    )
    args = ap.parse_args(argv)
    if args.monitor:
        # secure by default, as every process (agent.wire.network_spec)
        creds = "" if args.insecure else (args.credentials or os.environ.get(P.CREDENTIALS_ENV))
        if args.insecure:
            print(P.INSECURE_WARNING, file=sys.stderr, flush=True)
        elif not creds:
            print(
                "eval_loss: --monitor needs fleet credentials: --credentials DIR (or "
                f"${P.CREDENTIALS_ENV}); --insecure for development",
                file=sys.stderr,
            )
            return 2
        return monitor(
            args.connect,
            Path(args.out),
            args.d_e,
            args.phi_e_deg,
            args.until_done,
            args.timeout,
            args.seed,
            creds or "",
        )
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
    if not 1 <= args.robots <= 20 or args.seeds < 1 or args.seed_start < 0:
        print(
            "eval_loss: --robots must be in [1, 20], --seeds >= 1, --seed-start >= 0",
            file=sys.stderr,
        )
        return 2
    lo, hi = TCP_RTO_MAX_RANGE
    if args.tcp_rto_max_ms and not lo <= args.tcp_rto_max_ms <= hi:
        print(f"eval_loss: --tcp-rto-max-ms must be 0 or in [{lo}, {hi}]", file=sys.stderr)
        return 2
    if args.agent_mode == "peer" and not args.insecure:
        print("eval_loss: --agent-mode peer needs --insecure (secure runs use a router)",
              file=sys.stderr)  # fmt: skip
        return 2
    try:
        netns.preflight()
    except netns.NetnsError as exc:
        print(f"eval_loss: {exc}", file=sys.stderr)
        return 1
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    def on_term(signum: int, frame: FrameType | None) -> None:
        raise KeyboardInterrupt  # unwinds through netns.Fabric, which tears the hosts down

    signal.signal(signal.SIGTERM, on_term)
    try:
        return _evaluate(args, losses, out)
    except KeyboardInterrupt:
        print("eval_loss: interrupted; test hosts removed", file=sys.stderr)
        return 130


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


def _fleet(out: Path, robots: int) -> str:
    """A fleet for ``robots`` robots whose router is reached at test host 1 (made once)."""
    from agent.wire.trust import create_fleet

    root = out / f"fleet-{robots}"
    if not (root / "ca.pem").exists():
        create_fleet(root, range(1, robots + 1), hosts=[netns.address(1)])
    return str(root)


def _evaluate(args: argparse.Namespace, losses: list[float], out: Path) -> int:
    results: list[RunResult] = []
    rows: list[dict[str, Any]] = []
    total = len(losses) * args.seeds
    creds = "" if args.insecure else _fleet(out, args.robots)
    json_path = Path(args.json) if args.json else out / "runs.json"
    bar = Progress(total, "eval_loss")
    for loss in losses:
        for seed in range(args.seed_start, args.seed_start + args.seeds):
            try:
                r = run_once(
                    loss, seed, args.robots, args.timeout,
                    out / f"loss{loss:g}_seed{seed}", args.prefix, args.lossy_world,
                    args.d_e, args.phi_e_deg, args.agent_mode, creds, args.tcp_rto_max_ms,
                )  # fmt: skip
            except (RuntimeError, netns.NetnsError, OSError) as exc:
                print(f"eval_loss: run failed to start: {exc}", file=sys.stderr)
                return 1
            results.append(r)
            res_path = Path(r.out) / "result.json"
            res = json.loads(res_path.read_text()) if res_path.exists() else {}
            rows.append(run_row(r, res))
            report.write_runs(rows, json_path)
            bar.step(
                f"loss {loss:g} seed {seed}: {'OK  ' if r.success else 'FAIL'} {r.reason}; agree "
                f"{_fmt(r.agree_s, '.2f')} s, bytes/agent {r.bytes_per_agent}, "
                f"dropped {r.dropped_packets} pkts, wall {r.wall_s:.0f} s"
            )
    summary = summarise(results)
    doc = {
        "robots": args.robots,
        "seeds": args.seeds,
        "lossy_world": args.lossy_world,
        "agent_mode": args.agent_mode,
        "tcp_rto_max_ms": args.tcp_rto_max_ms,
        "summary": summary,
        "runs": [asdict(r) for r in results],
    }
    (out / "results.json").write_text(json.dumps(doc, indent=2))
    plot(summary, out / "loss.png")
    report.plot_outcomes(
        report.count_outcomes(
            sorted(rows, key=lambda r: float(r["loss"])), "loss", name=lambda x: f"{100 * x:g} %"
        ),
        out / "outcomes.png",
        f"{args.robots} robots, seeds {args.seed_start}..{args.seed_start + args.seeds - 1}, "
        f"{'insecure' if args.insecure else 'TLS router'}, world traffic "
        f"{'lossy' if args.lossy_world else 'exempt'}"
        + (f", TCP RTO <= {args.tcp_rto_max_ms} ms" if args.tcp_rto_max_ms else ""),
        ylabel="packet loss per direction",
    )
    report.print_runs(rows, "loss", detail_width=70)
    print(
        f"{'loss':>6} {'runs':>5} {'success':>8} {'agree s':>8} {'max s':>7} {'B/agent':>9} "
        f"{'exch B':>8} {'dropped':>8}"
    )
    for srow in summary:
        print(
            f"{srow['loss']:6.2f} {srow['runs']:5d} {srow['success_rate']:8.0%} "
            f"{_fmt(srow['agree_s_mean'], '8.2f')} {_fmt(srow['agree_s_max'], '7.2f')} "
            f"{_fmt(srow['bytes_per_agent_mean'], '9.0f')} "
            f"{_fmt(srow['exchange_bytes_per_agent_mean'], '8.0f')} {srow['dropped_packets_mean']:8.0f}"
        )
    print(f"wrote {json_path}, {out / 'results.json'}, {out / 'loss.png'}, {out / 'outcomes.png'}")
    return 0 if all(r.success for r in results) else 3


if __name__ == "__main__":
    raise SystemExit(main())
