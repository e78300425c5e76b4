"""tools/fleet.py (credentials on the command line) and tools/rogue.py's building blocks."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import msgpack
import pytest

from agent import wire as P
from agent.wire import trust as T
from tools import fleet, rogue


def test_init_show_export(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "fleet"
    assert fleet.main(["init", "--ids", "2,5", "--host", "10.77.0.1", "--out", str(root)]) == 0
    assert "robots [2, 5]" in capsys.readouterr().out
    assert fleet.main(["show", str(root)]) == 0
    shown = capsys.readouterr().out
    assert "robot-5" in shown and "key here" in shown
    host = tmp_path / "robot-5"
    assert fleet.main(["export", str(root), "--identity", "robot-5", "--out", str(host)]) == 0
    creds = T.Credentials(host)
    assert creds.robots() == [2, 5]  # the whole roster travels: it is public
    assert creds.own_robot_keys() == [5]  # and exactly one private key
    assert not (host / "ca-private").exists()
    assert creds.signer(T.Identity.robot(5)).who.cn == "robot-5"


@pytest.mark.parametrize(
    ("argv", "reason"),
    [
        (["init", "--out", "X"], "--robots N"),
        (["init", "--ids", "a,b", "--out", "X"], "expected integers"),
        (["init", "--robots", "2", "--days", "0", "--out", "X"], "valid_days"),
        (["show", "NOPE"], "untrusted: no fleet CA"),
        (["export", "F", "--identity", "king", "--out", "Y"], "names no fleet identity"),
        (["export", "F", "--identity", "robot-9", "--out", "Y"], "no private key for robot-9"),
    ],
)
def test_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], reason: str
) -> None:
    T.create_fleet(tmp_path / "F", [1])
    argv = [str(tmp_path / a) if a in ("X", "Y", "F", "NOPE") else a for a in argv]
    assert fleet.main(argv) == 2
    assert reason in capsys.readouterr().err


def test_export_refuses_a_folder_with_credentials(tmp_path: Path) -> None:
    T.create_fleet(tmp_path / "F", [1])
    with pytest.raises(ValueError, match="already holds"):
        fleet.export(tmp_path / "F", T.Identity.robot(1), tmp_path / "F")


def test_rogue_forgeries_are_well_formed_messages_of_the_victim() -> None:
    msgs = rogue.forged_messages(2)
    assert [k for k, _ in msgs] == ["nao/2/record", "nao/2/digest", "nao/2/status"]
    for _, data in msgs:
        assert P.decode(data).sender == 2  # the codec alone cannot tell them from real ones
    env = msgpack.unpackb(rogue.garbage_envelope("nao/2/record", b"x", "robot-2"), raw=False)
    assert env[1] == 2 and len(env[6]) == 64  # robot 2's code, a signature nobody made


def test_rogue_classifies_replies() -> None:
    def reply(msg: P.Message) -> SimpleNamespace:
        payload = SimpleNamespace(to_bytes=lambda: P.encode(msg))
        return SimpleNamespace(ok=SimpleNamespace(payload=payload))

    done = P.CommandReply(robot_id=2, status="done", t_sim=1.0)
    fake = P.CommandReply(robot_id=2, status="done", t_sim=0.0, detail=rogue.FAKE)
    assert rogue.classify(reply(done)) == "executed"
    assert rogue.classify(reply(fake)) == "own fake reply"
    assert rogue.classify(reply(P.ErrorReply(reason="no"))) == "ErrorReply"
    assert rogue.classify(SimpleNamespace(ok=None)) == "error reply"
