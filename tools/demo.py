"""``python -m tools.demo``: the world and N agents as separate processes, end to end.

    python -m tools.demo --robots 3 --seed 1 [--json FILE] [--out DIR]
    python -m tools.demo --robots 3 --seed 1 --batch 20 [--out DIR]   (seeds 1..20)

Starts ``python -m sim`` and N ``python -m agent`` processes (peers over loopback
TCP, no multicast so that concurrent runs never mix), shows one live status line per
agent, and when the agents have finished prints the result table from ground truth:
per child–parent pair of the pyramid the distance and the angle off the pyramid's
backward axis, r_d = (d - d_e)/d_e and r_φ = (φ - φ_e)/φ_e (NAO paper 5.1.1);
collisions; wall and sim time per phase; bytes each agent published; whether every
agent computed the same plan digest. Writes ``DIR/result.json``, a Fig. 16/24-like
``DIR/formation.png`` (starts, walked paths, final pyramid, ids) and ``DIR/run.mcap``
(truth, statuses, records, digests, contacts; replay with ``python -m tools.replay``).

Success (exit 0): every agent exited 0, identical plan digests, zero contacts, and
every pair within |r_d| <= 12.5 % and |r_φ| <= 30 %.

Marching (issue #13): ``--march D`` (metres along the pyramid's axis) or ``--march-to
X,Y`` (common frame) is given to every agent; after ``hold`` the fleet marches. The
world's room is then enlarged by the route's length (the demo generates the seed's
scenario, widens its room and starts the world with ``--scenario``), so the march
never meets a wall. The pairs are judged at the end of the march; the leader's measured
displacement (``march_distance``) must be within 10 % of the route (|displacement − V|
<= 0.1·|V|); the worst |r_d| and |r_φ| over the truth samples of the march are
reported (``march_worst_abs_r_d``, ``march_worst_abs_r_phi``); the figure shows the
pyramid at the start of the march (grey) and at its end, and the tracks in between.

This tool is an evaluator: it reads ground truth (``world/truth/**``); agents never do.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from agent.bus import Bus, BusConfig
from agent.protocol import (
    INSECURE_WARNING,
    KEY_ALIVE_ALL,
    KEY_DIGEST_ALL,
    KEY_RECORD_ALL,
    KEY_STATUS_ALL,
    KEY_WORLD_TRUTH_ALL,
    PHASES,
    ContactMsg,
    DigestMsg,
    Guard,
    NeighborRecordMsg,
    StatusMsg,
    TruthPosesMsg,
    encode,
    id_from_key,
)
from agent.trust import create_fleet

R_D_MAX = 0.125
R_PHI_MAX = 0.30
#: The phases of DESIGN.md §1 in order (the wire's list, less the terminal "failed").
PHASE_ORDER = tuple(p for p in PHASES if p != "failed")
ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# ===================================================================== recording


class Recorder:
    """MCAP file of everything the demo saw: one channel per topic, msgpack wire payloads.

    Why MCAP: a single indexed, self-describing file that the ``mcap`` package (already
    a dependency) reads back without a viewer, and Foxglove opens directly.
    """

    def __init__(self, path: Path) -> None:
        from mcap.writer import Writer

        self._f = path.open("wb")
        self._w = Writer(self._f)
        self._w.start(profile="", library="nao-formation tools.demo")
        self._schema = self._w.register_schema(
            name="agent.protocol", encoding="", data=b"msgpack map, see agent/protocol.py"
        )
        self._channels: dict[str, int] = {}
        self._lock = threading.Lock()
        self.count = 0

    def write(self, topic: str, data: bytes, t_ns: int | None = None) -> None:
        t = time.time_ns() if t_ns is None else t_ns
        with self._lock:
            ch = self._channels.get(topic)
            if ch is None:
                ch = self._w.register_channel(topic, "msgpack", self._schema)
                self._channels[topic] = ch
            self._w.add_message(ch, log_time=t, data=data, publish_time=t, sequence=self.count)
            self.count += 1

    def close(self) -> None:
        with self._lock:
            self._w.finish()
            self._f.close()


# ===================================================================== processes


@dataclass
class Proc:
    name: str
    popen: subprocess.Popen[bytes]
    log: IO[bytes]
    lines: list[str] = field(default_factory=list)


def start_world(
    robots: int,
    seed: int,
    endpoint: str,
    out: Path,
    extra: list[str],
    net: list[str] | None = None,
) -> Proc:
    """``python -m sim``; ``net``: its join flags (default: listen on ``endpoint``, insecure)."""
    if net is None:
        net = ["--listen", endpoint, "--no-multicast-scouting", "--insecure"]
    cmd = [
        sys.executable, "-m", "sim", "--robots", str(robots), "--seed", str(seed), *net, *extra,
    ]  # fmt: skip
    log = (out / "world.log").open("wb")
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=log)
    proc = Proc("world", p, log)

    def pump() -> None:
        assert p.stdout is not None
        for raw in p.stdout:
            log.write(raw)
            proc.lines.append(raw.decode(errors="replace").strip())

    threading.Thread(target=pump, daemon=True).start()
    return proc


def start_agent(
    rid: int,
    robots: int,
    endpoint: str,
    out: Path,
    args: argparse.Namespace,
    net: list[str] | None = None,
    extra: list[str] | None = None,
    append: bool = False,
) -> Proc:
    """Agent process for robot ``rid`` (with ``--auto-ids`` it claims a robot itself);
    ``net``: its join flags (default: connect to ``endpoint``, insecure); ``extra``: more
    agent flags (``--state-dir``); ``append``: add to the agent's log (a restart)."""
    auto = bool(getattr(args, "auto_ids", False))
    if net is None:
        net = ["--connect", endpoint, "--no-multicast-scouting", "--insecure"]
    cmd = [
        sys.executable, "-m", "agent", "--id", "auto" if auto else str(rid), "--fleet-size", str(robots),
        *net,
        "--d-e", str(args.d_e), "--phi-e-deg", str(args.phi_e_deg), "--timeout", str(args.agree_timeout),
        *(["--march", str(args.march)] if getattr(args, "march", None) is not None else []),
        *([f"--march-to={args.march_to}"] if getattr(args, "march_to", None) is not None else []),
        "--log-level", args.agent_log_level,
        *(["--no-correct"] if getattr(args, "no_correct", False) else []),
        *(["--body", "naoqi", "--nao", args.nao_urls[rid]] if getattr(args, "body", "") == "naoqi" else []),
        *(extra or []),
    ]  # fmt: skip
    log = (out / (f"agent-slot{rid}.log" if auto else f"agent-{rid}.log")).open(
        "ab" if append else "wb"
    )
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
    return Proc(f"agent {rid}", p, log)


