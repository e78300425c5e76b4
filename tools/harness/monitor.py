"""The monitor: one run observed and judged by a process of its own (docs/design.md §10
"Viewers are observers"; docs/faults.md).

``python -m tools.eval_loss --monitor`` runs it on a lossless test host of every
``tools.eval_loss`` run, and the compose ``observer`` runs it beside a containerised
fleet. It joins the bus as an observer (secure: a zenoh client of the TLS router with the
``observer`` identity, which only subscribes; every message it records has passed the
signature check), records statuses, records, digests and ground truth
(:mod:`tools.harness.observe`, MCAP) until the run is over, and judges it with
:func:`tools.harness.judge.summarise`. Besides the demo's result it records each
agent's ``phases_visited``, each robot's ``displacement_m`` and the protocol's
agreement time ``agree_s``. The exit code of an agent is the authority on ``done``
(:func:`done_by_exit_code`): one status packet that a cut session swallowed does not
turn a finished run into a failed one.

Exit codes are the processes' own, never read from what an agent claims: the
orchestrator of ``tools.eval_loss`` and ``tools.eval_chaos`` hands them over on stdin;
beside a containerised fleet (``--until-done``) the monitor reads the agents' exit
records (:func:`read_exits`): every agent container of docker-compose.yml appends to its
own file in a folder it shares with the observer ``{"robot": ID}`` (the agent, once it
has claimed its robot: ``python -m agent --exit-record``) and ``{"exit": CODE}`` (the
container's shell, the agent process's real exit status ``$?``, or 1 when it never
started). A robot without an ``exit`` line has no exit code: it did not finish.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import queue
import sys
import threading
import time
from pathlib import Path
from typing import Any

from agent.config import AgentConfig
from agent.net.bus import Bus, BusConfig
from agent.wire import CREDENTIALS_ENV, INSECURE_WARNING, PHASES
from tools.harness.judge import plan_meta, summarise
from tools.harness.observe import AgentView, Observer, Recorder, observe_still, watch
from tools.harness.run_report import print_table

#: Phases an agent reaches only after agreement (its first one ends ``agree_s``).
AGREED_PHASES = ("plan", "wait", "move", "hold", "march", "done")
TERMINAL_PHASES = ("done", "failed")


def monitor(
    connect: list[str],
    out: Path,
    agent: AgentConfig,
    until_done: int = 0,
    timeout_s: float = 900.0,
    seed: int | None = None,
    credentials: str = "",
    exits: Path | None = None,
) -> int:
    """Observe the bus like ``tools.demo`` does, until the run is over; judge it with the
    agents' planning parameters ``agent`` (d_e, φ_e, orientation, strategy and shape: a run
    of ``--shape line`` is judged against the line, not the pyramid).

    ``credentials``: a fleet credentials folder (``agent.wire.trust``); the monitor then joins
    as a zenoh client of the TLS router with the ``observer`` identity (observers only
    subscribe; every message it records has passed the signature check). Empty:
    insecure, as a peer (the caller gave ``--insecure``).

    Prints ``monitor ready`` once subscribed, then records statuses, records, digests and
    ground truth (``tools.harness.observe.Observer``, MCAP recording). The run is over when the
    orchestrator writes one JSON line to stdin, ``{"ids": [...], "exit_codes": {...},
    "timeout": str|null}``, or, with ``until_done=N`` (the compose ``observer``), when N
    agents have an exit record with their exit status in ``exits`` (default
    ``out/exits``; :func:`read_exits`), or N agents were alive and every liveliness token
    has been gone for 5 s, or ``timeout_s`` has passed; the robots are those of the
    ground truth (else those seen), each with the exit code of its record (none: it did
    not finish). It then waits until the world stands still (at most 1.5 s;
    ``observe_still``) and writes ``out/result.json`` (and the formation figure) with
    ``tools.harness.judge.summarise``. Returns 0 when the run succeeded.
    """
    out.mkdir(parents=True, exist_ok=True)
    lines: queue.Queue[str] = queue.Queue()

    def read_stdin() -> None:
        for line in sys.stdin:
            lines.put(line)
        lines.put("")

    if not until_done:
        threading.Thread(target=read_stdin, daemon=True).start()
    exits = out / "exits" if exits is None else exits
    since = time.time() - 1.0  # exit records of earlier runs are older
    deadline = time.monotonic() + timeout_s
    rec = Recorder(out / "run.mcap", params=agent.plan_params())  # the plan the agents report
    obs = Observer(time.monotonic())
    bus = Bus(
        BusConfig(
            connect=tuple(connect),
            multicast_scouting=False,
            mode="client" if credentials else "peer",
            credentials=credentials,
            identity="observer" if credentials else "",
        )
    )
    try:
        watch(bus)
        print("monitor ready", flush=True)
        order: dict[str, Any] | None = None
        alive: set[int] = set()
        ever_alive: set[int] = set()
        all_gone_since: float | None = None
        unclaimed: list[int] = []
        next_read = 0.0
        while order is None:
            for ev in bus.drain(0.1):
                if ev.kind == "msg":
                    known = len(obs.agents)
                    obs.take_event(ev, rec)
                    if len(obs.agents) > known:
                        print(f"monitor sees agents {sorted(obs.agents)}", flush=True)
                elif ev.kind == "alive":
                    alive.add(ev.robot_id)
                    ever_alive.add(ev.robot_id)
                elif ev.kind == "gone":
                    alive.discard(ev.robot_id)
            if until_done:
                now = time.monotonic()
                if now < next_read:
                    continue
                next_read = now + 0.5
                if alive or len(ever_alive) < until_done:
                    all_gone_since = None
                elif all_gone_since is None:
                    all_gone_since = now
                codes, unclaimed = read_exits(exits, since)
                ended = sum(c is not None for c in codes.values()) + len(unclaimed)
                gone = all_gone_since is not None and now - all_gone_since > 5.0
                late = now > deadline
                if ended >= until_done or gone or late:
                    world = set(obs.truth[-1][1]) if obs.truth else set()
                    ids = sorted(world or set(codes) | set(obs.agents))
                    order = {
                        "ids": ids,
                        "exit_codes": {str(i): codes.get(i) for i in ids},
                        "timeout": f"agents not finished after {timeout_s:g} s" if late else None,
                    }
                continue
            with contextlib.suppress(queue.Empty):
                line = lines.get_nowait()
                order = json.loads(line) if line.strip() else {}
        observe_still(bus, obs, rec, 1.5)
    finally:
        bus.close()
        rec.close()
    ids = [int(i) for i in order.get("ids", [])]
    for i in ids:
        code = order.get("exit_codes", {}).get(str(i))
        obs.agents.setdefault(i, AgentView()).exit_code = code
    lost = done_by_exit_code(obs, ids)
    result: dict[str, Any] = {
        "robots": len(ids),
        "seed": seed,
        "d_e": agent.d_e,
        "phi_e_deg": agent.phi_e_deg,
        **plan_meta(agent),
        "wall_total": time.monotonic() - obs.t0,  # since the monitor started
    }
    if order.get("timeout"):
        result["timeout"] = order["timeout"]
    if unclaimed:  # agents that ended before they claimed a robot: its exit code is theirs
        result["unclaimed_exits"] = unclaimed
    if lost:
        result["final_status_unheard"] = lost
    # which phases each agent went through (did it move?), and how far each robot walked
    # (ground truth): what tells a safe abort from a robot moving on an unshared plan
    result["phases_visited"] = {
        str(i): [p for p in PHASES if p in obs.agents[i].phase_wall] for i in ids if i in obs.agents
    }
    if obs.truth:
        first, last = obs.truth[0][1], obs.truth[-1][1]
        result["displacement_m"] = {
            str(i): math.dist(first[i][:2], last[i][:2]) for i in ids if i in first and i in last
        }
    result = summarise(obs, result, out, ids, agent.d_e, agent.phi_e, quiet=True)
    # protocol latency: from the last agent entering exchange to the last one agreeing
    views = [obs.agents[i] for i in ids if i in obs.agents]
    entered = [v.phase_wall.get("exchange") for v in views]
    agreed = [
        min((v.phase_wall[p] for p in AGREED_PHASES if p in v.phase_wall), default=None)
        for v in views
    ]
    if len(views) == len(ids) and all(t is not None for t in entered + agreed):
        result["agree_s"] = max(t for t in agreed if t is not None) - max(
            t for t in entered if t is not None
        )
    (out / "result.json").write_text(json.dumps(result, indent=2, default=float))
    if until_done:
        print_table(result)
    print("monitor done", flush=True)
    return 0 if result.get("success") else 1


def add_monitor_arguments(p: argparse.ArgumentParser) -> None:
    """The monitor's own flags (``python -m tools.eval_loss --monitor``; that tool's parser
    has the shared ``--out``, ``--timeout``, ``--insecure`` and the agents' settings,
    ``--d-e``, ``--phi-e-deg``, ``--orientation``, ``--strategy`` and ``--shape``, read into
    ``args.agent``)."""
    p.add_argument(
        "--monitor", action="store_true", help="only observe and judge a run (see monitor())"
    )
    p.add_argument("--seed", type=int, default=None, help="with --monitor: the run's seed")
    p.add_argument(
        "--until-done", type=int, default=0, help="with --monitor: stop when N agents finished"
    )
    p.add_argument("--connect", action="append", default=[], help="with --monitor: endpoint")
    p.add_argument(
        "--credentials",
        metavar="DIR",
        default=None,
        help="with --monitor: fleet credentials folder, joins as 'observer' "
        f"(default: ${CREDENTIALS_ENV})",
    )


def monitor_main(args: argparse.Namespace) -> int:
    """``--monitor``: :func:`monitor` with the flags of :func:`add_monitor_arguments`; secure
    by default, as every process (``agent.wire.network_spec``): 2 without credentials."""
    creds = "" if args.insecure else (args.credentials or os.environ.get(CREDENTIALS_ENV))
    if args.insecure:
        print(INSECURE_WARNING, file=sys.stderr, flush=True)
    elif not creds:
        print(
            "eval_loss: --monitor needs fleet credentials: --credentials DIR (or "
            f"${CREDENTIALS_ENV}); --insecure for development",
            file=sys.stderr,
        )
        return 2
    return monitor(args.connect, Path(args.out), args.agent, args.until_done, args.timeout,
                   args.seed, creds or "")  # fmt: skip


def read_exits(folder: Path, since: float) -> tuple[dict[int, int | None], list[int]]:
    """The agents' exit records in ``folder`` (module docstring), of files changed after
    ``since`` (epoch s): (robot -> its process's exit code, None while it runs; the exit
    codes of agents that ended without a robot). Lines that are no record are skipped."""
    codes: dict[int, int | None] = {}
    unclaimed: list[int] = []
    for path in sorted(folder.glob("*.jsonl")) if folder.is_dir() else []:
        try:
            if path.stat().st_mtime < since:
                continue
            lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
        except OSError:
            continue
        robot: int | None = None
        code: int | None = None
        for line in lines:
            with contextlib.suppress(ValueError, TypeError, AttributeError):
                rec = json.loads(line)
                if "robot" in rec:
                    robot = int(rec["robot"])
                if "exit" in rec:
                    code = int(rec["exit"])
        if robot is not None:
            codes[robot] = code
        elif code is not None:
            unclaimed.append(code)
    return codes, unclaimed


def done_by_exit_code(obs: Observer, ids: list[int]) -> list[int]:
    """Agents that exited 0 but whose final ``done`` status the monitor never heard (sorted);
    their phase in ``obs`` is set to ``done``.

    ``Runner.run`` returns 0 only after it published ``done`` (the exit code is the
    authority, not one status packet that a cut session may swallow); the rest of the
    judgement stays with what the monitor saw: the plan digests of the agents' statuses
    and the world's ground truth.
    """
    out = []
    for i in ids:
        view = obs.agents.get(i)
        if view is not None and view.exit_code == 0 and view.phase not in TERMINAL_PHASES:
            view.phase = "done"
            out.append(i)
    return sorted(out)
