"""agent/wire/trust.py: identities, the credentials folder, the signed envelope, zenoh settings."""

from __future__ import annotations

import argparse
import datetime
import json
import shutil
from pathlib import Path

import msgpack
import pytest

from agent import wire as P
from agent.wire import trust as T

FIXED = 1_800_000_000.0  # a fixed "now" (s) for the envelope tests


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> T.Credentials:
    root = tmp_path_factory.mktemp("fleet") / "fleet"
    T.create_fleet(root, [1, 2, 3])
    return T.Credentials(root)


def clock(t: float = FIXED):  # type: ignore[no-untyped-def]
    return lambda: t


def signer(creds: T.Credentials, cn: str, epoch: int = 1000, t: float = FIXED) -> T.Signer:
    s = creds.signer(T.Identity.parse(cn), epoch_ms=epoch)
    s.clock = clock(t)
    return s


def verifier(creds: T.Credentials, t: float = FIXED, **kw: object) -> T.Verifier:
    return T.Verifier(creds.roster, clock=clock(t), **kw)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- identities


@pytest.mark.parametrize(
    ("cn", "want"),
    [
        ("robot-0", T.Identity.robot(0)),
        ("robot-2", T.Identity.robot(2)),
        ("robot-65535", T.Identity.robot(65535)),
        ("world", T.Identity("world")),
        ("observer", T.Identity("observer")),
        ("router", T.Identity("router")),
    ],
)
def test_identity_parses_the_common_names_of_the_fleet(cn: str, want: T.Identity) -> None:
    assert T.Identity.parse(cn) == want
    assert want.cn == cn


@pytest.mark.parametrize(
    "cn", ["robot-01", "robot-65536", "robot-١", "robot-", "robot-2 ", "Robot-2", "admin", ""]
)
def test_identity_refuses_anything_else(cn: str) -> None:
    with pytest.raises(T.TrustError):
        T.Identity.parse(cn)


def test_identity_checks_its_fields() -> None:
    with pytest.raises(ValueError, match="role"):
        T.Identity("king")
    with pytest.raises(ValueError, match="outside"):
        T.Identity.robot(70000)
    with pytest.raises(ValueError, match="no robot id"):
        T.Identity("world", 3)


# --------------------------------------------------------------------------- the folder


def test_create_fleet_writes_the_roster_and_private_keys(fleet: T.Credentials) -> None:
    assert fleet.robots() == [1, 2, 3]
    assert fleet.own_robot_keys() == [1, 2, 3]
    assert {w.cn for w in fleet.roster} == {
        "robot-1", "robot-2", "robot-3", "world", "observer", "router", "render",
        "operator",
    }  # fmt: skip
    key = fleet.paths.key(T.Identity.robot(2))
    assert key.stat().st_mode & 0o777 == 0o600
    assert fleet.paths.ca_key.stat().st_mode & 0o777 == 0o600


def test_create_fleet_errors(tmp_path: Path, fleet: T.Credentials) -> None:
    with pytest.raises(ValueError, match="already holds"):
        T.create_fleet(fleet.root, [1])
    with pytest.raises(ValueError, match="at least one"):
        T.create_fleet(tmp_path / "a", [])
    with pytest.raises(ValueError, match="valid_days"):
        T.create_fleet(tmp_path / "b", [1], valid_days=0)


def test_a_certificate_of_another_fleet_is_refused(tmp_path: Path, fleet: T.Credentials) -> None:
    other = T.create_fleet(tmp_path / "other", [7])
    mixed = tmp_path / "mixed"
    shutil.copytree(fleet.root, mixed)
    shutil.copy(other.cert(T.Identity.robot(7)), mixed / "certs" / "robot-7.pem")
    with pytest.raises(T.TrustError, match="not issued by this fleet"):
        T.Credentials(mixed)


def test_a_certificate_under_another_name_is_refused(tmp_path: Path, fleet: T.Credentials) -> None:
    mixed = tmp_path / "renamed"
    shutil.copytree(fleet.root, mixed)
    shutil.copy(mixed / "certs" / "robot-1.pem", mixed / "certs" / "robot-9.pem")
    with pytest.raises(T.TrustError, match="not its file name"):
        T.Credentials(mixed)


