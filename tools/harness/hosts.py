"""One run's fleet on test hosts, with the levers of fault injection (docs/design.md §6, §8;
docs/faults.md "Chaos soak").

As ``tools.eval_loss`` lays it out (:mod:`tools.netns`, all on this machine):

=========  ====================================================================
host 1     the zenoh router (``python -m tools.router``), the rendezvous; its second
           port (``agent.wire.WORLD_PORT``) carries the world's link and the agents'
           body sessions
host 2     the world (``python -m sim``)
host 3     the monitor (:mod:`tools.harness.monitor`), which records and judges the run
           with the agents' planning parameters and shape (:func:`monitor_command`)
host 4..   one agent each (``python -m agent --id I --state-dir``, ids from the world's
           ready line)
then       one render worker each when ``render_workers`` K > 0 (the world spread over hosts:
           ``python -m sim.server.render_worker --shard i/K`` on the world's port), started
           after the world; they draw every camera picture
=========  ====================================================================

The run is a :class:`~tools.harness.fleet.FleetSpec`, as on this machine
(:class:`~tools.harness.fleet.Fleet`): the robots, the seed, every agent's settings (their
flags written by :meth:`agent.config.AgentConfig.to_argv`), ``journal`` (``--state-dir``),
``world_args`` (``--reply-delay``), ``render_workers``, ``timeout``; secure with
``credentials`` made for the test hosts (:func:`host_fleet_credentials`), or ``insecure``.
:class:`Hosts` says where: the hosts' name prefix, a cap of TCP's retransmission timeout,
the agents' zenoh mode, and a packet loss installed before the agents start.

The levers: :meth:`HostFleet.kill_agent` (SIGKILL, no goodbye) and
:meth:`HostFleet.start_agent` (the same id and state folder, so it resumes from its
journal), :meth:`HostFleet.kill_router` and :meth:`HostFleet.start_router` (the same
endpoint), :meth:`HostFleet.set_loss` (every agent host drops packets with a probability,
traffic on the world's port exempt unless ``lossy_world``: on a real NAO the camera and
legs are on board) and :meth:`HostFleet.clear_loss`. :meth:`HostFleet.wait` watches the
agents until they have exited; :meth:`HostFleet.judge` hands the monitor the agents' exit
codes and returns its ``result.json``. Needs root, iproute2 and iptables.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from agent import wire as P
from tools import netns
from tools.harness.fleet import FleetSpec
from tools.harness.procs import ROOT, Lines, robot_ids, router_command, world_command
from tools.harness.render import render_command, served_by
from tools.packet_drop import Dropper

ROUTER, WORLD, MONITOR, FIRST_AGENT = 1, 2, 3, 4


def host_fleet_credentials(out: Path, robots: int) -> str:
    """A fleet for robots 1..``robots`` whose router is reached at test host 1 (made once
    under ``out``)."""
    from agent.wire.trust import create_fleet

    root = out / f"fleet-{robots}"
    if not (root / "ca.pem").exists():
        create_fleet(root, range(1, robots + 1), hosts=[netns.address(ROUTER)])
    return str(root)


def monitor_command(spec: FleetSpec, connect: str, out: Path, sec: list[str]) -> list[str]:
    """The argv of the monitor of ``spec``'s run (``python -m tools.eval_loss --monitor``)
    joining at ``connect`` with ``sec`` (``--insecure`` or ``--credentials DIR``), writing
    to ``out``: it judges the run with the agents' planning parameters, their d_e and φ_e,
    orientation, strategy and shape (a built-in's name or a formation file's path, its
    ``source``; :func:`agent.config.load_shape` loads it again). ``ValueError`` for a shape
    with no source (built in code, not loaded): the monitor could not judge against it."""
    cfg = spec.agent
    if not cfg.shape.source:
        raise ValueError(
            f"the monitor cannot be told the shape {cfg.shape.name!r}: it came from no "
            "formation file (its source)"
        )
    return [
        sys.executable, "-m", "tools.eval_loss", "--monitor", "--connect", connect,
        "--out", str(out), "--seed", str(spec.seed), "--d-e", repr(cfg.d_e),
        "--phi-e-deg", repr(cfg.phi_e_deg), "--orientation", cfg.orientation,
        "--strategy", cfg.strategy, "--shape", cfg.shape.source, *sec,
    ]  # fmt: skip


#: Bounds of Linux's ``net.ipv4.tcp_rto_max_ms`` (kernel >= 6.15; ms).
TCP_RTO_MAX_RANGE = (1000, 120000)


def cap_tcp_rto(fab: netns.Fabric, ms: int) -> None:
    """Cap TCP's retransmission timeout at ``ms`` on every host of ``fab`` (see
    :class:`Hosts`)."""
    lo, hi = TCP_RTO_MAX_RANGE
    if not lo <= ms <= hi:
        raise ValueError(f"tcp_rto_max_ms must be in [{lo}, {hi}], got {ms}")
    for i in range(1, fab.n + 1):
        fab.run(i, ["sysctl", "-q", "-w", f"net.ipv4.tcp_rto_max_ms={ms}"])


@dataclass(frozen=True)
class Hosts:
    """Where a run lives on test hosts (module docstring).

    ``prefix``: the hosts' name prefix (:mod:`tools.netns`). ``tcp_rto_max_ms`` > 0: every
    host's kernel caps TCP's retransmission timeout there (``net.ipv4.tcp_rto_max_ms``).
    TCP doubles its retransmission timeout after every lost retransmission, up to 120 s
    by default: at 50 % loss per direction (a segment and its ACK both get through with
    probability 1/4) six losses in a row, probability 0.75^6 ≈ 18 %, already stall a
    zenoh session for about 25 s, longer than the membership grace; with a cap the
    session keeps probing. The setting is per network namespace, so only the test hosts
    change; on robots it is a deployment setting of their kernels. ``agent_mode``: the
    agents' zenoh mode, ``client`` (of the router; their body sessions on its world
    port) or ``peer`` (a mesh, insecure fleets only). ``loss``: every agent host drops
    packets with this probability per direction from before the agents start
    (``lossy_world``: also on the world's port).
    """

    prefix: str
    tcp_rto_max_ms: int = 0
    agent_mode: str = "client"
    loss: float = 0.0
    lossy_world: bool = False

    def __post_init__(self) -> None:
        lo, hi = TCP_RTO_MAX_RANGE
        if self.tcp_rto_max_ms and not lo <= self.tcp_rto_max_ms <= hi:
            raise ValueError(f"tcp_rto_max_ms must be 0 or in [{lo}, {hi}]")
        if self.agent_mode not in ("client", "peer"):
            raise ValueError(f"agent mode must be client or peer, got {self.agent_mode!r}")
        if not 0.0 <= self.loss <= 1.0:
            raise ValueError(f"loss must be a probability in [0, 1], got {self.loss}")


class HostFleet:
    """One run of ``spec`` on test hosts laid out by ``hosts`` (module docstring): the
    router, the monitor, the world, the render workers and, once the loss is installed,
    one agent per robot; logs, the recording and ``result.json`` in ``out``."""

    def __init__(self, spec: FleetSpec, out: Path, hosts: Hosts) -> None:
        if not spec.insecure and spec.credentials is None:
            raise ValueError("a secure fleet on test hosts needs credentials made for them")
        if hosts.agent_mode == "peer" and not spec.insecure:
            raise ValueError("agents in peer mode need an insecure fleet (secure: a router)")
        self.spec, self.workdir, self.hosts = spec, out, hosts
        self.robots, self.seed = spec.robots, spec.seed
        self.render_workers = spec.render_workers
        self.fab = netns.Fabric(
            spec.robots + FIRST_AGENT - 1 + spec.render_workers, prefix=hosts.prefix
        )
        self.renderers: list[subprocess.Popen[str]] = []
        proto = "tcp" if spec.insecure else "tls"
        self.router_ep = f"{proto}/{netns.address(ROUTER)}:{P.BUS_PORT}"
        self.world_ep = f"{proto}/{netns.address(ROUTER)}:{P.WORLD_PORT}"
        self.sec = ["--insecure"] if spec.insecure else ["--credentials", str(spec.credentials)]
        # refused here, before any host exists: a shape the monitor cannot be told
        self.monitor_argv = monitor_command(spec, self.router_ep, out, self.sec)
        self.env = dict(os.environ, PYTHONUNBUFFERED="1", MPLBACKEND="Agg")
        self.ids: list[int] = []
        self.agents: dict[int, subprocess.Popen[str]] = {}
        self.router: subprocess.Popen[str] | None = None
        self.monitor: subprocess.Popen[str] | None = None
        self._monitor_lines: Lines | None = None
        self._droppers: list[Dropper] = []
        self._dropped = 0
        self._files: list[IO[str]] = []
        self.t_agents = time.monotonic()  # when the agents started (reset then)
        #: why the run was cut (:meth:`wait`: the timeout), None when the agents finished
        self.cut: str | None = None

    # ------------------------------------------------------------------ set-up

    def _log(self, name: str, append: bool = False) -> IO[str]:
        f = open(self.workdir / f"{name}.log", "a" if append else "w")  # noqa: SIM115
        self._files.append(f)
        return f

    def __enter__(self) -> HostFleet:
        self.workdir.mkdir(parents=True, exist_ok=True)
        (self.workdir / "result.json").unlink(missing_ok=True)  # the monitor writes it anew
        self.fab.up()
        try:
            self._start()
        except BaseException:
            self.close()
            raise
        return self

    def _start(self) -> None:
        if self.hosts.tcp_rto_max_ms:
            cap_tcp_rto(self.fab, self.hosts.tcp_rto_max_ms)
        self.start_router()
        self.monitor = subprocess.Popen(
            netns.netns_cmd(
                self.fab.name(MONITOR),
                self.monitor_argv,
            ),
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._log("monitor"),
            text=True, env=self.env, cwd=str(ROOT), start_new_session=True,
        )  # fmt: skip
        self._monitor_lines = Lines(self.monitor)
        if not self._monitor_lines.wait_for("monitor ready", 30.0):
            raise RuntimeError(f"monitor did not start; see {self.workdir / 'monitor.log'}")
        world_net = ["--connect", self.world_ep, "--no-multicast-scouting", *self.sec]
        world = self.fab.popen(
            WORLD,
            world_command(self.robots, self.seed, world_net, list(self.spec.world_args)),
            stderr=self._log("world"),
            env=self.env,
            cwd=str(ROOT),
        )
        lines = Lines(world)
        if not lines.wait_for("ready", 180.0):
            raise RuntimeError(f"world not ready; see {self.workdir / 'world.log'}")
        self.ids = robot_ids(lines.lines, self.robots)
        self._start_renderers()
        self._droppers = [Dropper(self.fab.name(FIRST_AGENT + k)) for k in range(self.robots)]
        if self.hosts.loss > 0.0:
            self.set_loss(self.hosts.loss, self.hosts.lossy_world)
        self.t_agents = time.monotonic()
        for rid in self.ids:
            self.start_agent(rid)

    def _start_renderers(self) -> None:
        """K render workers, one per host after the agents' (shards 1/K..K/K)."""
        k = self.render_workers
        net = ["--connect", self.world_ep, "--no-multicast-scouting", *self.sec, "--mode", "client"]
        for i in range(1, k + 1):
            host = FIRST_AGENT + self.robots + i - 1
            p = self.fab.popen(
                host,
                render_command(net, (i, k)),
                stderr=self._log(f"render-{i}"),
                env=self.env,
                cwd=str(ROOT),
            )
            self.renderers.append(p)
            if not Lines(p).wait_for("render ready", 180.0):
                raise RuntimeError(f"render worker {i} not ready; see render-{i}.log")

    def render_served(self) -> dict[str, int | None]:
        """Camera queries each render worker answered (after :meth:`close`)."""
        return served_by(self.workdir, self.render_workers)

    def close(self) -> None:
        """Clear the loss, stop the monitor and every process, remove the test hosts."""
        for p in self.renderers:  # SIGTERM first: each logs what it served
            netns.stop(p, timeout=10.0)
        with contextlib.suppress(Exception):
            self.clear_loss()
        if self.monitor is not None:
            netns.stop(self.monitor, timeout=10.0)
        self.fab.down()
        for f in self._files:
            with contextlib.suppress(OSError):
                f.close()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # ------------------------------------------------------------------ levers

    def start_agent(self, rid: int, append: bool = False) -> None:
        """Start robot ``rid``'s agent (again, with ``append``: same id, same state folder)."""
        host = FIRST_AGENT + self.ids.index(rid)
        mode = self.hosts.agent_mode
        body = ["--world-connect", self.world_ep] if mode == "client" else []
        net = ["--connect", self.router_ep, "--no-multicast-scouting", *self.sec,
               "--mode", mode, *body]  # fmt: skip
        state = ["--state-dir", str(self.workdir / "state")] if self.spec.journal else []
        cmd = self.spec.agent_command(rid, net, state)
        self.agents[rid] = self.fab.popen(
            host,
            cmd,
            stdout=self._log(f"agent-{rid}", append),
            stderr=subprocess.STDOUT,
            env=self.env,
            cwd=str(ROOT),
        )

    def running(self, rid: int) -> bool:
        p = self.agents.get(rid)
        return p is not None and p.poll() is None

    def all_exited(self) -> bool:
        return all(p.poll() is not None for p in self.agents.values())

    def exit_codes(self) -> dict[str, int | None]:
        return {str(i): self.agents[i].poll() for i in sorted(self.agents)}

    def kill_agent(self, rid: int) -> None:
        """SIGKILL robot ``rid``'s agent (its whole process group), no goodbye."""
        _kill(self.agents[rid])

    def start_router(self) -> None:
        """Start the router (again) on the same endpoints; waits for its ready line."""
        cmd = router_command(
            self.router_ep, ["--listen", self.world_ep, "--no-multicast-scouting", *self.sec]
        )
        again = self.router is not None
        self.router = self.fab.popen(
            ROUTER, cmd, stderr=self._log("router", again), env=self.env, cwd=str(ROOT)
        )
        if not Lines(self.router).wait_for("router ready", 30.0):
            raise RuntimeError(f"router did not start; see {self.workdir / 'router.log'}")

    def kill_router(self) -> None:
        if self.router is not None:
            _kill(self.router)

    def set_loss(self, loss: float, lossy_world: bool = False) -> None:
        """Every agent host drops packets with probability ``loss`` per direction, except
        on the world's port unless ``lossy_world`` (replaces the loss before)."""
        self.clear_loss()
        for d in self._droppers:
            d.install(loss, "both", exempt_ports=[] if lossy_world else [P.WORLD_PORT])

    def clear_loss(self) -> None:
        for d in self._droppers:
            self._dropped += d.dropped_packets()
            d.clear()

    @property
    def dropped_packets(self) -> int:
        """Packets dropped by the loss so far (counted when it is cleared)."""
        return self._dropped

    # ------------------------------------------------------------------ verdict

    def wait(self, busy: Callable[[float], bool] | None = None, period: float = 0.5) -> None:
        """Watch the agents every ``period`` s until every one has exited and ``busy``
        (called with the seconds since the agents started: a caller's injector) has nothing
        pending, or the spec's ``timeout`` (:attr:`cut`)."""
        while True:
            now = time.monotonic() - self.t_agents
            pending = busy(now) if busy is not None else False
            if not pending and self.all_exited():
                return
            if now > self.spec.wall:
                self.cut = f"agents still running after {self.spec.wall:g} s"
                return
            time.sleep(period)  # polling the agents' exits, bounded by the timeout

    def judge(self, timeout: str | None = None) -> dict[str, Any]:
        """Hand the monitor the agents' exit codes (``timeout``: why the run was cut,
        default :attr:`cut`) and return its ``result.json`` (empty when it wrote none)."""
        assert self.monitor is not None and self.monitor.stdin is not None
        assert self._monitor_lines is not None
        cut = timeout if timeout is not None else self.cut
        order = {"ids": self.ids, "exit_codes": self.exit_codes(), "timeout": cut}
        with contextlib.suppress(OSError):
            self.monitor.stdin.write(json.dumps(order) + "\n")
            self.monitor.stdin.flush()
        self._monitor_lines.wait_for("monitor done", 90.0)
        path = self.workdir / "result.json"
        with contextlib.suppress(OSError, ValueError):
            res: dict[str, Any] = json.loads(path.read_text())
            return res
        return {}


def _kill(p: subprocess.Popen[str]) -> None:
    """SIGKILL ``p``'s process group (it was started in a session of its own) and reap it."""
    if p.poll() is None:
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            p.kill()
        with contextlib.suppress(subprocess.TimeoutExpired):
            p.wait(timeout=10.0)
