"""Processes of one run: free ports, the world, the router, the agents, the rogues, the
fleet's network (docs/design.md §8), and stopping them.

Every tool and test that starts ``python -m sim``, ``python -m agent`` or
``python -m tools.router`` on this machine does it here (:mod:`tools.harness.fleet`,
``tools.fuzz``, ``tools.bench world``, tests/system, tests/sim/server/test_server.py);
:mod:`tools.harness.hosts` runs the same command lines on test hosts (``tools.eval_loss``,
``tools.eval_chaos``). An agent's flags are written by its config alone
(:meth:`agent.config.AgentConfig.to_argv`).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from agent.config import AgentConfig
from agent.net.bus import BusConfig
from agent.wire.trust import create_fleet

ROOT = Path(__file__).resolve().parents[2]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# ===================================================================== processes


@dataclass
class Proc:
    name: str
    popen: subprocess.Popen[bytes]
    log: IO[bytes]
    lines: list[str] = field(default_factory=list)


class Lines:
    """A child's text stdout, pumped by a thread into ``lines`` (to wait for a ready line
    of a process started elsewhere, e.g. in a network namespace by ``tools.eval_loss``)."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.lines: list[str] = []
        self._proc = proc
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self._proc.stdout is not None
        for line in self._proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, needle: str, deadline_s: float) -> bool:
        """Whether a line holding ``needle`` came within ``deadline_s`` seconds (polls;
        False at once when the child ends without one)."""
        end = time.monotonic() + deadline_s
        while time.monotonic() < end:
            if any(needle in ln for ln in self.lines):
                return True
            if self._proc.poll() is not None:
                return any(needle in ln for ln in self.lines)
            time.sleep(0.1)  # polling the pumped lines, bounded by the deadline
        return False


def world_command(robots: int, seed: int, net: list[str], extra: list[str]) -> list[str]:
    """The argv of ``python -m sim`` (``extra``: e.g. ``--scenario FILE``, which replaces
    ``--robots``/``--seed``); :func:`start_world` runs it here, ``tools.eval_loss`` inside a
    network namespace."""
    return [
        sys.executable, "-m", "sim", "--robots", str(robots), "--seed", str(seed), *net, *extra,
    ]  # fmt: skip


def start_world(
    robots: int,
    seed: int,
    endpoint: str,
    out: Path | None,
    extra: list[str],
    net: list[str] | None = None,
) -> Proc:
    """``python -m sim``; ``net``: its join flags (default: listen on ``endpoint``, insecure).

    Its stdout and stderr go to ``out/world.log`` (``out`` None: nowhere, as the benches
    want); its stdout lines also to ``Proc.lines`` (see :func:`wait_ready`)."""
    if net is None:
        net = ["--listen", endpoint, "--no-multicast-scouting", "--insecure"]
    cmd = world_command(robots, seed, net, extra)
    log = (out / "world.log").open("wb") if out is not None else open(os.devnull, "wb")  # noqa: SIM115
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=log)
    proc = Proc("world", p, log)

    def pump() -> None:
        assert p.stdout is not None
        for raw in p.stdout:
            log.write(raw)
            proc.lines.append(raw.decode(errors="replace").strip())

    threading.Thread(target=pump, daemon=True).start()
    return proc


def wait_ready(world: Proc, timeout: float, idle: Callable[[], object] | None = None) -> str:
    """Wait for the world's ready line (``sim ready robots=1,2,3 ...``) and return it.

    ``idle`` is called between looks (default: sleep 0.1 s; ``tools.demo`` drains its bus
    there). ``RuntimeError`` when the world exits first or ``timeout`` seconds pass."""
    deadline = time.monotonic() + timeout
    while not any("ready" in ln.lower() for ln in world.lines):
        if world.popen.poll() is not None:
            see = f"; see {world.log.name}" if world.log.name != os.devnull else ""
            raise RuntimeError(f"world exited with {world.popen.returncode}{see}")
        if time.monotonic() > deadline:
            raise RuntimeError(f"world not ready after {timeout:g} s")
        if idle is None:
            time.sleep(0.1)  # polling the world's stdout lines, bounded by the deadline
        else:
            idle()
    return next(ln for ln in world.lines if "ready" in ln.lower())


