"""agent/net/bus.py with real zenoh sessions on loopback (tcp, no multicast)."""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Iterator
from dataclasses import replace
from types import SimpleNamespace
from typing import Any

import msgpack
import pytest
import zenoh

import agent.net.bus as bus_module
from agent.net.bus import (
    EVENT_CAPS,
    EVENT_MAX_BYTES,
    Bus,
    BusConfig,
    BusError,
    Busy,
    Event,
    NoRoute,
    QueryTimeout,
    SessionUnavailable,
    open_retrying,
)
from agent.net.replies import MAX_REPLIES, ReplyInbox
from agent.wire import (
    BUSY,
    MAX_MESSAGE_BYTES,
    MAX_PUBLICATION_BYTES,
    ClockMsg,
    CommandReply,
    DigestMsg,
    ErrorReply,
    NeighborRecordMsg,
    StatusMsg,
    WalkRequest,
    decode,
    encode,
    key_status,
    key_walk,
)
from tests.fakes import FakeZBytes, zb
from tools.harness.procs import free_port

pytestmark = pytest.mark.system


@pytest.fixture()
def pair() -> Iterator[tuple[Bus, Bus, str]]:
    ep = f"tcp/127.0.0.1:{free_port()}"
    a = Bus(BusConfig(listen=(ep,), multicast_scouting=False))
    b = Bus(BusConfig(connect=(ep,), multicast_scouting=False))
    try:
        yield a, b, ep
    finally:
        b.close()
        a.close()


#: zenoh's default link lease: a peer that left without a word is dropped after it.
LEASE_S = 10.0


def wait_for(bus: Bus, pred: object, deadline: float = 10.0) -> list[Event]:
    got: list[Event] = []
    end = time.monotonic() + deadline
    while time.monotonic() < end:
        got += bus.drain(0.1)
        if pred(got):  # type: ignore[operator]
            return got
    raise AssertionError(f"condition not met in {deadline} s; got {got}")


def test_publish_subscribe_round_trip_counts_bytes(pair: tuple[Bus, Bus, str]) -> None:
    a, b, _ = pair
    b.subscribe("nao/*/status")
    msg = StatusMsg(sender=4, phase="search", progress=0.5)
    end = time.monotonic() + 10
    got: list[Event] = []
    while time.monotonic() < end and not got:
        n = a.publish(key_status(4), msg)  # re-publish until the route exists
        got = [e for e in b.drain(0.2) if e.kind == "msg"]
    assert got and got[0].msg == msg and got[0].key == "nao/4/status"
    assert n == len(encode(msg))
    assert a.stats.published_bytes["status"] >= n
    assert a.stats.total_published == a.stats.published_bytes["status"]


def test_a_remote_only_subscription_hears_others_but_not_its_own_session(
    pair: tuple[Bus, Bus, str],
) -> None:
    a, b, _ = pair
    b.subscribe("nao/*/status", remote_only=True)
    a.subscribe("nao/*/status")  # a hears everything: its own too
    end = time.monotonic() + 10
    got: list[Event] = []
    while time.monotonic() < end and not got:
        a.publish(key_status(4), StatusMsg(sender=4, phase="search"))
        b.publish(key_status(5), StatusMsg(sender=5, phase="agree"))
        got = [e for e in b.drain(0.2) if e.kind == "msg"]
    assert got and {e.msg.sender for e in got} == {4}  # b's own status 5 never came back
    time.sleep(0.3)
    assert {e.msg.sender for e in b.drain() if e.kind == "msg"} <= {4}
    assert 4 in {e.msg.sender for e in a.drain() if e.kind == "msg"}  # its own, delivered


