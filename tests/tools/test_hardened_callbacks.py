"""Tools' zenoh callbacks and readers survive any input, count it and go on (every input
hardened)."""

from __future__ import annotations

import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from agent.net.bus import Event
from agent.wire import (
    MAX_PUBLICATION_BYTES,
    CameraReply,
    CameraRequest,
    NetworkSpec,
    StatusMsg,
    TruthPosesMsg,
    encode,
    key_camera,
)
from tests.fakes import FakeZBytes, zb


def test_demo_observer_counts_what_it_cannot_take(capsys: pytest.CaptureFixture[str]) -> None:
    from tools.harness.observe import Observer

    class BrokenRecorder:
        def record(self, *a: Any) -> None:
            raise OSError("x" * 10_000)

    obs = Observer(0.0)
    status = StatusMsg(sender=1, phase="hold")
    obs.take_event(Event("msg", "nao/1/status", status), BrokenRecorder())  # type: ignore[arg-type]
    obs.take_event(Event("alive", "nao/alive/1", robot_id=1), None)
    obs.take_event(Event("msg", "nao/1/status", status), None)
    assert obs.rejected == 1 and obs.agents[1].phase == "hold"
    err = capsys.readouterr().err
    assert "OSError" in err and len(err) < 400


def test_replay_counts_undecodable_messages(tmp_path: Path) -> None:
    from tools.harness.observe import Recorder
    from tools.replay import load

    rec = Recorder(tmp_path / "r.mcap")
    rec.write("nao/1/status", b"\xc1" * 100)
    rec.write("nao/1/status", b"\x91" * 100 + b"\x90")
    rec.write("nao/1/status", encode(StatusMsg(sender=1, phase="hold")))
    rec.close()
    rp = load(tmp_path / "r.mcap")
    assert rp.messages == 3 and rp.rejected == 2
    assert all(len(text) < 300 for _, text in rp.events)


class FakeSession:
    """Records the subscriber callback; ``get`` returns canned replies."""

    def __init__(self, replies: list[Any] | None = None) -> None:
        self.callback: Any = None
        self.replies = replies or []

    def declare_subscriber(self, key: str, cb: Any) -> Any:
        self.callback = cb
        return SimpleNamespace(undeclare=lambda: None)

    def get(self, key: str, **kw: Any) -> list[Any]:
        return self.replies


def test_sim_client_truth_survives_bad_samples() -> None:
    from sim.server import client

    good = TruthPosesMsg(t_sim=2.0, poses=((1, 0.0, 0.0, 0.0),))
    session = FakeSession()
    before = client.GUARD.rejected

    def feed() -> Any:
        cb = session.callback
        cb(SimpleNamespace(payload=FakeZBytes(MAX_PUBLICATION_BYTES + 1)))  # not copied
        cb(SimpleNamespace(payload=zb(b"\xc1")))
        cb(object())
        cb(SimpleNamespace(payload=zb(encode(good))))

    # the subscriber is declared inside truth(); feed it from a timer thread
    import threading

    t = threading.Timer(0.05, feed)
    t.start()
    assert client.truth(client.Link(session, NetworkSpec()), timeout=10.0) == good
    t.join()
    assert client.GUARD.rejected - before == 3  # b"\xc1" is refused when read, and counted


def test_sim_client_ask_skips_bad_replies() -> None:
    from sim.server import client

    rep = CameraReply(robot_id=3, yaw=0.0, t_sim=0.0, width=1, height=1, encoding="png", data=b"x")
    replies = [
        SimpleNamespace(ok=None),
        SimpleNamespace(ok=SimpleNamespace(payload=zb(b"\xc1"))),
        SimpleNamespace(ok=SimpleNamespace(payload=FakeZBytes(10**9))),
        SimpleNamespace(ok=SimpleNamespace(payload=zb(encode(rep)))),
    ]
    before = client.GUARD.rejected
    link = client.Link(FakeSession(replies), NetworkSpec())
    got = client.ask(link, key_camera(3), CameraRequest(yaw=0.0), 1.0)
    assert got == rep and client.GUARD.rejected - before == 2


def test_the_observer_dates_a_phase_by_its_arrival_not_its_turn_in_the_queue() -> None:
    """The observer's phase times are arrival times; a status that waited in
    its queue (behind the recording of others) keeps the time it arrived."""
    from tools.harness.observe import Observer

    obs = Observer(100.0)
    ev = Event("msg", "nao/1/status", StatusMsg(sender=1, phase="plan"), t_rx=105.5)
    obs.take_event(ev, None)
    assert obs.agents[1].phase_wall["plan"] == 5.5
    late = Event("msg", "nao/2/status", StatusMsg(sender=2, phase="plan"))  # no stamp: now
    before = time.monotonic()
    obs.take_event(late, None)
    assert before - 100.0 <= obs.agents[2].phase_wall["plan"] <= time.monotonic() - 100.0
