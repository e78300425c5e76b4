"""``python -m tools.bench idle --agents N --seconds S [--deployment secure|mesh]``: what an
idle agent costs its host.

An agent that waits for the fleet (agreement, waves, hold, done) should cost next to
nothing (docs/design.md §1, §8: every wait hears the fleet). This benchmark starts N
real agent processes (``python -m agent.idle``: the real phase machine on a real zenoh
session, given the flags of ``python -m agent``) that have nothing to do but wait, in
one of two deployments:

* ``secure`` (the default: the deployment users run, ``tools.demo``, ``docker compose``,
  ``python -m agent`` on hosts): a throwaway fleet's credentials made as the harness
  makes them (:func:`tools.harness.procs.fleet_network`), the real TLS router
  (``python -m tools.router --credentials DIR``, :func:`~tools.harness.procs.start_router`)
  on a loopback port, every agent a zenoh client of it over mutual TLS, every message
  signed and every signature checked (docs/design.md §8). The router's own CPU is
  printed apart: it is one process for the whole fleet, not a cost of each agent.
* ``mesh``: insecure zenoh peers over loopback TCP meeting at this process's listener
  (no multicast) and finding each other into a full mesh (N - 1 links each).

In both:

* each agent enters the phase machine at the agreement (``Runner.phases("agree", ...)``)
  with an empty record of its own, as a robot does once its search is over;
* the fleet size they are given is N + 1: the last member never comes, so the agreement
  can never complete, and every agent waits in it, exchanging records, digests and
  statuses with the N - 1 others, as the 77 robots of a 100-NAO run waited for the 23
  still searching. The agreement timeout is set beyond the run, so nobody gives up.

No world is started: the agents never look or move (the body only answers its id and
sim time; the perception is never called), so the CPU measured is the waiting alone:
the bus traffic, the signatures, the wake-ups of the main thread and zenoh's own threads.

Once every agent has published a status of the agreement (``exchange`` or ``agree``)
and ``--settle`` seconds more have passed, each thread's CPU time and wake-ups are
sampled over ``--seconds`` s: the scheduler's own nanosecond count of the time it ran
and the number of times it was put on a core (``/proc/PID/task/TID/schedstat``; the
tick-sampled user + system time of ``/proc/PID/stat`` is printed beside it, its 10 ms
tick is coarse next to a 0.1 % target). Prints per agent % of one core (mean, max, the
main thread's share), by thread name with wake-ups per second, beside the load average
(the machine may be shared: the CPU seconds of a process are its own, but a loaded host
delays its wake-ups), and draws a PNG (``--out``).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

from tools.harness.procs import ROOT, Proc, fleet_network, free_port, start_router, stop

if TYPE_CHECKING:
    from agent.net.bus import Bus

#: Clock ticks per second of /proc's CPU times.
TICKS = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int, tid: int | None = None) -> float:
    """User + system CPU seconds of process ``pid`` (all threads), or of its thread ``tid``."""
    path = f"/proc/{pid}/stat" if tid is None else f"/proc/{pid}/task/{tid}/stat"
    with open(path) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS  # utime, stime (fields 14, 15)


def threads(pid: int) -> dict[int, tuple[str, float, int]]:
    """Thread id -> (name, CPU seconds, times put on a core) of every thread of ``pid``,
    from the scheduler's ``schedstat`` (nanoseconds run, time waited, slices run)."""
    out: dict[int, tuple[str, float, int]] = {}
    for tid in sorted(int(t) for t in os.listdir(f"/proc/{pid}/task")):
        try:
            with open(f"/proc/{pid}/task/{tid}/comm") as f:
                name = f.read().strip()
            with open(f"/proc/{pid}/task/{tid}/schedstat") as f:
                ran_ns, _, slices = (int(x) for x in f.read().split())
            out[tid] = (name, ran_ns / 1e9, slices)
        except OSError:  # the thread ended meanwhile
            continue
    return out


def wait_settled(bus: Bus, n: int, timeout: float) -> bool:
    """Whether all ``n`` agents published a status of the agreement within ``timeout`` s
    (heard on ``bus``, the session the agents connect to)."""
    from agent.wire import StatusMsg

    waiting: set[int] = set()
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for ev in bus.drain(0.5):
            if isinstance(ev.msg, StatusMsg) and ev.msg.phase in ("exchange", "agree"):
                waiting.add(ev.msg.sender)
        if len(waiting) >= n:
            return True
    return False


#: Agreement timeout of a waiting agent (s): beyond any benchmark.
NEVER = 1e6
DEPLOYMENTS = ("secure", "mesh")