def test_malformed_payload_is_rejected_and_the_bus_goes_on(pair: tuple[Bus, Bus, str]) -> None:
    # The garbage may go out before the route exists and be lost: keep sending all three
    # until both the good message and the rejections have been seen (deadline, no sleep).
    a, b, _ = pair
    b.subscribe("nao/**")
    good = StatusMsg(sender=1, phase="hold")
    end = time.monotonic() + 10
    seen_good = False
    while time.monotonic() < end and not (seen_good and b.stats.rejected >= 2):
        a.session.put("nao/1/status", b"\xc1 not msgpack")
        a.session.put("nao/1/status", encode(good)[:-3])
        a.publish(key_status(1), good)
        for e in b.drain(0.2):
            assert e.msg == good
            seen_good = True
    assert seen_good
    assert b.stats.rejected >= 2
    assert b.guard.rejected == b.stats.rejected


def test_liveliness_alive_and_gone(pair: tuple[Bus, Bus, str]) -> None:
    _, b, ep = pair
    b.watch_alive("nao/alive/*")
    c = Bus(BusConfig(connect=(ep,), multicast_scouting=False))
    c.declare_alive("nao/alive/7")
    got = wait_for(b, lambda g: any(e.kind == "alive" and e.robot_id == 7 for e in g))
    c.close()
    # A peer's tokens go at once when its close reaches the router, and at the
    # latest when its link's lease (zenoh's default, 10 s) runs out: wait past the lease.
    got = wait_for(
        b, lambda g: any(e.kind == "gone" and e.robot_id == 7 for e in g), LEASE_S + 10.0
    )
    assert got


def test_liveliness_history_sees_existing_members(pair: tuple[Bus, Bus, str]) -> None:
    a, b, _ = pair
    a.declare_alive("nao/alive/2")
    b.watch_alive("nao/alive/*")
    wait_for(b, lambda g: any(e.kind == "alive" and e.robot_id == 2 for e in g))


def serve(session: zenoh.Session, key: str, reply: bytes | None) -> zenoh.Queryable:
    def on_query(q: zenoh.Query) -> None:
        # test server only: replies inline (the world hands queries to a worker)
        if reply is not None:
            q.reply(key, reply)

    return session.declare_queryable(key, on_query)


def world_session(ep: str) -> zenoh.Session:
    cfg = zenoh.Config()
    cfg.insert_json5("connect/endpoints", json.dumps([ep]))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(cfg)


def query_eventually(bus: Bus, key: str, expect: type, timeout: float = 2.0) -> object:
    end = time.monotonic() + 15
    last: Exception | None = None
    while time.monotonic() < end:
        try:
            return bus.query(key, WalkRequest(distance=0.2), expect, timeout)
        except BusError as exc:
            last = exc
            if "no reply" not in str(exc):
                raise
    raise AssertionError(f"no reply: {last}")


def test_query_reply_decoded(pair: tuple[Bus, Bus, str]) -> None:
    _, b, ep = pair
    w = world_session(ep)
    rep = CommandReply(robot_id=3, status="done", t_sim=1.5)
    q = serve(w, key_walk(3), encode(rep))
    try:
        got = query_eventually(b, key_walk(3), CommandReply)
        assert got == rep
        assert b.stats.query_bytes > 0
    finally:
        q.undeclare()
        w.close()


@pytest.mark.parametrize(
    ("why", "kind"),
    [("robot 3 is busy", BusError), (f"{BUSY}: 64 pictures being drawn", Busy)],
)
def test_query_error_reply_raises_with_reason(
    pair: tuple[Bus, Bus, str], why: str, kind: type[BusError]
) -> None:
    """An error reply raises with its reason; one that starts with BUSY raises Busy (the
    caller may ask again), any other a plain BusError (a refusal, not an overload)."""
    _, b, ep = pair
    w = world_session(ep)
    q = serve(w, key_walk(3), encode(ErrorReply(reason=why)))
    try:
        with pytest.raises(BusError, match=why) as info:
            query_eventually(b, key_walk(3), CommandReply)
        assert type(info.value) is kind
    finally:
        q.undeclare()
        w.close()


def test_query_undecodable_reply_raises(pair: tuple[Bus, Bus, str]) -> None:
    _, b, ep = pair
    w = world_session(ep)
    q = serve(w, key_walk(3), b"garbage")
    try:
        with pytest.raises(BusError, match="undecodable reply"):
            query_eventually(b, key_walk(3), CommandReply)
    finally:
        q.undeclare()
        w.close()


