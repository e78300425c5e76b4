"""Revoking a key (docs/design.md §8 "Trust"): agent/wire/revocation.py, the checks in
agent/wire/credentials.py, the verifier and the router's access control, ``tools.fleet
revoke`` and, marked ``system``, a real TLS router that refuses a revoked robot's traffic.
"""

from __future__ import annotations

import contextlib
import datetime
import json
import queue
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh
from cryptography import x509
from cryptography.hazmat.primitives import serialization

from agent import wire as P
from agent.wire import trust as T
from agent.wire.credentials import _load_cert
from tools import fleet, router
from tools.harness.procs import free_port

REPO = Path(__file__).resolve().parents[2]
R2, R3 = T.Identity.robot(2), T.Identity.robot(3)


@pytest.fixture
def root(tmp_path: Path) -> Path:
    out = tmp_path / "fleet"
    T.create_fleet(out, [1, 2, 3])
    return out


def _crl(root: Path) -> x509.CertificateRevocationList:
    return x509.load_pem_x509_crl((root / "crl.pem").read_bytes())


# --------------------------------------------------------------------------- the checks


def test_no_revocation_list_revokes_nothing(root: Path) -> None:
    creds = T.Credentials(root)
    assert not (root / "crl.pem").exists()
    assert creds.revoked == {} and creds.robots() == [1, 2, 3]


def test_a_revoked_certificate_leaves_the_roster_and_cannot_act(root: Path) -> None:
    assert T.revoke(root, [R3], reason="key-compromise") == [R3]
    creds = T.Credentials(root)
    assert R3 not in creds.roster and creds.robots() == [1, 2]
    assert creds.own_robot_keys() == [1, 2]  # `--id auto` never claims robot 3
    assert creds.revoked[R3].reason == "key-compromise"
    # on the same path as expiry: loading the certificate itself is refused
    with pytest.raises(T.CertificateRevoked, match="revoked by the fleet CA"):
        _load_cert(creds.paths.cert(R3), creds.ca, _now(), creds.revocations)
    # a process whose own key is revoked refuses to start: signer (bus, world) and TLS
    with pytest.raises(T.TrustError, match="robot-3's certificate is revoked"):
        creds.signer(R3)
    with pytest.raises(T.TrustError, match="robot-3's certificate is revoked"):
        T.tls_settings(creds, R3)
    assert creds.signer(R2).who == R2  # the others are unaffected


def _now() -> datetime.datetime:
    return datetime.datetime.now(datetime.UTC)


def test_a_revocation_list_of_another_ca_is_refused(root: Path, tmp_path: Path) -> None:
    other = T.create_fleet(tmp_path / "other", [1, 2, 3])
    T.revoke(other.root, [T.Identity.robot(1)])  # same CA name, another CA key
    shutil.copy(other.crl, root / "crl.pem")
    with pytest.raises(T.TrustError, match="not signed by this fleet's CA"):
        T.Credentials(root)


def test_a_tampered_revocation_list_is_refused(root: Path) -> None:
    T.revoke(root, [R3])
    der = bytearray(_crl(root).public_bytes(serialization.Encoding.DER))
    der[-1] ^= 0x01  # the signature's last byte
    crl = x509.load_der_x509_crl(bytes(der))
    (root / "crl.pem").write_bytes(crl.public_bytes(serialization.Encoding.PEM))
    with pytest.raises(T.TrustError, match="not signed by this fleet's CA"):
        T.Credentials(root)


def test_a_corrupt_revocation_list_is_refused(root: Path) -> None:
    (root / "crl.pem").write_bytes(b"-----BEGIN X509 CRL-----\nnonsense\n-----END X509 CRL-----\n")
    with pytest.raises(T.TrustError, match="not a PEM revocation list"):
        T.Credentials(root)


def test_an_unreadable_revocation_list_is_refused(root: Path) -> None:
    (root / "crl.pem").mkdir()  # there, but not a file: fail closed, never "nothing revoked"
    with pytest.raises(T.TrustError, match="cannot read the revocation list"):
        T.Credentials(root)