def test_expired_certificates_and_missing_folders_are_refused(
    tmp_path: Path, fleet: T.Credentials
) -> None:
    later = datetime.datetime.now(datetime.UTC) + datetime.timedelta(days=400)
    with pytest.raises(T.TrustError, match="expired"):
        T.Credentials(fleet.root, now=later)
    with pytest.raises(T.TrustError, match="no fleet CA"):
        T.Credentials(tmp_path / "nothing")


def test_a_key_that_does_not_match_its_certificate_is_refused(
    tmp_path: Path, fleet: T.Credentials
) -> None:
    swapped = tmp_path / "swapped"
    shutil.copytree(fleet.root, swapped)
    shutil.copy(swapped / "keys" / "robot-1.key", swapped / "keys" / "robot-2.key")
    creds = T.Credentials(swapped)
    with pytest.raises(T.TrustError, match="does not match"):
        creds.signer(T.Identity.robot(2))
    (swapped / "keys" / "robot-3.key").unlink()
    with pytest.raises(T.TrustError, match="no usable private key"):
        creds.signer(T.Identity.robot(3))
    assert creds.own_robot_keys() == [1, 2]


# --------------------------------------------------------------------------- envelope


def test_a_sealed_message_opens_with_its_signer_epoch_and_payload(fleet: T.Credentials) -> None:
    data = signer(fleet, "robot-2", epoch=42).seal("nao/2/record", b"payload")
    opened = verifier(fleet).open("nao/2/record", data)
    assert opened.who == T.Identity.robot(2)
    assert (opened.epoch, opened.seq, opened.payload) == (42, 1, b"payload")


FIELDS = ("v", "by", "e", "n", "dt", "p", "s")


def _tamper(data: bytes, **changes: object) -> bytes:
    obj = msgpack.unpackb(data, raw=False)
    for k, v in changes.items():
        if k == "extra":
            obj.append(v)
        else:
            obj[FIELDS.index(k)] = v
    out = msgpack.packb(obj, use_bin_type=True)
    assert isinstance(out, bytes)
    return out


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"p": b"forged"}, "bad signature"),
        ({"by": 3}, "bad signature"),
        ({"n": 7}, "bad signature"),
        ({"e": 43}, "bad signature"),
        ({"dt": 5}, "bad signature"),
        ({"by": 9}, "not in the fleet roster"),
        ({"by": -7}, "names no fleet identity"),
        ({"by": "robot-2"}, "names no fleet identity"),
        ({"v": 2}, "envelope version"),
        ({"v": True}, "envelope version"),
        ({"n": -1}, "sequence"),
        ({"e": 1.5}, "epoch"),
        ({"s": b"short"}, "signature malformed"),
        ({"extra": 1}, "not a sealed envelope"),
    ],
)
def test_a_tampered_envelope_is_refused(
    fleet: T.Credentials, change: dict[str, object], reason: str
) -> None:
    data = signer(fleet, "robot-2", epoch=42).seal("nao/2/record", b"payload")
    with pytest.raises(T.TrustError, match=reason):
        verifier(fleet).open("nao/2/record", _tamper(data, **change))


def test_the_envelope_costs_under_100_bytes(fleet: T.Credentials) -> None:
    s = fleet.signer(T.Identity.robot(2))  # a real epoch: ms since the Unix epoch
    for _ in range(300):  # sequence numbers past 255 take 2 more bytes
        data = s.seal("nao/2/status", b"x" * 200)
    assert len(data) - 200 <= 100
    w = fleet.signer(T.Identity("world")).seal("world/clock", b"")
    assert T.Verifier(fleet.roster).open("world/clock", w).who == T.Identity("world")


