"""``python -m tools.bench idle --agents N --seconds S``: what an idle agent costs its host.

An agent that waits for the fleet (agreement, waves, hold, done) should cost next to
nothing (docs/design.md §1, §8: every wait hears the fleet). This benchmark starts N
real agent processes (``python -m agent.idle``: the real phase machine on a real zenoh
session; insecure, peers over loopback TCP meeting at this process's listener, no
multicast) that have nothing to do but wait:

* each agent enters the phase machine at the agreement (``Runner.phases("agree", ...)``)
  with an empty record of its own, as a robot does once its search is over;
* the fleet size they are given is N + 1: the last member never comes, so the agreement
  can never complete, and every agent waits in it, exchanging records, digests and
  statuses with the N - 1 others, as the 77 robots of a 100-NAO run waited for the 23
  still searching. The agreement timeout is set beyond the run, so nobody gives up.

No world is started: the agents never look or move (the body only answers its id and
sim time; the perception is never called), so the CPU measured is the waiting alone:
the bus traffic, the wake-ups of the main thread and zenoh's own threads.

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
import time
from pathlib import Path
from typing import TYPE_CHECKING

from tools.harness.procs import ROOT, free_port

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


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    p = argparse.ArgumentParser(prog="python -m tools.bench idle", description=__doc__)
    p.add_argument("--agents", type=int, default=10, help="agent processes (default 10)")
    p.add_argument("--seconds", type=float, default=30.0, help="sampling window (s)")
    p.add_argument("--settle", type=float, default=10.0, help="s after all wait, then sample")
    p.add_argument(
        "--start-timeout", type=float, default=300.0, help="s for all agents to start waiting"
    )
    p.add_argument("--out", type=Path, default=Path("out/bench_idle.png"), help="PNG")
    a = p.parse_args(args)
    if a.agents < 2 or a.seconds <= 0:
        p.error("need --agents >= 2 and --seconds > 0")
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    from agent.net.bus import Bus, BusConfig
    from agent.wire import KEY_STATUS_ALL

    # the meeting point (as the world is in a demo): it listens, the agents connect and
    # find each other through it; it hears their statuses to know when all of them wait
    bus = Bus(BusConfig(listen=(endpoint,), multicast_scouting=False))
    bus.subscribe(KEY_STATUS_ALL)

    def command(i: int) -> list[str]:
        return [sys.executable, "-m", "agent.idle", "--id", str(i),
                "--fleet-size", str(a.agents + 1), "--connect", endpoint]  # fmt: skip

    procs = [
        subprocess.Popen(
            command(i), cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        for i in range(a.agents)
    ]
    try:
        return measure(a, procs, bus)
    finally:
        bus.close()
        for proc in procs:
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(10.0)
            except subprocess.TimeoutExpired:
                proc.kill()


def measure(a: argparse.Namespace, procs: list[subprocess.Popen[bytes]], bus: Bus) -> int:
    """Wait for the agents to settle, sample their CPU, print and draw (module docstring)."""
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
    w0 = time.monotonic()
    time.sleep(a.seconds)
    wall = time.monotonic() - w0
    end = {pr.pid: (cpu_seconds(pr.pid), cpu_seconds(pr.pid, pr.pid)) for pr in procs}
    t_end = {pr.pid: threads(pr.pid) for pr in procs}
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
    mean = sum(pct) / len(pct)
    print(
        f"idle agent: {mean:.3f} % of a core (mean), {max(pct):.3f} % (max) over {wall:.0f} s; "
        f"main thread {sum(main_pct) / len(main_pct):.3f} %; {a.agents} agents, "
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
    print(f"statuses heard: {60.0 * heard / wall / len(procs):.1f} per agent per minute")
    draw(a.out, pct, main_pct, mean, load1[0], wall)
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
         wall: float) -> None:  # fmt: skip
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
    ax.set_title(f"idle agents waiting in the agreement, {wall:.0f} s; load average {load:.1f}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    print(f"wrote {out}")


if __name__ == "__main__":
    raise SystemExit(main())
