"""``python -m agent`` selects its body: ``--body zenoh|naoqi`` and ``--nao URL`` (a real NAO)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from agent.__main__ import parse_args

ROOT = Path(__file__).resolve().parents[2]


def test_help_shows_body_and_nao() -> None:
    res = subprocess.run(
        [sys.executable, "-m", "agent", "--help"],
        cwd=ROOT, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert res.returncode == 0
    assert "--body {zenoh,naoqi}" in res.stdout and "--nao URL" in res.stdout
    assert "tcp://nao.local:9559" in res.stdout


def test_body_defaults_to_the_zenoh_world() -> None:
    a = parse_args(["--id", "2"])
    assert a.body == "zenoh" and a.nao is None


def test_exit_record_names_the_file_a_supervisor_files_the_exit_under() -> None:
    assert parse_args(["--id", "2"]).exit_record is None
    assert parse_args(["--id", "auto", "--exit-record", "/exits/c.jsonl"]).exit_record == (
        "/exits/c.jsonl"
    )


def test_planning_parameters_default_and_choices(capsys: pytest.CaptureFixture[str]) -> None:
    a = parse_args(["--id", "2"])
    assert (a.orientation, a.strategy) == ("pca", "default")
    a = parse_args(["--id", "2", "--orientation", "cp", "--strategy", "paper"])
    assert (a.orientation, a.strategy) == ("cp", "paper")
    for bad in (["--orientation", "south"], ["--strategy", "fastest"]):
        with pytest.raises(SystemExit) as exc:
            parse_args(["--id", "2", *bad])
        assert exc.value.code == 2 and "invalid choice" in capsys.readouterr().err


def test_naoqi_body_takes_the_robot_url() -> None:
    a = parse_args(["--id", "2", "--body", "naoqi", "--nao", "tcp://10.0.0.12:9559"])
    assert a.body == "naoqi" and a.nao == "tcp://10.0.0.12:9559"


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--id", "2", "--body", "naoqi"], "needs --nao"),
        (["--id", "auto", "--body", "naoqi", "--nao", "tcp://h:9559"], "fixed --id"),
        (["--id", "2", "--body", "naoqi", "--nao", "nao.local"], "not a URL"),
        (["--id", "2", "--nao", "tcp://h:9559"], "needs --body naoqi"),
        (["--id", "2", "--research-rounds", "11"], "--research-rounds must be"),
        (["--id", "2", "--explore-step", "0.1"], "--explore-step must be"),
        (["--id", "2", "--join-timeout", "-1"], "--join-timeout must be >= 0"),
    ],
)
def test_body_usage_errors(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        parse_args(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_an_unreachable_nao_is_a_safe_stop_with_the_reason(tmp_path: Path) -> None:
    """The agent joins the bus, publishes ``failed`` with the reason, and exits 1."""
    res = subprocess.run(
        [sys.executable, "-m", "agent", "--id", "4", "--body", "naoqi",
         "--nao", "tcp://127.0.0.1:9", "--no-multicast-scouting", "--insecure"],
        cwd=ROOT, capture_output=True, text=True, timeout=90,
    )  # fmt: skip
    assert res.returncode == 1, res.stderr[-2000:]
    assert "no NAOqi at tcp://127.0.0.1:9" in res.stderr
    assert "terminate called" not in res.stderr


def test_world_connect_opens_a_second_session_for_the_body() -> None:
    import logging

    from agent.__main__ import open_bus

    args = parse_args(
        ["--id", "2", "--insecure", "--no-multicast-scouting", "--mode", "peer",
         "--connect", "tcp/127.0.0.1:9", "--world-connect", "tcp/127.0.0.1:10"]
    )  # fmt: skip
    bus, world, rid = open_bus(args, logging.getLogger("test"))
    try:
        assert rid == 2 and world is not bus
        assert bus.config.connect == ("tcp/127.0.0.1:9",)
        assert world.config.connect == ("tcp/127.0.0.1:10",) and world.config.listen == ()
    finally:
        world.close()
        bus.close()
    one = parse_args(["--id", "3", "--insecure", "--no-multicast-scouting", "--mode", "peer"])
    bus, world, rid = open_bus(one, logging.getLogger("test"))
    with bus:
        assert world is bus and rid == 3  # without --world-connect: one session for both