def test_an_expired_revocation_list_is_refused(root: Path) -> None:
    T.revoke(root, [R3])
    later = _now() + datetime.timedelta(days=400)  # past the CA, and the list's next update
    with pytest.raises(T.TrustError, match="revocation list expired"):
        T.Credentials(root, now=later)


def test_revoking_twice_keeps_one_entry(root: Path) -> None:
    first = _now() - datetime.timedelta(minutes=5)
    assert T.revoke(root, [R3], reason="retired", now=first) == [R3]
    data = (root / "crl.pem").read_bytes()
    assert T.revoke(root, [R3], reason="key-compromise") == []
    assert (root / "crl.pem").read_bytes() == data  # nothing new: the file is untouched
    assert T.revoke(root, [R3, R2]) == [R2]
    crl = _crl(root)
    assert len(list(crl)) == 2
    assert crl.extensions.get_extension_for_class(x509.CRLNumber).value.crl_number == 2
    entry = T.Credentials(root).revoked[R3]
    assert (entry.reason, entry.date) == ("retired", first.replace(microsecond=0))


def test_revoke_errors(root: Path, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="reason 'stolen'"):
        T.revoke(root, [R3], reason="stolen")
    other = T.create_fleet(tmp_path / "other", [1])
    shutil.copy(other.ca_key, root / "ca-private" / "ca.key")
    with pytest.raises(T.TrustError, match="not the private key of"):
        T.revoke(root, [R3])
    (root / "ca-private" / "ca.key").unlink()
    with pytest.raises(ValueError, match="needs the CA's private key"):
        T.revoke(root, [R3])
    assert not (root / "crl.pem").exists()


# --------------------------------------------------------------------------- what it stops


def test_a_message_sealed_before_the_revocation_is_refused_after(root: Path) -> None:
    before = T.Credentials(root)
    captured = before.signer(R3).seal("nao/3/status", b"captured")
    assert before.verifier().open("nao/3/status", captured).who == R3
    T.revoke(root, [R3])
    after = T.Credentials(root).verifier()
    with pytest.raises(T.TrustError, match="robot-3's key is revoked"):
        after.open("nao/3/status", captured)  # a replay of the old capture
    ok = before.signer(R2).seal("nao/2/status", b"x")
    assert after.open("nao/2/status", ok).who == R2


def test_the_verifier_never_trusts_a_revoked_identity(root: Path) -> None:
    creds = T.Credentials(root)
    v = T.Verifier(creds.roster, revoked=[R3])  # even when the roster still holds it
    assert R3 not in v.roster
    with pytest.raises(T.TrustError, match="revoked"):
        v.open("nao/3/status", creds.signer(R3).seal("nao/3/status", b"x"))


def test_the_access_control_has_no_rule_for_a_revoked_robot(root: Path) -> None:
    T.revoke(root, [R3])
    acl = T.acl_settings(T.Credentials(root).roster)
    assert acl["default_permission"] == "deny"
    assert not [r for r in acl["rules"] if r["id"].startswith("r3-")]
    assert all("robot-3" not in s["cert_common_names"] for s in acl["subjects"])
    assert "robot-3" not in {p["id"] for p in acl["policies"]}
    assert "robot-2" in {s["id"] for s in acl["subjects"]}
    # the router's settings come from the same roster
    spec = P.NetworkSpec(
        listen=("tls/127.0.0.1:7447",), mode="router", credentials=str(root), identity="router"
    )
    assert json.loads(dict(spec.json5_items())["access_control"]) == acl


def test_revoked_world_and_observer_lose_their_subjects(root: Path) -> None:
    T.revoke(root, [T.Identity("world"), T.Identity("observer")])
    acl = T.acl_settings(T.Credentials(root).roster)
    subjects = {s["id"]: s["cert_common_names"] for s in acl["subjects"]}
    assert "world" not in subjects and "observer" not in subjects
    assert subjects["members"] == ["operator", "robot-1", "robot-2", "robot-3"]
    for p in acl["policies"]:  # every policy names subjects that exist
        assert set(p["subjects"]) <= set(subjects)


# --------------------------------------------------------------------------- the CLI