def agent_command(
    cfg: AgentConfig,
    net: Sequence[str],
    *,
    claim_id: bool = False,
    log_level: str | None = None,
    nao: str | None = None,
    extra: Sequence[str] = (),
) -> list[str]:
    """The argv of ``python -m agent`` running ``cfg`` (its flags: ``cfg.to_argv()``, the
    agent's defaults left out), joining with ``net``; ``claim_id``: ``--id auto``;
    ``log_level``: its ``--log-level`` (None: the agent's); ``nao``: the qi URL of the NAO
    it drives (``--body naoqi``); ``extra``: more flags, last (``--state-dir``, a test's odd
    setting). :func:`start_agent` runs it here, :mod:`tools.harness.hosts` on a test host."""
    return [
        sys.executable, "-m", "agent", *cfg.to_argv(claim_id=claim_id), *net,
        *(["--log-level", log_level] if log_level else []),
        *(["--body", "naoqi", "--nao", nao] if nao else []),
        *extra,
    ]  # fmt: skip


def start_agent(cmd: list[str], log: Path, append: bool = False) -> Proc:
    """An agent process running ``cmd`` (:func:`agent_command`), its output to ``log``
    (``append``: added to, as for a restarted agent)."""
    f = log.open("ab" if append else "wb")
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=f, stderr=subprocess.STDOUT)
    return Proc(log.stem, p, f)


def router_command(endpoint: str, net: list[str]) -> list[str]:
    """The argv of ``python -m tools.router`` listening on ``endpoint`` (``net``: more flags)."""
    return [sys.executable, "-m", "tools.router", "--listen", endpoint, *net]


def start_router(endpoint: str, out: Path, net: list[str]) -> Proc:
    """``python -m tools.router`` listening on ``endpoint``; waits for its ready line."""
    cmd = router_command(endpoint, net)
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
    """How one run's processes join the bus (docs/design.md §8): see :func:`fleet_network`."""

    endpoint: str
    flags: list[str]  # join flags every process gets (besides --listen/--connect)
    credentials: str = ""  # empty: insecure
    tls: bool = True

    @property
    def router(self) -> bool:
        """Secure TLS runs meet at a router; the others at the world's listener."""
        return bool(self.credentials) and self.tls

    def observer(self, identity: str = "observer") -> BusConfig:
        """The bus of an observer (or of another fleet identity that is no robot)."""
        if not self.credentials:
            return BusConfig(connect=(self.endpoint,), multicast_scouting=False)
        return BusConfig(
            connect=(self.endpoint,),
            multicast_scouting=False,
            mode="client" if self.tls else "peer",
            credentials=self.credentials,
            identity=identity,
            tls=self.tls,
        )

    def operator(self) -> BusConfig:
        """The operator's bus: it publishes the reshape commands (docs/formation.md)."""
        return self.observer("operator")


def fleet_network(
    out: Path,
    robots: int,
    ids: Sequence[int] | None = None,
    *,
    insecure: bool = False,
    credentials: Path | None = None,
    plain_links: bool = False,
) -> FleetNet:
    """One run's network: secure by default.

    Secure: a throwaway fleet in ``out/fleet`` unless ``credentials`` names one, a TLS
    router on a free loopback port, every process a client of it. ``plain_links``
    (tests): the same signatures over plain TCP, the world listening. ``insecure``:
    plain TCP, no signatures. ``ids``: the robots' ids (default 1..robots).
    """
    port = free_port()
    if insecure:
        return FleetNet(f"tcp/127.0.0.1:{port}", ["--no-multicast-scouting", "--insecure"])
    creds = credentials
    if creds is None:
        creds = out / "fleet"  # throwaway: made anew for every run
        shutil.rmtree(creds, ignore_errors=True)
        fleet = sorted(ids) if ids else list(range(1, robots + 1))
        create_fleet(creds, [*fleet, fleet[-1] + 1])  # one spare robot key: --rogue's insider
    flags = ["--no-multicast-scouting", "--credentials", str(creds)]
    if plain_links:
        return FleetNet(f"tcp/127.0.0.1:{port}", [*flags, "--plain-links"], str(creds), False)
    return FleetNet(f"tls/127.0.0.1:{port}", flags, str(creds))


def start_rogues(
    net: FleetNet, out: Path, ids: list[int], duration: float, replay: Path | None = None
) -> list[Proc]:
    """``tools.rogue`` attackers for ``--rogue`` (docs/security.md), each writing a JSON report.

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