def route_length(args: argparse.Namespace) -> float:
    """An upper bound of the march's length (m): 0 without a march."""
    if getattr(args, "march", None) is not None:
        return float(args.march)
    if getattr(args, "march_to", None) is not None:
        x, y = (float(v) for v in args.march_to.split(","))
        return math.hypot(x, y) + 2.0  # the leader's target is near the fleet's centre
    return 0.0


def march_room(args: argparse.Namespace, n: int, seed: int, out: Path) -> list[str]:
    """World flags giving a march room: the seed's generated scenario with its room's
    half-size enlarged by the route's length (sim/scenarios is not changed); [] without
    a march or when the caller chose a scenario with --world-arg."""
    extra = route_length(args)
    if extra <= 0.0 or any("--scenario" in a for a in (args.world_arg or [])):
        return []
    from dataclasses import replace

    from sim import scenarios

    sc = scenarios.generate(n, seed)
    sc = replace(sc, room=min(100.0, math.ceil(2.0 * (sc.room + extra)) / 2.0))
    path = out / "scenario.json"
    scenarios.dump(sc, path)
    return ["--scenario", str(path)]


def start_router(endpoint: str, out: Path, net: list[str]) -> Proc:
    """``python -m tools.router`` listening on ``endpoint``; waits for its ready line."""
    cmd = [sys.executable, "-m", "tools.router", "--listen", endpoint, *net]
    log = (out / "router.log").open("wb")
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
    proc = Proc("router", p, log)
    deadline = time.monotonic() + 30.0
    while "router ready" not in (out / "router.log").read_text(errors="replace"):
        if p.poll() is not None or time.monotonic() > deadline:
            stop(proc)
            raise RuntimeError(f"router did not start; see {out / 'router.log'}")
        time.sleep(0.05)  # polling the router's log for its ready line, bounded above
    return proc


@dataclass(frozen=True)
class FleetNet:
    """How one run's processes join the bus (DESIGN.md §8): see :func:`fleet_network`."""

    endpoint: str
    flags: list[str]  # join flags every process gets (besides --listen/--connect)
    credentials: str = ""  # empty: insecure
    tls: bool = True

    @property
    def router(self) -> bool:
        """Secure TLS runs meet at a router; the others at the world's listener."""
        return bool(self.credentials) and self.tls

    def observer(self) -> BusConfig:
        if not self.credentials:
            return BusConfig(connect=(self.endpoint,), multicast_scouting=False)
        return BusConfig(
            connect=(self.endpoint,),
            multicast_scouting=False,
            mode="client" if self.tls else "peer",
            credentials=self.credentials,
            identity="observer",
            tls=self.tls,
        )


def fleet_network(args: argparse.Namespace, out: Path, robots: int) -> FleetNet:
    """One run's network: secure by default.

    Secure: a throwaway fleet in ``out/fleet`` unless ``--credentials`` names one, a TLS
    router on a free loopback port, every process a client of it. ``--plain-links``
    (tests): the same signatures over plain TCP, the world listening. ``--insecure``:
    plain TCP, no signatures.
    """
    port = free_port()
    if args.insecure:
        return FleetNet(f"tcp/127.0.0.1:{port}", ["--no-multicast-scouting", "--insecure"])
    creds = args.credentials
    if creds is None:
        creds = out / "fleet"  # throwaway: made anew for every run
        shutil.rmtree(creds, ignore_errors=True)
        create_fleet(creds, range(1, robots + 2))  # one spare robot key: --rogue's insider
    flags = ["--no-multicast-scouting", "--credentials", str(creds)]
    if getattr(args, "plain_links", False):
        return FleetNet(f"tcp/127.0.0.1:{port}", [*flags, "--plain-links"], str(creds), False)
    return FleetNet(f"tls/127.0.0.1:{port}", flags, str(creds))


