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

The hosts and processes are those of :class:`tools.harness.hosts.HostFleet` (the same
:class:`~tools.harness.fleet.FleetSpec` as every run; the agents of a loss run keep no
journal). A monitor on its own (lossless) host (:mod:`tools.harness.monitor`) observes the bus and
judges each run with ``tools.harness``'s criteria (every agent exits 0 in ``done``, identical
plan digests, no contact, every pair within |r_d| <= 12.5 % and |r_φ| <= 30 %). Per run
it also records the agreement time (wall seconds from the last agent entering
``exchange`` to the last agent leaving ``agree``: the cost of the protocol, not of the
search), the bytes each agent published (all, and records + digests only) and the
packets dropped. Each run's outcome is that of :func:`tools.harness.judge.outcome`,
reported as every evaluation tool does (:mod:`tools.harness.report`: ``--json``, the
table, ``outcomes.png``). It writes ``results.json`` and ``loss.png`` (success rate,
agreement time and bytes vs loss; :mod:`tools.lib.loss_report`) under ``--out``, one directory per run with the
processes' logs, ``result.json``, ``formation.png`` and ``run.mcap``, and prints a table.

``python -m tools.eval_loss --loss 0,0.1,0.3 --robots 3 --seeds 3 [--out out/eval_loss]``
Needs root, iproute2 and iptables (network namespaces).
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import time
from pathlib import Path
from types import FrameType
from typing import Any

from agent.config import add_plan_arguments
from tools import netns
from tools.harness import report
from tools.harness.fleet import FleetSpec
from tools.harness.fleet_flags import add_agent_arguments, agent_settings
from tools.harness.hosts import TCP_RTO_MAX_RANGE, HostFleet, Hosts, host_fleet_credentials
from tools.harness.monitor import add_monitor_arguments, monitor_main
from tools.lib.loss_report import RunResult, fmt, run_reason, run_row, write_report

# =========================================================================== one run


def run_once(args: argparse.Namespace, loss: float, seed: int, credentials: str) -> RunResult:
    """One formation run with ``loss`` on every agent host; logs and results in its folder
    under ``--out``. ``credentials``: a fleet folder made for the test hosts (secure: TLS
    links, signatures); empty: insecure."""
    workdir = Path(args.out) / f"loss{loss:g}_seed{seed}"
    spec = FleetSpec(robots=args.robots, seed=seed, agent=args.agent, insecure=not credentials,
                     credentials=Path(credentials) if credentials else None,
                     timeout=args.timeout)  # fmt: skip
    hosts = Hosts(args.prefix, tcp_rto_max_ms=args.tcp_rto_max_ms, agent_mode=args.agent_mode,
                  loss=loss, lossy_world=args.lossy_world)  # fmt: skip
    t_start = time.monotonic()
    with HostFleet(spec, workdir, hosts) as fleet:
        fleet.wait()
        fleet.clear_loss()
        res = fleet.judge()
    wall = time.monotonic() - t_start
    reason = run_reason(res, args.robots) if res else "monitor wrote no result"
    bytes_tot = [int(b.get("total", 0)) for _, b in sorted(res.get("bytes", {}).items())]
    exch = [int(v) for _, v in sorted(res.get("exchange_bytes", {}).items())]
    return RunResult(
        loss=loss,
        seed=seed,
        robots=args.robots,
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
        dropped_packets=fleet.dropped_packets,
        out=str(workdir),
    )


def _row(r: RunResult) -> dict[str, Any]:
    path = Path(r.out) / "result.json"
    return run_row(r, json.loads(path.read_text()) if path.exists() else {})


# =========================================================================== CLI


def parse_args(argv: list[str] | None) -> argparse.Namespace:
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
    add_agent_arguments(ap, agreement=False)
    add_plan_arguments(ap)  # the agents' and the monitor's: it judges the shape they plan
    add_monitor_arguments(ap)  # --monitor: only observe and judge a run (a test host's)
    ap.add_argument(
        "--insecure",
        action="store_true",
        help="no TLS or signatures (development only; prints a warning); runs are secure "
        "by default (a fleet made under OUT/fleet, a TLS router)",
    )
    args = ap.parse_args(argv)
    args.agent = agent_settings(
        ap, args, orientation=args.orientation, strategy=args.strategy, shape=args.shape
    )
    return args


def usage_error(args: argparse.Namespace) -> str | None:
    """Why the flags of a loss matrix are refused, or None; sets ``args.losses``."""
    try:
        args.losses = [float(x) for x in args.loss.split(",") if x.strip()]
    except ValueError:
        return f"--loss {args.loss!r} is not a comma-separated list of numbers"
    if not args.losses or any(not 0.0 <= x <= 1.0 for x in args.losses):
        return "every --loss value must be a probability in [0, 1]"
    if not 1 <= args.robots <= 20 or args.seeds < 1 or args.seed_start < 0:
        return "--robots must be in [1, 20], --seeds >= 1, --seed-start >= 0"
    lo, hi = TCP_RTO_MAX_RANGE
    if args.tcp_rto_max_ms and not lo <= args.tcp_rto_max_ms <= hi:
        return f"--tcp-rto-max-ms must be 0 or in [{lo}, {hi}]"
    if args.agent_mode == "peer" and not args.insecure:
        return "--agent-mode peer needs --insecure (secure runs use a router)"
    return None


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.monitor:
        return monitor_main(args)
    why = usage_error(args)
    if why is not None:
        print(f"eval_loss: {why}", file=sys.stderr)
        return 2
    try:
        netns.preflight()
    except netns.NetnsError as exc:
        print(f"eval_loss: {exc}", file=sys.stderr)
        return 1
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    def on_term(signum: int, frame: FrameType | None) -> None:
        raise KeyboardInterrupt  # unwinds through the test hosts, which are removed

    signal.signal(signal.SIGTERM, on_term)
    try:
        return _evaluate(args, out)
    except KeyboardInterrupt:
        print("eval_loss: interrupted; test hosts removed", file=sys.stderr)
        return 130


def _evaluate(args: argparse.Namespace, out: Path) -> int:
    creds = "" if args.insecure else host_fleet_credentials(out, args.robots)
    json_path = Path(args.json) if args.json else out / "runs.json"
    cases = [(loss, seed) for loss in args.losses
             for seed in range(args.seed_start, args.seed_start + args.seeds)]  # fmt: skip
    try:
        results = report.run_matrix(
            cases,
            lambda c: run_once(args, c[0], c[1], creds),
            report=lambda runs: report.write_runs([_row(r) for r in runs], json_path),
            progress="eval_loss",
            label=lambda c, r: (
                f"loss {c[0]:g} seed {c[1]}: {'OK  ' if r.success else 'FAIL'} {r.reason}; "
                f"agree {fmt(r.agree_s, '.2f')} s, bytes/agent {r.bytes_per_agent}, "
                f"dropped {r.dropped_packets} pkts, wall {r.wall_s:.0f} s"
            ),
        )
    except (RuntimeError, netns.NetnsError, OSError) as exc:
        print(f"eval_loss: run failed to start: {exc}", file=sys.stderr)
        return 1
    rows = [_row(r) for r in results]
    write_report(results, rows, out, json_path, vars(args))
    return 0 if all(r.success for r in results) else 3


if __name__ == "__main__":
    raise SystemExit(main())
