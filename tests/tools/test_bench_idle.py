"""tools/bench/idle.py: the scheduler's per-thread counts, the waiting agents' flags
(those of ``python -m agent``, agent/idle.py), and a run of each deployment."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import pytest

from agent import idle
from agent.__main__ import agent_config, parse_args
from agent.wire import CREDENTIALS_ENV, network_spec
from tools.bench.idle import DEPLOYMENTS, NEVER, agent_commands, main, spent, threads
from tools.harness.procs import fleet_network


def test_threads_reads_each_threads_cpu_time_and_wake_ups_of_a_live_process() -> None:
    stop = threading.Event()
    sleeper = threading.Thread(target=lambda: [stop.wait(0.01) for _ in range(20)])
    before = threads(os.getpid())
    sleeper.start()
    end = time.thread_time() + 0.05
    while time.thread_time() < end:  # the main thread works 50 ms
        pass
    sleeper.join()
    after = threads(os.getpid())
    used = spent(before, after)
    cpu, slices = used[os.getpid()]
    assert 0.04 <= cpu < 5.0 and slices >= 1
    assert after[os.getpid()][0]  # a name
    assert all(c >= 0.0 and n >= 0 for c, n in used.values())


def test_spent_counts_a_thread_born_meanwhile_from_zero() -> None:
    t0 = {1: ("main", 2.0, 10)}
    t1 = {1: ("main", 2.5, 14), 7: ("rx-0", 0.1, 3)}
    assert spent(t0, t1) == {1: (0.5, 4), 7: (0.1, 3)}


def test_each_waiting_agent_gets_the_flags_of_python_m_agent_secure_by_default(
    tmp_path: Path,
) -> None:
    net = fleet_network(tmp_path, 3, [1, 2, 3])
    cmds = agent_commands(3, ["--connect", net.endpoint, *net.flags], [1, 2, 3])
    for rid, cmd in zip([1, 2, 3], cmds, strict=True):
        assert cmd[1:3] == ["-m", "agent.idle"]
        args = parse_args(cmd[3:])  # the parser of python -m agent
        cfg = agent_config(args, rid)
        assert (cfg.robot_id, cfg.fleet_size, cfg.timeout) == (rid, 4, NEVER)
        spec = network_spec(args, f"robot-{rid}")
        assert spec.secure and spec.tls and spec.mode == "client"
        assert spec.connect == (net.endpoint,) and net.endpoint.startswith("tls/")


def test_a_waiting_agent_without_a_fleet_size_is_a_usage_error() -> None:
    assert idle.main(["--id", "1", "--insecure", "--no-multicast-scouting"]) == 2


def test_a_waiting_agent_without_credentials_is_a_usage_error(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv(CREDENTIALS_ENV, raising=False)
    assert idle.main(["--id", "1", "--fleet-size", "3"]) == 2
    assert "no fleet credentials" in capsys.readouterr().err


@pytest.mark.slow  # starts a router and agents (~15 s)
@pytest.mark.parametrize("deployment", DEPLOYMENTS)
def test_the_bench_measures_each_deployment(
    deployment: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["--agents", "2", "--seconds", "1", "--settle", "0", "--start-timeout", "120",
            "--deployment", deployment, "--out", str(tmp_path / "idle.png")]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert f"idle agent ({deployment}):" in out and (tmp_path / "idle.png").exists()
    assert ("the router (one for the fleet)" in out) == (deployment == "secure")