def test_query_without_queryable_is_no_route(pair: tuple[Bus, Bus, str]) -> None:
    # zenoh ends a get at once when no queryable matches: nothing ran, a retry is safe
    _, b, _ = pair
    t0 = time.monotonic()
    with pytest.raises(NoRoute, match="no queryable reachable"):
        b.query(key_walk(9), WalkRequest(distance=0.1), CommandReply, timeout=5.0)
    assert time.monotonic() - t0 < 5.0


def test_query_to_a_queryable_that_holds_the_reply_times_out(pair: tuple[Bus, Bus, str]) -> None:
    _, b, ep = pair
    w = world_session(ep)
    held: list[zenoh.Query] = []  # keeps the queries alive: no reply, no final
    q = w.declare_queryable(key_walk(4), held.append)
    try:
        end = time.monotonic() + 15
        while True:  # until the route to the queryable is known
            try:
                b.query(key_walk(4), WalkRequest(distance=0.1), CommandReply, timeout=1.0)
            except NoRoute:
                assert time.monotonic() < end, "route never appeared"
                continue
            except QueryTimeout as exc:
                # zenoh itself ends a timed-out get with an error reply "Timeout": it is
                # a timeout (asked again by the body), not a world's error (at 100 NAOs one stopped
                # a robot)
                assert "no reply within 1 s" in str(exc)
                break
    finally:
        held.clear()
        q.undeclare()
        w.close()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"mode": "server"}, "mode"),
        ({"connect": ("127.0.0.1:7447",)}, "proto/address"),
        ({"mode": "client", "multicast_scouting": False}, "client mode"),
    ],
)
def test_bad_config(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        BusConfig(**kwargs)  # type: ignore[arg-type]


def test_decode_of_reply_helpers() -> None:
    # the codec round trip the bus relies on
    rep = CommandReply(robot_id=1, status="contact", t_sim=2.0, detail="bumped robot 2")
    assert decode(encode(rep), expect=CommandReply) == rep


# --------------------------------------------------------------------------- hardening


def sample(key: object, payload: object, kind: object = zenoh.SampleKind.PUT) -> Any:
    return SimpleNamespace(key_expr=key, payload=payload, kind=kind)


class BadStr:
    def __str__(self) -> str:
        raise RuntimeError("key that cannot be printed")


def test_callbacks_survive_everything_and_count_it(
    pair: tuple[Bus, Bus, str], caplog: pytest.LogCaptureFixture
) -> None:
    _, b, _ = pair
    caplog.set_level(logging.WARNING, "agent.net.bus")
    good = encode(StatusMsg(sender=1, phase="hold"))
    b._on_sample(sample("nao/1/status", FakeZBytes(MAX_PUBLICATION_BYTES + 1)))  # not copied
    b._on_sample(sample("nao/1/status", FakeZBytes(len(good), good)), max_bytes=10)
    b._on_sample(sample(BadStr(), FakeZBytes(len(good), good)))
    b._on_sample(sample("nao/1/status", None))
    b._on_sample(object())  # no attributes at all
    b._on_sample(sample("nao/1/status", FakeZBytes(3, b"\xc1" * 3)))
    b._on_alive(sample("nao/alive/01", None))  # an alias of robot 1
    b._on_alive(sample("nao/alive/\u0661", None))
    b._on_alive(sample(BadStr(), None))
    assert b.stats.rejected == 9
    assert b.drain() == []
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 9 and all(len(line) < 300 for line in lines)
    assert "exceeds" in lines[0] and "RuntimeError" in lines[2]
    # and the bus goes on
    b._on_sample(sample("nao/1/status", FakeZBytes(len(good), good)))
    b._on_alive(sample("nao/alive/1", None))
    got = b.drain()
    assert [e.kind for e in got] == ["msg", "alive"] and got[1].robot_id == 1


def test_long_exception_text_is_cut_in_the_log(
    pair: tuple[Bus, Bus, str], caplog: pytest.LogCaptureFixture
) -> None:
    _, b, _ = pair
    caplog.set_level(logging.WARNING, "agent.net.bus")

    class Huge:
        def __len__(self) -> int:
            raise ValueError("x" * 11_000_000)  # an 11 MB exception text (hostile input)

    b._on_sample(sample("nao/1/status", Huge()))
    (line,) = [r.getMessage() for r in caplog.records]
    assert len(line) < 300 and b.stats.rejected == 1


def test_event_queue_is_bounded_oldest_dropped_and_counted(pair: tuple[Bus, Bus, str]) -> None:
    _, b, _ = pair
    b._on_alive(sample("nao/alive/5", None))
    cap = EVENT_CAPS["msg"]
    for i in range(cap + 100):
        b._enqueue_sample("nao/1/status", encode(StatusMsg(sender=1, phase="hold", wave=i)))
    assert b.stats.dropped == 100
    got = b.drain()
    assert got[0].kind == "alive" and got[0].robot_id == 5  # a flood cannot push it out
    waves = [e.msg.wave for e in got[1:]]
    assert waves == list(range(100, cap + 100))  # the oldest went first
    for i in range(EVENT_CAPS["alive"] + 1):
        b._on_alive(sample(f"nao/alive/{i}", None))
    assert b.stats.dropped == 101
    assert len(b.drain()) == EVENT_CAPS["alive"]


def test_a_status_flood_cannot_push_records_out(pair: tuple[Bus, Bus, str]) -> None:
    """At 100 NAOs the run's observer lost 23 of the 100 records to a
    flood of statuses. Records have a lane of their own: a flood of statuses drops the
    oldest statuses, never a record."""
    _, b, _ = pair
    rec = NeighborRecordMsg(sender=7, round=0, neighbours=((1.0, 0.5),), orientations=(0.0,))
    b._enqueue_sample("nao/7/record", encode(rec))
    for i in range(EVENT_CAPS["msg"] + 10):
        b._enqueue_sample("nao/1/status", encode(StatusMsg(sender=1, phase="hold", wave=i)))
    assert b.stats.dropped == 10
    got = b.drain()
    assert got[0].key == "nao/7/record" and got[0].msg == rec
    assert [e.msg.wave for e in got[1:]] == list(range(10, EVENT_CAPS["msg"] + 10))
    # and the record lane is bounded too: the oldest record goes first
    for i in range(EVENT_CAPS["record"] + 1):
        b._enqueue_sample("nao/7/record", encode(replace(rec, round=i % 100)))
    assert b.stats.dropped == 11 and len(b.drain()) == EVENT_CAPS["record"]


def serve_raw(session: zenoh.Session, key: str, replies: list[bytes]) -> zenoh.Queryable:
    def on_query(q: zenoh.Query) -> None:
        for r in replies:
            q.reply(key, r)

    return session.declare_queryable(key, on_query)


@pytest.mark.parametrize(
    ("payloads", "match"),
    [
        # was an uncaught TypeError in the agent (sorted() over str and bytes names)
        (
            [msgpack.packb({"v": 1, "t": "done", "a": 1, b"b": 2}, use_bin_type=True)],
            "field names must be text",
        ),
        ([encode(ClockMsg(t_sim=1.0))], "unexpected reply ClockMsg, expected CommandReply"),
        ([msgpack.packb({"v": True, "t": "done"})], "schema version"),
    ],
)
def test_unexpected_replies_are_a_bus_error(
    pair: tuple[Bus, Bus, str], payloads: list[bytes], match: str
) -> None:
    _, b, ep = pair
    w = world_session(ep)
    q = serve_raw(w, key_walk(3), payloads)
    try:
        with pytest.raises(BusError, match=match):
            query_eventually(b, key_walk(3), CommandReply)
        assert b.stats.rejected >= len(payloads)
    finally:
        q.undeclare()
        w.close()


def ok_reply(data: bytes) -> Any:
    return SimpleNamespace(ok=SimpleNamespace(payload=FakeZBytes(len(data), data)), err=None)


def test_a_good_reply_after_bad_ones_is_taken_and_reasons_are_capped(
    pair: tuple[Bus, Bus, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # zenoh consolidates one queryable's replies on one key: feed the reply loop directly
    _, b, _ = pair
    rep = CommandReply(robot_id=3, status="done", t_sim=1.0)
    bad = [ok_reply(b"junk"), ok_reply(encode(ClockMsg(t_sim=1.0)))]
    replies: list[Any] = [*bad, ok_reply(encode(rep))]

    def get(key: str, handler: Any, **kw: Any) -> None:  # zenoh's get: replies, then the end
        for r in replies:
            handler.callback(r)
        handler.drop()

    monkeypatch.setattr(b, "session", SimpleNamespace(get=get))
    assert b.query(key_walk(3), WalkRequest(distance=0.1), CommandReply) == rep
    assert b.stats.rejected == 2
    replies = [ok_reply(b"\xc1" * (i + 1)) for i in range(6)]
    with pytest.raises(BusError, match=r"not msgpack.*; and 2 more$"):
        b.query(key_walk(3), WalkRequest(distance=0.1), CommandReply)
    assert b.stats.rejected == 8


def test_reply_checks_without_a_network(pair: tuple[Bus, Bus, str]) -> None:
    _, b, _ = pair
    big = SimpleNamespace(ok=SimpleNamespace(payload=FakeZBytes(MAX_MESSAGE_BYTES + 1)), err=None)
    huge_err = SimpleNamespace(ok=None, err=SimpleNamespace(payload=FakeZBytes(10**9)))
    empty = SimpleNamespace(ok=None, err=None)
    errors: list[str] = []
    assert b._first_reply("k", [big, huge_err, empty], CommandReply, errors) is None
    assert "exceeds" in errors[0] and "exceeds 4096" in errors[1] and errors[2] == "empty reply"
    assert b.stats.rejected == 2  # the empty reply is zenoh's, not an attack

    def broken() -> Iterator[Any]:
        yield empty
        raise RuntimeError("link gone")

    errors = []
    assert b._first_reply("k", broken(), CommandReply, errors) is None
    assert errors[-1] == "reply stream failed: RuntimeError: link gone"


def test_a_reply_stream_that_never_ends_ends_at_its_deadline(
    pair: tuple[Bus, Bus, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """zenoh ends a get's replies at its timeout; a stream it leaves open (no reply, no
    end) ends REPLY_GRACE s past the query's timeout, as a timeout, and a flood of
    replies is kept to MAX_REPLIES."""
    _, b, _ = pair
    monkeypatch.setattr(bus_module, "REPLY_GRACE", 0.3)
    monkeypatch.setattr(b, "session", SimpleNamespace(get=lambda key, handler, **kw: None))
    t0 = time.monotonic()
    with pytest.raises(QueryTimeout, match=r"no reply within 0\.2 s"):
        b.query(key_walk(3), WalkRequest(distance=0.1), CommandReply, timeout=0.2)
    assert 0.45 <= time.monotonic() - t0 < 5.0
    inbox = ReplyInbox(limit=2)
    for k in range(3):
        inbox.put(k)  # the third is dropped
    assert list(inbox.stream(time.monotonic() + 0.1)) == [0, 1]  # then the deadline
    inbox.end()
    assert list(inbox.stream(time.monotonic() + 60.0)) == []  # the end comes at once
    with pytest.raises(ValueError, match="limit"):
        ReplyInbox(limit=0)

    def flood(key: str, handler: Any, **kw: Any) -> None:
        for _ in range(MAX_REPLIES + 50):
            handler.callback(ok_reply(b"junk"))
        handler.drop()

    monkeypatch.setattr(b, "session", SimpleNamespace(get=flood))
    before = b.stats.rejected
    with pytest.raises(BusError):
        b.query(key_walk(3), WalkRequest(distance=0.1), CommandReply, timeout=0.2)
    assert b.stats.rejected - before == MAX_REPLIES


def test_query_on_a_bad_key_is_a_bus_error(pair: tuple[Bus, Bus, str]) -> None:
    _, b, _ = pair
    with pytest.raises(BusError, match="query failed"):
        b.query("world/robot/**/#bad?", WalkRequest(distance=0.1), CommandReply, timeout=1.0)


@pytest.mark.parametrize("lane", ["msg", "record"])
def test_event_queue_is_bounded_in_payload_bytes_too(pair: tuple[Bus, Bus, str], lane: str) -> None:
    _, b, _ = pair
    if lane == "record":
        key, big = "nao/1/record", encode(
            NeighborRecordMsg(
                sender=1, round=0, neighbours=tuple((0.1 * i, 1.0 / (i + 1)) for i in range(128)),
                orientations=tuple(0.01 * i for i in range(128)),
            )
        )  # fmt: skip
    else:
        members = tuple(range(60_000, 61_024))
        key, big = (
            "nao/1/digest",
            encode(DigestMsg(sender=1, round=0, digest="ab" * 32, members=members)),
        )
    n = EVENT_CAPS[lane]
    assert n * len(big) > EVENT_MAX_BYTES[lane]  # the byte cap binds before the count
    for _ in range(n):
        b._enqueue_sample(key, big)
    kept = EVENT_MAX_BYTES[lane] // len(big)
    assert b.events.weights()[lane] <= EVENT_MAX_BYTES[lane]
    assert b.stats.dropped == n - kept and len(b.drain()) == kept


class _Flaky:
    """Fails to open ``fails`` times, then returns "session"; a fake clock and sleep."""

    def __init__(self, fails: int) -> None:
        self.fails, self.calls, self.t = fails, 0, 0.0
        self.sleeps: list[float] = []

    def open(self) -> str:
        self.calls += 1
        if self.calls <= self.fails:
            raise SessionUnavailable(f"cannot open the zenoh session: attempt {self.calls}")
        return "session"

    def sleep(self, s: float) -> None:
        self.sleeps.append(s)
        self.t += s


def test_open_retrying_backs_off_until_the_session_opens() -> None:
    f = _Flaky(fails=5)
    got = open_retrying(f.open, 100.0, clock=lambda: f.t, sleep=f.sleep, wait=(1.0, 4.0))
    assert got == "session" and f.calls == 6
    assert f.sleeps == [1.0, 2.0, 4.0, 4.0, 4.0]


def test_open_retrying_gives_up_at_the_deadline_with_the_last_error() -> None:
    f = _Flaky(fails=100)
    with pytest.raises(SessionUnavailable, match="attempt 5"):
        open_retrying(f.open, 10.0, clock=lambda: f.t, sleep=f.sleep, wait=(1.0, 4.0))
    assert f.sleeps == [1.0, 2.0, 4.0, 3.0]  # the last wait ends at the deadline, one more try
    assert sum(f.sleeps) == 10.0


def test_open_retrying_does_not_retry_other_errors() -> None:
    def broken() -> str:
        raise BusError("not a session problem")

    with pytest.raises(BusError, match="not a session problem"):
        open_retrying(broken, 100.0, sleep=lambda s: pytest.fail("retried"))


@pytest.mark.parametrize(
    "give_up, wait, match",
    [(-1.0, (1.0, 2.0), "give_up_s"), (math.inf, (1.0, 2.0), "give_up_s"),
     (1.0, (0.0, 2.0), "wait"), (1.0, (3.0, 2.0), "wait")],
)  # fmt: skip
def test_open_retrying_rejects_bad_bounds(
    give_up: float, wait: tuple[float, float], match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        open_retrying(lambda: "x", give_up, wait=wait)


def test_a_sample_carries_the_time_it_arrived(pair: tuple[Bus, Bus, str]) -> None:
    """A loaded reader's queue must not delay when a message is said to have
    arrived (the harness's phase times): the callback stamps it before any check."""
    _, b, _ = pair
    before = time.monotonic()
    b._on_sample(sample("nao/1/status", zb(encode(StatusMsg(sender=1, phase="hold")))))
    after = time.monotonic()
    (ev,) = b.drain()
    assert before <= ev.t_rx <= after