def start_rogues(
    net: FleetNet, out: Path, ids: list[int], duration: float, replay: Path | None = None
) -> list[Proc]:
    """``tools.rogue`` attackers for ``--rogue`` (issue #8), each writing a JSON report.

    Always a stranger (no credentials). Secure TLS fleets: also an insider holding the
    observer's key (access control limits it). Plain-links fleets: also an insider
    holding the key of a fleet robot that is not in this run (the demo's fleet has one
    spare) attacking robot ``ids[0]``: only the end-to-end signatures stand in its way.
    Each writes what it saw to ``rogue-NAME.capture``; ``replay`` (a capture of an
    earlier run) is replayed as well.
    """
    target = ids[0]
    base = [sys.executable, "-m", "tools.rogue", "--connect", net.endpoint,
            "--target", str(target), "--robots", ",".join(map(str, ids)),
            "--duration", f"{duration:g}"]  # fmt: skip
    if not net.tls:
        base.append("--plain-links")
    who: list[tuple[str, list[str]]] = [("stranger", [])]
    if net.credentials:
        insider = "observer" if net.tls else f"robot-{max(ids) + 1}"
        who.append((insider, ["--credentials", net.credentials, "--identity", insider]))
    procs = []
    for old in out.glob("rogue-*.json"):
        old.unlink()
    for name, extra in who:
        cmd = [*base, *extra, "--json", str(out / f"rogue-{name}.json"),
               "--capture", str(out / f"rogue-{name}.capture")]  # fmt: skip
        if replay is not None:
            cmd += ["--replay-file", str(replay)]
        log = (out / f"rogue-{name}.log").open("wb")
        p = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
        procs.append(Proc(f"rogue {name}", p, log))
    return procs


def rogue_reports(out: Path) -> dict[str, Any]:
    """The rogues' JSON reports, by name (those that wrote one)."""
    reports = {}
    for path in sorted(out.glob("rogue-*.json")):
        with contextlib.suppress(ValueError, OSError):
            reports[path.stem.removeprefix("rogue-")] = json.loads(path.read_text())
    return reports


def stop(proc: Proc, grace: float = 5.0) -> None:
    p = proc.popen
    if p.poll() is None:
        p.send_signal(signal.SIGINT)
        try:
            p.wait(grace)
        except subprocess.TimeoutExpired:
            p.terminate()
            try:
                p.wait(grace)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
    with contextlib.suppress(Exception):
        proc.log.close()


# ===================================================================== observation


@dataclass
class AgentView:
    phase: str = "-"
    progress: float = 0.0
    detail: str = ""
    error: str = ""
    plan_digest: str = ""
    wave: int = -1
    t_sim: float = 0.0
    march_sample: int | None = None  # truth samples seen at its first ``march`` status
    phase_wall: dict[str, float] = field(default_factory=dict)
    phase_sim: dict[str, float] = field(default_factory=dict)
    bytes_by_kind: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    count_by_kind: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    exit_code: int | None = None


@dataclass
class Observer:
    t0: float
    agents: dict[int, AgentView] = field(default_factory=dict)
    truth: list[tuple[float, dict[int, tuple[float, float, float]]]] = field(default_factory=list)
    contacts: list[tuple[float, int, int]] = field(default_factory=list)
    truth_contacts: int = 0
    records: dict[int, NeighborRecordMsg] = field(default_factory=dict)
    digests: dict[int, DigestMsg] = field(default_factory=dict)
    #: events whose handling failed (counted, reason logged, the observer goes on)
    rejected: int = 0
    guard: Guard = field(
        default_factory=lambda: Guard(lambda line: print(f"observer: {line}", file=sys.stderr))
    )

    def take_event(self, ev: Any, rec: Recorder | None) -> None:
        """:meth:`take` for one bus event; never raises (a failure is counted in
        ``rejected`` and logged with a reason cut to 200 characters, rate limited)."""
        if ev.kind != "msg":
            return
        try:
            self.take(ev.key, ev.msg, rec, ev.size)
        except Exception as exc:
            self.rejected += 1
            self.guard.reject(f"message on {ev.key}", exc)

    def take(self, key: str, msg: Any, rec: Recorder | None, size: int = 0) -> None:
        """Record one message; ``size``: its bytes on the wire (0: its encoding's)."""
        if rec is not None:
            rec.write(key, encode(msg))
        now = time.monotonic() - self.t0
        if isinstance(msg, TruthPosesMsg):
            self.truth.append((msg.t_sim, {p[0]: (p[1], p[2], p[3]) for p in msg.poses}))
            self.truth_contacts = max(self.truth_contacts, msg.contacts)
            return
        if isinstance(msg, ContactMsg):
            self.contacts.append((msg.t_sim, msg.a, msg.b))
            return
        try:
            sender = id_from_key(key)
        except ValueError:
            return
        view = self.agents.setdefault(sender, AgentView())
        kind = key.rsplit("/", 1)[-1]
        view.bytes_by_kind[kind] += size or len(encode(msg))
        view.count_by_kind[kind] += 1
        if isinstance(msg, StatusMsg):
            if msg.phase not in view.phase_wall:
                view.phase_wall[msg.phase] = now
                view.phase_sim[msg.phase] = msg.t_sim
            view.phase, view.progress, view.detail = msg.phase, msg.progress, msg.detail
            if msg.phase == "march" and view.march_sample is None:
                view.march_sample = len(self.truth)
            view.error, view.plan_digest, view.wave, view.t_sim = (
                msg.error, msg.plan_digest, msg.wave, msg.t_sim,
            )  # fmt: skip
        elif isinstance(msg, NeighborRecordMsg):
            self.records[msg.sender] = msg
        elif isinstance(msg, DigestMsg):
            self.digests[msg.sender] = msg