def test_fleet_revoke_show_and_export(
    root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["revoke", str(root), "--robot", "3", "--reason", "key-compromise"]
    assert fleet.main(argv) == 0
    assert "revoked robot-3" in capsys.readouterr().out
    assert fleet.main([*argv, "--identity", "observer"]) == 0
    out = capsys.readouterr().out
    assert "revoked observer" in out and "already revoked: robot-3" in out
    assert len(list(_crl(root))) == 2
    assert fleet.main(["show", str(root)]) == 0
    assert "robot-3      revoked (key-compromise" in capsys.readouterr().out
    host = tmp_path / "robot-2"
    assert fleet.main(["export", str(root), "--identity", "robot-2", "--out", str(host)]) == 0
    assert "crl.pem" in capsys.readouterr().out
    assert (host / "crl.pem").read_bytes() == (root / "crl.pem").read_bytes()
    assert set(T.Credentials(host).revoked) == {R3, T.Identity("observer")}
    x = str(tmp_path / "x")
    assert fleet.main(["export", str(root), "--identity", "robot-3", "--out", x]) == 2
    assert "robot-3's certificate is revoked" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "reason"),
    [
        (["revoke", "F"], "--robot N or --identity"),
        (["revoke", "F", "--identity", "king"], "names no fleet identity"),
        (["revoke", "F", "--robot", "9"], "not a PEM certificate"),
        (["revoke", "NOPE", "--robot", "1"], "no fleet CA"),
    ],
)
def test_fleet_revoke_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], reason: str
) -> None:
    T.create_fleet(tmp_path / "F", [1])
    argv = [str(tmp_path / a) if a in ("F", "NOPE") else a for a in argv]
    assert fleet.main(argv) == 2
    assert reason in capsys.readouterr().err