def agent_commands(n: int, joins: list[str], ids: list[int]) -> list[list[str]]:
    """The argv of each waiting agent (``python -m agent.idle`` with the flags of
    ``python -m agent``: :meth:`AgentConfig.to_argv` and the join flags ``joins``),
    robots ``ids`` of a fleet of ``n`` + 1 whose last member never comes."""
    from agent.config import AgentConfig

    return [
        [sys.executable, "-m", "agent.idle",
         *AgentConfig(robot_id=i, fleet_size=n + 1, timeout=NEVER).to_argv(), *joins]
        for i in ids
    ]  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    p = argparse.ArgumentParser(
        prog="python -m tools.bench idle",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--agents", type=int, default=10, help="agent processes (default 10)")
    p.add_argument("--seconds", type=float, default=30.0, help="sampling window (s)")
    p.add_argument("--settle", type=float, default=10.0, help="s after all wait, then sample")
    p.add_argument(
        "--deployment",
        choices=DEPLOYMENTS,
        default="secure",
        help="secure: clients of a TLS router, signed messages (what users run; default); "
        "mesh: insecure peers in a full mesh",
    )
    p.add_argument(
        "--start-timeout", type=float, default=300.0, help="s for all agents to start waiting"
    )
    p.add_argument("--out", type=Path, default=Path("out/bench_idle.png"), help="PNG")
    a = p.parse_args(args)
    if a.agents < 2 or a.seconds <= 0:
        p.error("need --agents >= 2 and --seconds > 0")
    with tempfile.TemporaryDirectory(prefix="bench_idle_") as tmp:
        return run(a, Path(tmp))


def run(a: argparse.Namespace, tmp: Path) -> int:
    """Start the deployment (its credentials and router log in ``tmp``), the agents, and
    :func:`measure` them."""
    from agent.net.bus import Bus, BusConfig
    from agent.wire import KEY_STATUS_ALL

    ids = list(range(1, a.agents + 1))
    router: Proc | None = None
    if a.deployment == "secure":
        net = fleet_network(tmp, a.agents, ids)  # a throwaway fleet CA and keys in tmp/fleet
        router = start_router(net.endpoint, tmp, net.flags)
        joins = ["--connect", net.endpoint, *net.flags]
        config = net.observer()  # the fleet's observer: hears the statuses through the router
    else:  # the meeting point (as the world is in an insecure demo): it listens, the agents
        endpoint = f"tcp/127.0.0.1:{free_port()}"  # connect and find each other through it
        joins = ["--connect", endpoint, "--no-multicast-scouting", "--insecure"]
        config = BusConfig(listen=(endpoint,), multicast_scouting=False)
    procs: list[subprocess.Popen[bytes]] = []
    try:
        bus = Bus(config)  # hears the agents' statuses to know when all of them wait
        try:
            bus.subscribe(KEY_STATUS_ALL)
            for cmd in agent_commands(a.agents, joins, ids):
                out = subprocess.DEVNULL
                procs.append(subprocess.Popen(cmd, cwd=ROOT, stdout=out, stderr=out))
            return measure(a, procs, bus, router)
        finally:
            bus.close()
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(10.0)
            except subprocess.TimeoutExpired:
                proc.kill()
        if router is not None:
            stop(router)


def measure(
    a: argparse.Namespace, procs: list[subprocess.Popen[bytes]], bus: Bus, router: Proc | None
) -> int:
    """Wait for the agents to settle, sample their CPU (and the ``router``'s), print and
    draw (module docstring)."""
    t0 = time.monotonic()
    if not wait_settled(bus, a.agents, a.start_timeout):
        print(
            f"the agents did not all reach the agreement within {a.start_timeout:g} s",
            file=sys.stderr,
        )
        return 1
    print(f"{a.agents} agents waiting in the agreement after {time.monotonic() - t0:.0f} s")
    time.sleep(a.settle)
    bus.drain()
    load0 = os.getloadavg()
    start = {pr.pid: (cpu_seconds(pr.pid), cpu_seconds(pr.pid, pr.pid)) for pr in procs}
    t_start = {pr.pid: threads(pr.pid) for pr in procs}
    r_start = threads(router.popen.pid) if router is not None else {}
    w0 = time.monotonic()
    time.sleep(a.seconds)
    wall = time.monotonic() - w0
    end = {pr.pid: (cpu_seconds(pr.pid), cpu_seconds(pr.pid, pr.pid)) for pr in procs}
    t_end = {pr.pid: threads(pr.pid) for pr in procs}
    r_end = threads(router.popen.pid) if router is not None else {}
    load1 = os.getloadavg()
    heard = len(bus.drain())  # the agents' statuses during the window
    if any(pr.poll() is not None for pr in procs):
        print("an agent exited during the sampling window", file=sys.stderr)
        return 1
    pids = sorted(start)
    ran = {pid: spent(t_start[pid], t_end[pid]) for pid in pids}
    pct = [100.0 * sum(c for c, _ in ran[pid].values()) / wall for pid in pids]
    main_pct = [100.0 * ran[pid].get(pid, (0.0, 0))[0] / wall for pid in pids]
    ticked = [100.0 * (end[pid][0] - start[pid][0]) / wall for pid in pids]
    wakes = [sum(n for _, n in ran[pid].values()) / wall for pid in pids]
    mean = sum(pct) / len(pct)
    print(
        f"idle agent ({a.deployment}): {mean:.3f} % of a core (mean), {max(pct):.3f} % (max) "
        f"over {wall:.0f} s; main thread {sum(main_pct) / len(main_pct):.3f} %; "
        f"{sum(wakes) / len(wakes):.1f} wake-ups/s; {a.agents} agents, "
        f"{sum(pct):.2f} % of a core together"
    )
    print(
        f"load average: {load0[0]:.2f} at the start, {load1[0]:.2f} at the end "
        f"({os.cpu_count()} cores); tick-sampled user + system time "
        f"{sum(ticked) / len(ticked):.2f} % (mean; {1000 / TICKS:.0f} ms tick, "
        f"resolution {100.0 / TICKS / wall:.3f} % over the window)"
    )
    by_name: dict[str, tuple[float, float]] = {}
    for pid in pids:
        for tid, (cpu, slices) in ran[pid].items():
            key = "main (Python)" if tid == pid else t_end[pid][tid][0]
            old_pct, old_wakes = by_name.get(key, (0.0, 0.0))
            by_name[key] = (
                old_pct + 100.0 * cpu / wall / len(pids),
                old_wakes + slices / wall / len(pids),
            )
    top = sorted(by_name.items(), key=lambda kv: (-kv[1][0], kv[0]))[:7]
    print(
        "per agent, by thread (% of a core, wake-ups a second): "
        + ", ".join(f"{n} {v:.3f} % {w:.1f}/s" for n, (v, w) in top)
    )
    if router is not None:
        r_ran = spent(r_start, r_end)
        r_cpu = 100.0 * sum(c for c, _ in r_ran.values()) / wall
        r_wakes = sum(n for _, n in r_ran.values()) / wall
        print(
            f"the router (one for the fleet): {r_cpu:.3f} % of a core, {r_wakes:.1f} wake-ups/s "
            f"({r_cpu / len(pids):.3f} % per agent)"
        )
    print(f"statuses heard: {60.0 * heard / wall / len(procs):.1f} per agent per minute")
    draw(a.out, pct, main_pct, mean, load1[0], wall, a.deployment)
    return 0


def spent(
    t0: dict[int, tuple[str, float, int]], t1: dict[int, tuple[str, float, int]]
) -> dict[int, tuple[float, int]]:
    """Thread id -> (CPU seconds, times put on a core) between two :func:`threads`
    samples of one process (a thread born meanwhile counts from zero)."""
    out: dict[int, tuple[float, int]] = {}
    for tid, (name, cpu, slices) in t1.items():
        _, cpu0, slices0 = t0.get(tid, (name, 0.0, 0))
        out[tid] = (cpu - cpu0, slices - slices0)
    return out


def draw(out: Path, pct: list[float], main_pct: list[float], mean: float, load: float,
         wall: float, deployment: str) -> None:  # fmt: skip
    """Bars: each agent's % of a core (all threads, and its main thread)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    ids = list(range(len(pct)))
    ax.bar(ids, pct, color="tab:blue", label="process (all threads)")
    ax.bar(ids, main_pct, color="tab:orange", width=0.5, label="main thread")
    ax.axhline(mean, color="k", lw=1, ls="--", label=f"mean {mean:.2f} %")
    ax.axhline(0.1, color="tab:green", lw=1, ls=":", label="target 0.1 %")
    ax.set_xlabel("agent")
    ax.set_ylabel("% of one core")
    ax.set_title(
        f"idle agents ({deployment}) waiting in the agreement, {wall:.0f} s; "
        f"load average {load:.1f}"
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    print(f"wrote {out}")


if __name__ == "__main__":
    raise SystemExit(main())