class LiveView:
    """One line per agent, repainted in place on a terminal, else printed on changes."""

    def __init__(self, stream: IO[str], ids: list[int]) -> None:
        self.stream = stream
        self.ids = ids
        self.tty = stream.isatty()
        self.drawn = 0
        self.last: dict[int, str] = {}
        self.last_draw = 0.0

    def line(self, rid: int, v: AgentView | None, elapsed: float) -> str:
        if v is None:
            return f"  robot {rid:2d} | {'(waiting)':10s}"
        n = 20
        fill = round(v.progress * n)
        bar = "#" * fill + "." * (n - fill)
        wave = f"w{v.wave}" if v.wave >= 0 else "  "
        text = (v.error or v.detail)[:60]
        return f"  robot {rid:2d} | {v.phase:9s} [{bar}] {wave:3s} t_sim {v.t_sim:6.1f}s | {text}"

    def update(self, obs: Observer, elapsed: float, force: bool = False) -> None:
        if self.tty:
            if not force and elapsed - self.last_draw < 0.25:
                return
            self.last_draw = elapsed
            if self.drawn:
                self.stream.write(f"\x1b[{self.drawn}A")
            head = f"nao-formation demo  wall {elapsed:6.1f}s"
            rows = [head] + [self.line(i, obs.agents.get(i), elapsed) for i in self.ids]
            for r in rows:
                self.stream.write("\x1b[2K" + r + "\n")
            self.drawn = len(rows)
            self.stream.flush()
            return
        for i in self.ids:
            v = obs.agents.get(i)
            key = "" if v is None else f"{v.phase}:{v.error}"
            if key and self.last.get(i) != key:
                self.last[i] = key
                self.stream.write(f"[{elapsed:6.1f}s]{self.line(i, v, elapsed)}\n")
                self.stream.flush()


# ===================================================================== evaluation


def plan_from_agreed(obs: Observer, d_e: float, phi_e: float) -> Any:
    """The plan recomputed by the evaluator from the records the agents exchanged."""
    from agent.adapters import FormationAdapter

    fa = FormationAdapter()
    recs = tuple(obs.records[i] for i in sorted(obs.records))
    return fa, fa.plan(recs, d_e, phi_e)


def pyramid_pairs(plan: Any, ids: list[int]) -> list[tuple[int, int]]:
    """(child, parent) ids of the planned pyramid (AUV eq. 6 via ``RobotPlan.parent``)."""
    return sorted((i, int(plan.robot(i).parent)) for i in ids if int(plan.robot(i).parent) >= 0)


def evaluate(
    final: dict[int, tuple[float, float, float]],
    pairs: list[tuple[int, int]],
    axis: float,
    d_e: float,
    phi_e: float,
) -> list[dict[str, float]]:
    """Per pair: distance, angle off the backward axis, r_d, r_φ (NAO paper 5.1.1)."""
    back = np.array([-math.cos(axis), -math.sin(axis)])
    rows = []
    for child, parent in pairs:
        v = np.array(final[child][:2]) - np.array(final[parent][:2])
        d = float(np.hypot(*v))
        cosang = float(np.clip(np.dot(v, back) / max(d, 1e-12), -1.0, 1.0))
        phi = math.acos(cosang)
        rows.append(
            {
                "child": child,
                "parent": parent,
                "distance": d,
                "angle_deg": math.degrees(phi),
                "r_d": (d - d_e) / d_e,
                "r_phi": (phi - phi_e) / phi_e,
            }
        )
    return rows


MARCH_TOLERANCE = 0.10  # the leader's displacement within 10 % of the route