def test_the_router_refuses_to_start_on_a_bad_revocation_list(
    root: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (root / "crl.pem").write_text("not a list")
    argv = ["--credentials", str(root), "--listen", "tls/127.0.0.1:1", "--no-multicast-scouting"]
    assert router.main(argv) == 2
    assert "not a PEM revocation list" in capsys.readouterr().err


def test_a_revoked_router_refuses_to_start(root: Path, capsys: pytest.CaptureFixture[str]) -> None:
    T.revoke(root, [T.Identity("router")])
    argv = ["--credentials", str(root), "--listen", "tls/127.0.0.1:1", "--no-multicast-scouting"]
    assert router.main(argv) == 2
    assert "router's certificate is revoked" in capsys.readouterr().err


def _host(root: Path, tmp_path: Path, rid: int) -> Path:
    """One robot host's folder (its own key only), exported before any revocation."""
    host = tmp_path / f"robot-{rid}"
    fleet.export(root, T.Identity.robot(rid), host)
    return host


def test_id_auto_with_only_a_revoked_key_says_it_is_revoked(
    root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from agent.__main__ import main as agent_main

    host = _host(root, tmp_path, 3)
    T.revoke(root, [R3], reason="key-compromise")
    shutil.copy(root / "crl.pem", host / "crl.pem")  # the list handed out
    argv = ["--id", "auto", "--credentials", str(host), "--connect", "tls/127.0.0.1:1",
            "--no-multicast-scouting"]  # fmt: skip
    assert agent_main(argv) == 2  # refused before any session opens
    err = capsys.readouterr().err
    assert "holds only revoked robot keys" in err and "robot-3 (key-compromise" in err, err
    assert "no robot key to claim" not in err
    # a folder with no robot key at all: the message as before
    assert T.Credentials(host).revoked_robot_keys() == [3]
    (host / "keys" / "robot-3.key").unlink()
    assert agent_main(argv) == 2
    assert "holds no robot key to claim a robot with" in capsys.readouterr().err


def test_id_auto_skips_a_revoked_key_among_others(root: Path) -> None:
    T.revoke(root, [R3])
    creds = T.Credentials(root)
    assert creds.own_robot_keys() == [1, 2] and creds.revoked_robot_keys() == [3]


# --------------------------------------------------------------------------- a real router


def _spec(creds: Path, ep: str, cn: str) -> P.NetworkSpec:
    return P.NetworkSpec(
        connect=(ep,), multicast_scouting=False, mode="client", credentials=str(creds), identity=cn
    )


@pytest.mark.system
def test_a_tls_router_refuses_everything_from_a_revoked_robot(root: Path, tmp_path: Path) -> None:
    """Robot 3's key was stolen: the thief's copy of the folder predates the revocation
    (no crl.pem), so its TLS link to the router opens; the router, started with the list,
    gives robot-3 no rule: the observer hears robot 2 and never robot 3, and robot 3 is
    delivered nothing."""
    from agent.net.bus import zenoh_config

    thief = tmp_path / "thief"
    shutil.copytree(root, thief)
    T.revoke(root, [R3], reason="key-compromise")
    ep = f"tls/127.0.0.1:{free_port()}"
    argv = ["--credentials", str(root), "--listen", ep, "--no-multicast-scouting"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "tools.router", *argv],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=str(REPO),
    )  # fmt: skip
    sessions: list[zenoh.Session] = []
    try:
        assert proc.stdout is not None and "router ready" in proc.stdout.readline()
        for folder, cn in ((root, "observer"), (root, "robot-2"), (thief, "robot-3")):
            sessions.append(zenoh.open(zenoh_config(_spec(folder, ep, cn))))
        obs, r2, r3 = sessions
        heard: queue.Queue[str] = queue.Queue()
        stolen: queue.Queue[str] = queue.Queue()
        obs.declare_subscriber("nao/*/status", lambda s: heard.put(str(s.key_expr)))
        r3.declare_subscriber("nao/2/status", lambda s: stolen.put(str(s.key_expr)))
        alive: queue.Queue[str] = queue.Queue()
        obs.liveliness().declare_subscriber(
            "nao/alive/*",
            lambda s: alive.put(str(s.key_expr)) if s.kind == zenoh.SampleKind.PUT else None,
            history=True,
        )
        # kept: a token whose handle is dropped is undeclared at once, and whether its short
        # life reached the observer then depended on which message arrived first
        tokens_kept = [r2.liveliness().declare_token("nao/alive/2")]
        tokens_kept.append(r3.liveliness().declare_token("nao/alive/3"))
        counts = {"nao/2/status": 0, "nao/3/status": 0}
        deadline = time.monotonic() + 30.0
        # until 20 of robot 2's statuses arrived, robot 3 publishing alongside the whole time
        while counts["nao/2/status"] < 20 and time.monotonic() < deadline:
            r2.put("nao/2/status", b"genuine")
            r3.put("nao/3/status", b"revoked")
            try:
                key = heard.get(timeout=0.05)  # paces the puts; bounded by the deadline
                counts[key] = counts.get(key, 0) + 1
            except queue.Empty:
                pass
        while not heard.empty():  # whatever was still in flight counts too
            key = heard.get()
            counts[key] = counts.get(key, 0) + 1
        assert counts["nao/2/status"] >= 20, counts
        assert counts["nao/3/status"] == 0, counts
        assert [str(z) for z in r3.info.routers_zid()]  # its link is up: the ACL refused
        assert stolen.empty()  # and the router delivered nothing to it
        # the tokens: from the subscriber, and by asking the router for the live ones, on a
        # deadline of their own (a token declared before the subscription reached the router
        # is still answered by the query)
        tokens: set[str] = set()
        token_deadline = time.monotonic() + 30.0
        while "nao/alive/2" not in tokens and time.monotonic() < token_deadline:
            for reply in obs.liveliness().get("nao/alive/*", timeout=1.0):
                if reply.ok is not None:  # an error reply carries no key
                    tokens.add(str(reply.ok.key_expr))
            with contextlib.suppress(queue.Empty):
                tokens.add(alive.get(timeout=0.2))
        while not alive.empty():
            tokens.add(alive.get())
        assert tokens == {"nao/alive/2"}  # robot 2's token arrived, robot 3's never did
    finally:
        for s in sessions:
            s.close()
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=15)
    assert "revoked, denied everything: robot-3" in err
