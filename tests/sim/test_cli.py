"""``python -m sim`` argument errors (exit 2 with a reason, before any zenoh session)."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim import scenarios
from sim.__main__ import build_parser, main
from sim.camera.look import Look


@pytest.mark.parametrize(
    ("argv", "reason"),
    [
        (["--robots", "0"], "robot count"),
        (["--speed", "-1"], "--speed"),
        (["--speed", "nan"], "--speed"),
        (["--truth-rate", "0"], "--truth-rate"),
        (["--render-workers", "17"], "render workers"),
        (["--render-workers", "-1"], "render workers"),
        (["--light", "9"], "light intensity"),
        (["--noise-scale", "-1"], "noise scale"),
        (["--noise-scale", "nan"], "noise scale"),
        (["--listen", "nonsense"], "endpoint"),
        (["--scenario", "/nonexistent.json"], "No such file"),
        (["--look", "sunny"], "neither KEY:VALUE nor a preset"),
        (["--look", "noise:-3"], "outside [0, 64]"),
    ],
)
def test_bad_arguments(argv: list[str], reason: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*argv, "--insecure"]) == 2
    assert reason in capsys.readouterr().err


def test_no_credentials_is_a_usage_error(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("NAO_CREDENTIALS", raising=False)
    assert main(["--robots", "1"]) == 2
    assert "no fleet credentials" in capsys.readouterr().err


def test_dump_scenario(tmp_path: Path) -> None:
    # A bad endpoint stops the world after the scenario was written.
    out = tmp_path / "sc.json"
    assert (
        main(
            [
                "--robots",
                "4",
                "--seed",
                "2",
                "--dump-scenario",
                str(out),
                "--listen",
                "x",
                "--insecure",
            ]
        )
        == 2
    )
    assert out.exists()


def test_dump_isolated_scenario(tmp_path: Path) -> None:
    out = tmp_path / "sc.json"
    argv = ["--robots", "4", "--seed", "2", "--isolated", "--dump-scenario", str(out)]
    assert main([*argv, "--listen", "x", "--insecure"]) == 2  # stops after writing it
    assert scenarios.load(out) == scenarios.generate(4, 2, isolated=True)


def test_a_look_goes_into_the_scenario(tmp_path: Path) -> None:
    out = tmp_path / "sc.json"
    argv = [
        "--robots",
        "2",
        "--seed",
        "2",
        "--look",
        "dim-warm,hue:30",
        "--dump-scenario",
        str(out),
    ]
    assert main([*argv, "--listen", "x", "--insecure"]) == 2  # stops after writing it
    assert str(scenarios.load(out).look) == str(Look.parse("dim-warm,hue:30"))
    again = tmp_path / "again.json"  # a file's look, replaced by --look
    argv = ["--scenario", str(out), "--look", "default", "--dump-scenario", str(again)]
    assert main([*argv, "--listen", "x", "--insecure"]) == 2
    assert scenarios.load(again).look.is_default()


def test_help_documents_the_stable_flags() -> None:
    text = build_parser().format_help()
    for flag in ("--robots", "--seed", "--scenario", "--connect", "--listen",
                 "--no-multicast-scouting", "--mode", "--gui", "--speed", "--noise-scale",
                 "--look", "--free-looks"):  # fmt: skip
        assert flag in text


def test_gui_without_a_display(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    assert main(["--robots", "1", "--gui", "--insecure"]) == 2
    assert "DISPLAY" in capsys.readouterr().err