def judge_march(
    obs: Observer,
    result: dict[str, Any],
    plan: Any,
    axis: float,
    pairs: list[tuple[int, int]],
    d_e: float,
    phi_e: float,
) -> None:
    """The march from ground truth: from the moment every agent was ready to march (its
    first ``march`` status, after its correction) to the end.

    Sets ``march_distance`` (the leader's displacement, m), ``march_route`` (V, m),
    ``march_error`` (|displacement − V| / |V|), ``march_ok`` and the worst |r_d|, |r_φ|
    over every truth sample of the march."""
    from agent.config import Route
    from agent.march import route_vector

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
        if all(c in poses and p in poses for c, p in pairs):
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
    for row in result.get("pairs", []):
        c, p = row["child"], row["parent"]
        if c in final and p in final:
            ax.plot([final[c][0], final[p][0]], [final[c][1], final[p][1]], "k--", lw=0.8)
    leader = result.get("leader")
    if leader in final:
        ax.plot(final[leader][0], final[leader][1], "*", color="green", ms=16)
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("world x (m)")
    ax.set_ylabel("world y (m), north")
    ok = "success" if result.get("success") else "FAILED"
    ax.set_title(
        f"{len(ids)} NAOs, seed {result.get('seed')}: {ok}\n"
        f"max |r_d| {result.get('max_abs_r_d', float('nan')):.1%}, "
        f"max |r_phi| {result.get('max_abs_r_phi', float('nan')):.1%}, "
        f"contacts {result.get('contacts')}"
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


# ===================================================================== one run


def run_once(args: argparse.Namespace, seed: int, out: Path, quiet: bool = False) -> dict[str, Any]:
    out.mkdir(parents=True, exist_ok=True)
    n = args.robots
    d_e, phi_e = args.d_e, math.radians(args.phi_e_deg)
    net = fleet_network(args, out, n)
    endpoint = net.endpoint
    t0 = time.monotonic()
    rec = Recorder(out / "run.mcap")
    obs = Observer(t0)
    procs: list[Proc] = []
    agents: dict[int, Proc] = {}
    result: dict[str, Any] = {"robots": n, "seed": seed, "d_e": d_e, "phi_e_deg": args.phi_e_deg}
    if getattr(args, "march", None) is not None:
        result["route"] = {"distance": float(args.march)}
    elif getattr(args, "march_to", None) is not None:
        result["route"] = {"to": [float(v) for v in args.march_to.split(",")]}
    err = sys.stderr
    result["secure"] = bool(net.credentials)
    result["tls"] = net.router
    if net.router:
        procs.append(start_router(endpoint, out, net.flags))
    world_net = ["--connect" if net.router else "--listen", endpoint, *net.flags]
    bus = observer_bus(net)
    try:
        naoqi = ["--naoqi"] if getattr(args, "body", "") == "naoqi" else []
        room = march_room(args, n, seed, out)
        world = start_world(
            n, seed, endpoint, out, [*room, *(args.world_arg or []), *naoqi], world_net
        )
        procs.append(world)
        wait_world_ready(world, bus, obs, rec, args.world_timeout, out)
        result["wall_world_ready"] = time.monotonic() - t0
        ids = robot_ids(world.lines, n)
        result["ids"] = ids
        # with --body naoqi: each robot's virtual NAO, "sim naoqi robot=ID url=URL"
        args.nao_urls = {
            int(ln.split("robot=")[1].split()[0]): ln.split("url=")[1].strip()
            for ln in world.lines
            if ln.startswith("sim naoqi ")
        }
        agent_net = ["--connect", endpoint, *net.flags]
        agents.update({i: start_agent(i, n, endpoint, out, args, agent_net) for i in ids})
        procs.extend(agents.values())
        rogues = (
            start_rogues(net, out, ids, args.rogue, args.rogue_replay) if args.rogue > 0 else []
        )
        result["rogues_started"] = [r.name for r in rogues]
        live = LiveView(err, ids) if not quiet else None
        deadline = time.monotonic() + args.timeout
        while True:
            for ev in bus.drain(0.1):
                obs.take_event(ev, rec)
            if live is not None:
                live.update(obs, time.monotonic() - t0)
            if all(p.popen.poll() is not None for p in agents.values()):
                break
            if time.monotonic() > deadline:
                result["timeout"] = f"agents still running after {args.timeout:g} s"
                break
        observe_for(bus, obs, rec, 1.5)  # the last truth after the motions
        if live is not None:
            live.update(obs, time.monotonic() - t0, force=True)
        result["wall_total"] = time.monotonic() - t0
        result["rejected"] = {
            "bus": bus.stats.rejected, "untrusted": bus.stats.untrusted,
            "observer": obs.rejected,
        }  # fmt: skip
        result["dropped"] = bus.stats.dropped
        for r in rogues:  # they stop by themselves after --rogue seconds
            with contextlib.suppress(subprocess.TimeoutExpired):
                r.popen.wait(max(1.0, args.rogue + 30.0 - (time.monotonic() - t0)))
            stop(r)
    finally:
        for p in reversed(procs):
            stop(p)
        bus.close()
        rec.close()
    if getattr(args, "auto_ids", False):
        agents = claimed_ids(agents, out)
        result["claimed_ids"] = sorted(agents)
    for i, p in agents.items():
        obs.agents.setdefault(i, AgentView()).exit_code = p.popen.returncode
    return summarise(obs, result, out, sorted(agents), d_e, phi_e, quiet)


def observer_bus(net: FleetNet) -> Bus:
    """The observer's bus: statuses, records, digests, ground truth and membership."""
    bus = Bus(net.observer())
    for key in (KEY_STATUS_ALL, KEY_RECORD_ALL, KEY_DIGEST_ALL, KEY_WORLD_TRUTH_ALL):
        bus.subscribe(key)
    bus.watch_alive(KEY_ALIVE_ALL)
    return bus


def observe_for(bus: Bus, obs: Observer, rec: Recorder | None, seconds: float) -> None:
    """Hand what arrives on ``bus`` to ``obs`` for ``seconds`` (polls, bounded)."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for ev in bus.drain(0.1):
            obs.take_event(ev, rec)


def wait_world_ready(
    world: Proc, bus: Bus, obs: Observer, rec: Recorder | None, timeout: float, out: Path
) -> None:
    """Observe the bus until the world prints its ready line; ``RuntimeError`` if it exits
    or is not ready within ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while not any("ready" in ln.lower() for ln in world.lines):
        if world.popen.poll() is not None:
            raise RuntimeError(
                f"world exited with {world.popen.returncode}; see {out / 'world.log'}"
            )
        if time.monotonic() > deadline:
            raise RuntimeError(f"world not ready after {timeout:g} s")
        for ev in bus.drain(0.1):
            obs.take_event(ev, rec)


def claimed_ids(agents: dict[int, Proc], out: Path) -> dict[int, Proc]:
    """Re-key ``--id auto`` agents by the robot each one claimed (from its log)."""
    import re

    mapped: dict[int, Proc] = {}
    for slot, p in agents.items():
        text = (out / f"agent-slot{slot}.log").read_text(errors="replace")
        m = re.search(r"claimed robot (\d+)", text)
        if m is None or int(m.group(1)) in mapped:
            mapped[-1 - slot] = p  # claimed nothing (or a duplicate): a failure in the table
        else:
            mapped[int(m.group(1))] = p
    return mapped


def robot_ids(lines: list[str], n: int) -> list[int]:
    """Robot ids from the world's ready line ``sim ready robots=1,2,3 ...``."""
    for ln in lines:
        if "ready" in ln and "robots=" in ln:
            raw = ln.split("robots=", 1)[1].split()[0]
            ids = sorted(int(x) for x in raw.split(",") if x.strip())
            if len(ids) != n:
                raise RuntimeError(f"world serves {len(ids)} robots {ids}, asked for {n}")
            return ids
    raise RuntimeError(f"world ready line without robot ids: {lines[-1:]}")


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
    result["pairs"] = []
    ok_agents = all(views[i].exit_code == 0 and views[i].phase == "done" for i in ids)
    if obs.truth and len(obs.records) == n:
        try:
            fa, plan = plan_from_agreed(obs, d_e, phi_e)
            result["evaluator_plan_digest"] = str(plan.digest)
            result["leader"] = int(plan.leader)
            # in the common frame: where --march-to points are given
            result["leader_target"] = [float(v) for v in plan.robot(plan.leader).target]
            axis = fa.axis_angle(plan)
            result["axis_deg"] = math.degrees(axis)
            pairs = pyramid_pairs(plan, ids)
            final = obs.truth[-1][1]
            result["pairs"] = evaluate(final, pairs, axis, d_e, phi_e)
            result["starts"] = {
                str(i): list(obs.truth[0][1][i]) for i in ids if i in obs.truth[0][1]
            }
            result["finals"] = {str(i): list(final[i]) for i in ids if i in final}
            if result.get("route"):
                judge_march(obs, result, plan, axis, pairs, d_e, phi_e)
        except (ValueError, KeyError, AttributeError, ImportError) as exc:
            result["evaluation_error"] = f"{type(exc).__name__}: {exc}"
    rows = result["pairs"]
    result["max_abs_r_d"] = max((abs(r["r_d"]) for r in rows), default=math.nan)
    result["max_abs_r_phi"] = max((abs(r["r_phi"]) for r in rows), default=math.nan)
    within = bool(rows) and all(
        abs(r["r_d"]) <= R_D_MAX and abs(r["r_phi"]) <= R_PHI_MAX for r in rows
    )
    result["within_tolerance"] = within
    # The agents planned from exactly the records the robots signed: the evaluator, which
    # accepts only verified envelopes, recomputes the same plan digest from them.
    result["plan_matches_records"] = bool(digests) and digests == {
        result.get("evaluator_plan_digest")
    }
    trusted = True
    rogues = rogue_reports(out)
    if result.get("rogues_started"):
        result["rogues"] = rogues
        trusted = (
            result["plan_matches_records"]
            and len(rogues) == len(result["rogues_started"])
            and all(
                r.get("commands_executed", 0) == 0 and r.get("claims_granted", 0) == 0
                for r in rogues.values()
            )
        )
        result["rogue_defeated"] = trusted
    marched = result.get("march_ok", True)
    result["success"] = bool(
        ok_agents and within and result["identical_digests"] and result["contacts"] == 0
        and "timeout" not in result and trusted and marched
    )  # fmt: skip
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


def print_table(r: dict[str, Any]) -> None:
    p = print
    p(f"\nnao-formation demo: {r['robots']} robots, seed {r['seed']}, "
      f"d_e {r['d_e']:.2f} m, phi_e {r['phi_e_deg']:.0f} deg")  # fmt: skip
    p(f"{'child':>5} {'parent':>6} {'dist (m)':>9} {'angle (deg)':>11} {'r_d':>8} {'r_phi':>8}  ok")
    for row in r["pairs"]:
        ok = abs(row["r_d"]) <= R_D_MAX and abs(row["r_phi"]) <= R_PHI_MAX
        p(f"{row['child']:>5} {row['parent']:>6} {row['distance']:9.3f} {row['angle_deg']:11.1f} "
          f"{row['r_d']:+8.1%} {row['r_phi']:+8.1%}  {'yes' if ok else 'NO'}")  # fmt: skip
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
    p("phase       wall max (s)  sim max (s)")
    for ph, t in r["phases"].items():
        p(f"  {ph:9s} {t['wall_max']:12.1f} {t['sim_max']:12.1f}")
    p(f"wall total {r.get('wall_total', float('nan')):.1f} s, sim end {r['t_sim_end']:.1f} s")
    p("bytes published per agent (record + digest = exchange; status for viewers):")
    for i, b in r["bytes"].items():
        p(f"  robot {i}: total {b['total']} B, exchange {r['exchange_bytes'][i]} B, "
          f"status {b.get('status', 0)} B")  # fmt: skip
    same = "yes" if r["identical_digests"] else "NO"
    p(f"identical plan digests: {same} ({next(iter(r['plan_digests'].values()))[:12]})")
    for i, e in r["errors"].items():
        p(f"  robot {i} error: {e}")
    if "timeout" in r:
        p(f"  {r['timeout']}")
    p(f"exit codes: {r['exit_codes']}")
    p(f"figure: {r.get('figure', '-')}   recording: {r['recording']}")
    p("RESULT: " + ("SUCCESS" if r["success"] else "FAILURE"))


# ===================================================================== CLI


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m tools.demo", description=__doc__.split("\n\n")[0])
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", type=Path, default=Path("out/demo"))
    p.add_argument("--json", type=Path, default=None, help="also write the result JSON here")
    p.add_argument("--batch", type=int, default=0, help="run seeds seed..seed+K-1, print totals")
    p.add_argument("--d-e", type=float, default=0.8)
    p.add_argument("--phi-e-deg", type=float, default=30.0)
    p.add_argument("--timeout", type=float, default=600.0, help="wall limit for the agents (s)")
    p.add_argument("--agree-timeout", type=float, default=120.0)
    p.add_argument("--auto-ids", action="store_true", help="agents claim robots (--id auto)")
    p.add_argument("--no-correct", action="store_true", help="agents skip the final alignment")
    march = p.add_mutually_exclusive_group()
    march.add_argument(
        "--march", type=float, default=None, metavar="D",
        help="after hold, the fleet marches D m along the pyramid's axis (issue #13)",
    )  # fmt: skip
    march.add_argument(
        "--march-to", default=None, metavar="X,Y",
        help="after hold, the leader marches to (X, Y) m in the common frame",
    )  # fmt: skip
    p.add_argument("--agent-log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING"))
    p.add_argument("--world-timeout", type=float, default=120.0)
    p.add_argument(
        "--body",
        choices=("zenoh", "naoqi"),
        default="zenoh",
        help="agents drive the world over zenoh, or its virtual NAOs over qi (sim --naoqi)",
    )
    p.add_argument(
        "--world-arg", action="append", default=[], help="extra argument for python -m sim"
    )
    p.add_argument(
        "--credentials",
        type=Path,
        default=None,
        help="fleet credentials folder (default: a throwaway fleet in OUT/fleet)",
    )
    p.add_argument(
        "--insecure", action="store_true", help="no TLS, access control or signatures (dev only)"
    )
    p.add_argument(
        "--rogue",
        type=float,
        default=0.0,
        metavar="S",
        help="attack the fleet with tools.rogue for S seconds while it works (issue #8)",
    )
    p.add_argument(
        "--rogue-replay",
        type=Path,
        default=None,
        metavar="FILE",
        help="the rogue also replays this capture of an earlier run (rogue-*.capture)",
    )
    p.add_argument(
        "--plain-links",
        action="store_true",
        help="tests: signatures over plain TCP links (no TLS/ACL), as behind a bad router",
    )
    a = p.parse_args(argv)
    if not 1 <= a.robots <= 64:
        p.error("--robots must be in [1, 64]")
    if a.batch < 0:
        p.error("--batch must be >= 0")
    if a.body == "naoqi" and a.auto_ids:
        p.error("--body naoqi drives the robot at a fixed URL: no --auto-ids")
    if not (math.isfinite(a.d_e) and a.d_e > 0) or not 0 < a.phi_e_deg < 90:
        p.error("--d-e must be > 0 and --phi-e-deg in (0, 90)")
    from agent.config import Route

    try:
        if a.march is not None:
            Route(distance=a.march)
        if a.march_to is not None:
            xy = a.march_to.split(",")
            if len(xy) != 2:
                raise ValueError(f"--march-to wants X,Y, got {a.march_to!r}")
            Route(to=(float(xy[0]), float(xy[1])))
    except ValueError as exc:
        p.error(str(exc))
    return a


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    if args.insecure:
        print(INSECURE_WARNING, file=sys.stderr)
    if args.batch:
        return batch(args)
    try:
        result = run_once(args, args.seed, args.out)
    except RuntimeError as exc:
        print(f"demo failed: {exc}", file=sys.stderr)
        return 1
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2, default=float))
    return 0 if result["success"] else 1


