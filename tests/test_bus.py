"""agent/bus.py with real zenoh sessions on loopback (tcp, no multicast)."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Iterator

import pytest
import zenoh

from agent.bus import Bus, BusConfig, BusError, Event, NoRoute
from agent.protocol import (
    CommandReply,
    ErrorReply,
    StatusMsg,
    WalkRequest,
    decode,
    encode,
    key_status,
    key_walk,
)

pytestmark = pytest.mark.system


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


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


def test_malformed_payload_is_rejected_and_the_bus_goes_on(pair: tuple[Bus, Bus, str]) -> None:
    a, b, _ = pair
    b.subscribe("nao/**")
    good = StatusMsg(sender=1, phase="hold")
    end = time.monotonic() + 10
    seen_good = False
    while time.monotonic() < end and not seen_good:
        a.session.put("nao/1/status", b"\xc1 not msgpack")
        a.session.put("nao/1/status", encode(good)[:-3])
        a.publish(key_status(1), good)
        for e in b.drain(0.2):
            assert e.msg == good
            seen_good = True
    assert seen_good
    assert b.stats.rejected >= 2


def test_liveliness_alive_and_gone(pair: tuple[Bus, Bus, str]) -> None:
    _, b, ep = pair
    b.watch_alive("nao/alive/*")
    c = Bus(BusConfig(connect=(ep,), multicast_scouting=False))
    c.declare_alive("nao/alive/7")
    got = wait_for(b, lambda g: any(e.kind == "alive" and e.robot_id == 7 for e in g))
    c.close()
    got = wait_for(b, lambda g: any(e.kind == "gone" and e.robot_id == 7 for e in g))
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


def test_query_error_reply_raises_with_reason(pair: tuple[Bus, Bus, str]) -> None:
    _, b, ep = pair
    w = world_session(ep)
    q = serve(w, key_walk(3), encode(ErrorReply(reason="robot 3 is busy")))
    try:
        with pytest.raises(BusError, match="robot 3 is busy"):
            query_eventually(b, key_walk(3), CommandReply)
    finally:
        q.undeclare()
        w.close()


def test_query_undecodable_reply_raises(pair: tuple[Bus, Bus, str]) -> None:
    _, b, ep = pair
    w = world_session(ep)
    q = serve(w, key_walk(3), b"garbage")
    try:
        with pytest.raises(BusError, match="rejected reply"):
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
            except BusError as exc:
                assert not isinstance(exc, NoRoute)
                # zenoh itself answers a timed-out get with an error reply "Timeout"
                assert "Timeout" in str(exc) or "no reply within" in str(exc)
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
