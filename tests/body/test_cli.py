"""``python -m agent`` selects its body: ``--body zenoh|naoqi`` and ``--nao URL`` (issue #11)."""

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