def batch(args: argparse.Namespace) -> int:
    results = []
    for k in range(args.batch):
        seed = args.seed + k
        print(
            f"[batch] run {k + 1}/{args.batch}: {args.robots} robots, seed {seed}", file=sys.stderr
        )
        try:
            r = run_once(args, seed, args.out / f"seed-{seed:03d}", quiet=True)
        except RuntimeError as exc:
            r = {"seed": seed, "success": False, "error": str(exc), "contacts": -1,
                 "identical_digests": False, "pairs": []}  # fmt: skip
        results.append(r)
        print(
            f"[batch] seed {seed}: {'ok' if r['success'] else 'FAIL'} "
            f"max|r_d| {r.get('max_abs_r_d', math.nan):.1%} max|r_phi| {r.get('max_abs_r_phi', math.nan):.1%} "
            f"contacts {r.get('contacts')} digests {'same' if r.get('identical_digests') else 'DIFFER'} "
            f"march {r.get('march_distance', math.nan):.2f} m worst|r_d| {r.get('march_worst_abs_r_d', math.nan):.1%} "
            f"wall {r.get('wall_total', math.nan):.0f}s",
            file=sys.stderr,
        )
    ok = sum(1 for r in results if r["success"])
    collisions = sum(1 for r in results if r.get("contacts", -1) != 0)
    same = sum(1 for r in results if r.get("identical_digests"))
    completed = sum(1 for r in results if set(r.get("final_phase", {}).values()) == {"done"})
    rds = [abs(p["r_d"]) for r in results for p in r.get("pairs", [])]
    rps = [abs(p["r_phi"]) for r in results for p in r.get("pairs", [])]
    walls = [r["wall_total"] for r in results if "wall_total" in r]
    exch = [v for r in results for v in r.get("exchange_bytes", {}).values()]
    tot = [b["total"] for r in results for b in r.get("bytes", {}).values()]
    summary: dict[str, Any] = {
        "robots": args.robots, "runs": len(results), "success": ok, "completed": completed,
        "runs_with_contacts": collisions, "identical_digests": same,
        "median_abs_r_d": float(np.median(rds)) if rds else math.nan,
        "max_abs_r_d": max(rds, default=math.nan),
        "median_abs_r_phi": float(np.median(rps)) if rps else math.nan,
        "max_abs_r_phi": max(rps, default=math.nan),
        "wall_median": float(np.median(walls)) if walls else math.nan,
        "exchange_bytes_max": max(exch, default=0), "published_bytes_max": max(tot, default=0),
    }  # fmt: skip
    if args.march is not None or args.march_to is not None:
        md = [r["march_worst_abs_r_d"] for r in results if "march_worst_abs_r_d" in r]
        mp = [r["march_worst_abs_r_phi"] for r in results if "march_worst_abs_r_phi" in r]
        me = [r["march_error"] for r in results if "march_error" in r]
        summary.update({
            "march_worst_abs_r_d": max(md, default=math.nan),
            "march_worst_abs_r_phi": max(mp, default=math.nan),
            "march_error_max": max(me, default=math.nan),
            "contacts_total": sum(r.get("contacts", 0) for r in results if r.get("contacts", 0) > 0),
        })  # fmt: skip
    print(f"\nbatch: {args.robots} robots, seeds {args.seed}..{args.seed + args.batch - 1}")
    for name, val in summary.items():
        print(f"  {name:22s} {val:.3f}" if isinstance(val, float) else f"  {name:22s} {val}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "batch.json").write_text(
        json.dumps({"summary": summary, "runs": results}, indent=2, default=float)
    )
    if args.json is not None:
        args.json.write_text(
            json.dumps({"summary": summary, "runs": results}, indent=2, default=float)
        )
    return 0 if ok == len(results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
