"""One run's fleet on test hosts, with the levers of fault injection (docs/design.md §6, §8;
docs/faults.md "Chaos soak").

As ``tools.eval_loss`` lays it out (:mod:`tools.netns`, all on this machine):

=========  ====================================================================
host 1     the zenoh router (``python -m tools.router``), the rendezvous; its second
           port (``agent.wire.WORLD_PORT``) carries the world's link and the agents'
           body sessions
host 2     the world (``python -m sim``)
host 3     the monitor (:mod:`tools.harness.monitor`), which records and judges the run
host 4..   one agent each (``python -m agent --id I --state-dir``, ids from the world's
           ready line)
then       one render worker each when ``render_workers`` K > 0 (the world spread over hosts:
           ``python -m sim.render_worker --shard i/K`` on the world's port), started
           after the world; they draw every camera picture
=========  ====================================================================

The levers: :meth:`HostFleet.kill_agent` (SIGKILL, no goodbye) and
:meth:`HostFleet.start_agent` (the same id and state folder, so it resumes from its
journal), :meth:`HostFleet.kill_router` and :meth:`HostFleet.start_router` (the same
endpoint), :meth:`HostFleet.set_loss` (every agent host drops packets with a probability,
traffic on the world's port exempt: on a real NAO the camera and legs are on board) and
:meth:`HostFleet.clear_loss`. :meth:`HostFleet.judge` hands the monitor the agents'
exit codes and returns its ``result.json``. Needs root, iproute2 and iptables.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from agent import wire as P
from tools import netns
from tools.harness.procs import (
    ROOT,
    Lines,
    agent_command,
    robot_ids,
    router_command,
    world_command,
)
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


class HostFleet:
    """Router, world and monitor of one run on test hosts; agents started by the caller.

    ``args`` holds the agents' settings as :func:`tools.harness.procs.agent_command` reads
    them (``d_e``, ``phi_e_deg``, ``agree_timeout``, ``agent_log_level``) and
    ``tcp_rto_max_ms``; ``credentials``: a fleet folder from
    :func:`host_fleet_credentials` (empty: insecure); ``world_extra``: more world flags
    (``--reply-delay``).
    """

    def __init__(
        self,
        args: argparse.Namespace,
        robots: int,
        seed: int,
        workdir: Path,
        prefix: str,
        credentials: str = "",
        world_extra: list[str] | None = None,
        render_workers: int = 0,
    ) -> None:
        self.args, self.robots, self.seed, self.workdir = args, robots, seed, workdir
        self.render_workers = render_workers
        self.fab = netns.Fabric(robots + FIRST_AGENT - 1 + render_workers, prefix=prefix)
        self.renderers: list[subprocess.Popen[str]] = []
        self.world_extra = world_extra or []
        proto = "tls" if credentials else "tcp"
        self.router_ep = f"{proto}/{netns.address(ROUTER)}:{P.BUS_PORT}"
        self.world_ep = f"{proto}/{netns.address(ROUTER)}:{P.WORLD_PORT}"
        self.sec = ["--credentials", credentials] if credentials else ["--insecure"]
        self.env = dict(os.environ, PYTHONUNBUFFERED="1", MPLBACKEND="Agg")
        self.ids: list[int] = []
        self.agents: dict[int, subprocess.Popen[str]] = {}
        self.router: subprocess.Popen[str] | None = None
        self.monitor: subprocess.Popen[str] | None = None
        self._monitor_lines: Lines | None = None
        self._droppers: list[Dropper] = []
        self._dropped = 0
        self._files: list[IO[str]] = []

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
        rto = int(getattr(self.args, "tcp_rto_max_ms", 0) or 0)
        if rto:
            for i in range(1, self.fab.n + 1):
                self.fab.run(i, ["sysctl", "-q", "-w", f"net.ipv4.tcp_rto_max_ms={rto}"])
        self.start_router()
        py, a = sys.executable, self.args
        self.monitor = subprocess.Popen(
            netns.netns_cmd(
                self.fab.name(MONITOR),
                [
                    py, "-m", "tools.eval_loss", "--monitor", "--connect", self.router_ep,
                    "--out", str(self.workdir), "--d-e", str(a.d_e), "--phi-e-deg",
                    str(a.phi_e_deg), "--seed", str(self.seed), *self.sec,
                ],
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
            world_command(self.robots, self.seed, world_net, self.world_extra),
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
        net = ["--connect", self.router_ep, "--no-multicast-scouting", *self.sec,
               "--mode", "client", "--world-connect", self.world_ep]  # fmt: skip
        state = ["--state-dir", str(self.workdir / "state")]
        cmd = agent_command(rid, self.robots, self.router_ep, self.args, net, state)
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

    def set_loss(self, loss: float) -> None:
        """Every agent host drops packets with probability ``loss`` per direction, except
        on the world's port (replaces the loss before)."""
        self.clear_loss()
        for d in self._droppers:
            d.install(loss, "both", exempt_ports=[P.WORLD_PORT])

    def clear_loss(self) -> None:
        for d in self._droppers:
            self._dropped += d.dropped_packets()
            d.clear()

    @property
    def dropped_packets(self) -> int:
        """Packets dropped by the loss so far (counted when it is cleared)."""
        return self._dropped

    # ------------------------------------------------------------------ verdict

    def judge(self, timeout: str | None) -> dict[str, Any]:
        """Hand the monitor the agents' exit codes (``timeout``: why the run was cut, or
        None) and return its ``result.json`` (empty when it wrote none)."""
        assert self.monitor is not None and self.monitor.stdin is not None
        assert self._monitor_lines is not None
        order = {"ids": self.ids, "exit_codes": self.exit_codes(), "timeout": timeout}
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