def test_an_envelope_moved_to_another_key_or_request_is_refused(fleet: T.Credentials) -> None:
    s = signer(fleet, "world")
    reply = s.seal("world/robot/2/walk", b"done", bind=b"request-a")
    v = verifier(fleet)
    with pytest.raises(T.TrustError, match="bad signature"):
        v.open("world/robot/3/walk", reply, bind=b"request-a", replay=False)
    with pytest.raises(T.TrustError, match="bad signature"):
        v.open("world/robot/2/walk", reply, bind=b"request-b", replay=False)
    assert v.open("world/robot/2/walk", reply, bind=b"request-a", replay=False).payload == b"done"


def test_unsigned_and_oversized_payloads_are_refused(fleet: T.Credentials) -> None:
    v = verifier(fleet)
    with pytest.raises(T.TrustError, match="not a sealed envelope"):
        v.open("nao/2/record", P.encode(P.ClockMsg(t_sim=1.0)))
    with pytest.raises(P.ProtocolError, match="exceeds"):
        v.open("nao/2/record", b"\x00" * (T.MAX_SEALED_BYTES + 1))
    with pytest.raises(P.ProtocolError, match="not msgpack"):
        v.open("nao/2/record", b"\xc1")


@pytest.mark.parametrize("age", [T.MAX_AGE_S + 1, -(T.MAX_AGE_S + 1)])
def test_stale_and_future_messages_are_refused(fleet: T.Credentials, age: float) -> None:
    data = signer(fleet, "robot-1", t=FIXED - age).seal("nao/1/status", b"x")
    with pytest.raises(T.TrustError, match="stale"):
        verifier(fleet).open("nao/1/status", data)


def test_replays_are_refused_and_reordering_is_tolerated(fleet: T.Credentials) -> None:
    s = signer(fleet, "robot-1")
    msgs = [s.seal("nao/1/status", bytes([k])) for k in range(5)]
    v = verifier(fleet, window=3)
    v.open("nao/1/status", msgs[1])
    v.open("nao/1/status", msgs[3])
    v.open("nao/1/status", msgs[2])  # late, inside the window: accepted
    with pytest.raises(T.TrustError, match="already seen"):
        v.open("nao/1/status", msgs[3])
    v.open("nao/1/status", msgs[4])
    with pytest.raises(T.TrustError, match="too old"):
        v.open("nao/1/status", msgs[0])  # 1 <= top(5) - window(3)


def test_only_the_newest_epochs_of_a_key_are_kept(fleet: T.Credentials) -> None:
    v = verifier(fleet)
    first = signer(fleet, "robot-1", epoch=1).seal("nao/1/status", b"x")
    for epoch in range(2, 2 + T.EPOCHS_KEPT):
        v.open("nao/1/status", signer(fleet, "robot-1", epoch=epoch).seal("nao/1/status", b"y"))
    with pytest.raises(T.TrustError, match="older than kept"):
        v.open("nao/1/status", first)


def test_verifier_and_signer_errors(fleet: T.Credentials) -> None:
    with pytest.raises(ValueError, match="max_age"):
        T.Verifier(fleet.roster, max_age=0)
    s = signer(fleet, "robot-1")
    a, na = s.seal_request("k", b"1")
    _, nb = s.seal_request("k", b"2")
    assert na != nb  # every request has its own nonce
    assert verifier(fleet).open("k", a).nonce == na


# --------------------------------------------------------------------------- zenoh settings


def test_access_control_denies_by_default_and_gives_each_robot_its_keys(
    fleet: T.Credentials,
) -> None:
    acl = T.acl_settings(fleet.roster)
    assert acl["enabled"] and acl["default_permission"] == "deny"
    rules = {r["id"]: r for r in acl["rules"]}
    assert rules["r2-out"]["key_exprs"] == ["nao/2/**"]
    assert rules["r2-alive"]["key_exprs"] == ["nao/alive/2"]
    assert "world/robot/2/**" in rules["r2-ask"]["key_exprs"]
    assert all("nao/1" not in k for k in rules["r2-out"]["key_exprs"])
    subjects = {s["id"]: s for s in acl["subjects"]}
    assert subjects["robot-2"]["cert_common_names"] == ["robot-2"]
    policies = {p["id"]: p["rules"] for p in acl["policies"]}
    assert policies["observer"] == ["observe", "observe-deliver"]  # observers never send


def test_network_spec_with_credentials(fleet: T.Credentials) -> None:
    c = str(fleet.root)
    spec = P.NetworkSpec(
        connect=("tls/127.0.0.1:7447",), multicast_scouting=False, mode="client",
        credentials=c, identity="robot-2",
    )  # fmt: skip
    items = dict(spec.json5_items())
    tls = json.loads(items["transport/link/tls"])
    assert tls["enable_mtls"] and tls["connect_certificate"].endswith("robot-2.pem")
    assert "access_control" not in items
    router = P.NetworkSpec(
        listen=("tls/0.0.0.0:7447",), mode="router", credentials=c, identity="router"
    )
    assert json.loads(dict(router.json5_items())["access_control"])["enabled"]
    plain = P.NetworkSpec(
        connect=("tcp/127.0.0.1:1",), credentials=c, identity="robot-2", tls=False
    )
    assert "transport/link/tls" not in dict(plain.json5_items())


@pytest.mark.parametrize(
    ("kwargs", "reason"),
    [
        ({"identity": ""}, "identity"),
        ({"mode": "peer"}, "client of a TLS router"),
        ({"connect": ("tcp/127.0.0.1:7447",)}, "not tls"),
        ({"connect": ()}, "--connect tls"),
    ],
)
def test_network_spec_credentials_errors(
    fleet: T.Credentials, kwargs: dict[str, object], reason: str
) -> None:
    base: dict[str, object] = {
        "connect": ("tls/127.0.0.1:7447",), "multicast_scouting": False, "mode": "client",
        "credentials": str(fleet.root), "identity": "robot-2",
    }  # fmt: skip
    with pytest.raises(ValueError, match=reason):
        P.NetworkSpec(**{**base, **kwargs})  # type: ignore[arg-type]


def _args(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    P.add_network_arguments(p, ("peer", "client"))
    return p.parse_args(list(argv))


def test_network_spec_from_flags_is_secure_by_default(
    fleet: T.Credentials, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv(P.CREDENTIALS_ENV, raising=False)
    with pytest.raises(ValueError, match="no fleet credentials"):
        P.network_spec(_args(), "robot-1")
    insecure = P.network_spec(_args("--insecure"), "robot-1")
    assert not insecure.secure and insecure.mode == "peer"
    assert "WARNING: --insecure" in capsys.readouterr().err
    monkeypatch.setenv(P.CREDENTIALS_ENV, str(fleet.root))
    spec = P.network_spec(
        _args("--connect", "tls/127.0.0.1:7447", "--no-multicast-scouting"), "robot-1"
    )
    assert spec.secure and spec.mode == "client" and spec.identity == "robot-1"
    plain = P.network_spec(_args("--connect", "tcp/127.0.0.1:7447", "--plain-links"), "robot-1")
    assert plain.secure and not plain.tls and plain.mode == "peer"


def test_the_replay_window_is_pruned_seldom_and_stays_bounded(fleet: T.Credentials) -> None:
    s = signer(fleet, "robot-1")
    v = verifier(fleet, window=4)
    msgs = [s.seal("nao/1/status", bytes([k % 256])) for k in range(40)]
    sizes = []
    for m in msgs:
        v.open("nao/1/status", m)
        (state,) = v._state[T.Identity.robot(1)].values()
        sizes.append(len(state.seen))
    # grows to twice the window, then is pruned to the window (top - 4, top] and grows again
    assert sizes[:12] == [1, 2, 3, 4, 5, 6, 7, 8, 4, 5, 6, 7] and max(sizes) == 8
    with pytest.raises(T.TrustError, match="too old"):
        v.open("nao/1/status", msgs[35])  # 36 <= top(40) - window(4)
    with pytest.raises(T.TrustError, match="already seen"):
        v.open("nao/1/status", msgs[37])
