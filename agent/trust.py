"""Fleet trust (DESIGN.md §8): credentials, the signed envelope, TLS and access control.

Three layers, each useful without the others:

1. **Fleet credentials.** One Ed25519 fleet CA signs one certificate per identity:
   ``robot-{id}``, ``world``, ``observer``, ``router``. The certificate's common name *is*
   the identity; the same Ed25519 key serves the TLS link and the end-to-end signatures.
   Layout of a credentials folder (``python -m tools.fleet init``)::

       ca.pem                 fleet CA certificate (public; every host)
       certs/{cn}.pem         every identity's certificate: the roster (public; every host)
       keys/{cn}.key          private keys: a host gets only its own
       ca-private/ca.key      the CA's private key: keep it offline

2. **Transport.** Every zenoh link is TLS with mutual authentication against the fleet
   CA (:func:`tls_settings`), and the router's access control (:func:`acl_settings`) gives
   each common name its role: robot i publishes ``nao/i/**``, declares ``nao/alive/i``,
   serves ``nao/i/records`` (the agreed record sets, any member may ask) and
   queries ``world/robot/i/**`` and ``world/register``; the world serves ``world/**``;
   observers only subscribe.

3. **End to end.** Every payload travels in a sealed envelope (:meth:`Signer.seal`), a
   msgpack array ``[1, signer, epoch, seq, dt, payload, signature]``: the signer's
   :attr:`Identity.code`, its epoch (process start, ms since the Unix epoch; a restart is
   a newer epoch), a per-signer sequence number, the time since the epoch (ms) and an
   Ed25519 signature over the key expression, those numbers, an optional binding (a
   reply is bound to its request) and the payload: 88-95 bytes more per message. :class:`Verifier` checks the signature against the roster, the age
   (``|now - (epoch + dt)| <= max_age``) and replays (per signer and epoch a sliding window of
   sequence numbers, as IPsec's anti-replay window, refuses repeats while tolerating
   reordering; the newest :data:`EPOCHS_KEPT` epochs of a key are tracked, older ones
   refused). Which epoch of a key may *act* is the receiver's decision: the world binds
   a robot to the session that claimed or last commanded it, agents pin each member's
   epoch when they agree. Whatever routers or links lie in between, what reaches the
   planner is exactly what each robot signed.

Insider limit: a robot's own key can still lie about what it saw; Algorithm 2's
consistency check (``agent/formation/neighbour_check.py``) is the defence there.

This module uses ``cryptography`` only (no hand-written crypto) and is part of the wire
contract: ``sim/`` reaches it through ``agent.protocol``.
"""

from __future__ import annotations

import datetime
import ipaddress
import os
import re
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack
from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import ed25519
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from agent.protocol import (
    KEY_RECORDS_ALL,
    MAX_MESSAGE_BYTES,
    MAX_ROBOT_ID,
    ProtocolError,
    unpack_bounded,
)

ROLES = ("robot", "world", "observer", "router")
ENVELOPE_VERSION = 1
SIGNATURE_CONTEXT = b"nao-formation/sealed/1\x00"
#: Largest sealed payload: a message plus the envelope's fields.
MAX_SEALED_BYTES = MAX_MESSAGE_BYTES + 1024
#: Default freshness: a message older (or newer) than this many seconds is refused.
MAX_AGE_S = 120.0
#: Sequence numbers tolerated behind the newest one seen (reordering between paths).
REPLAY_WINDOW = 1024
#: Epochs (sessions) of one key tracked at once: a restart, or replicas trying a key.
EPOCHS_KEPT = 4

_ROBOT_CN = re.compile(r"robot-(0|[1-9][0-9]{0,4})")


class TrustError(ProtocolError):
    """A credential, certificate or envelope that cannot be trusted; the text says why."""


# --------------------------------------------------------------------------- identities


@dataclass(frozen=True, order=True)
class Identity:
    """Who holds a key: a ``role`` of :data:`ROLES`, and the robot id for robots."""

    role: str
    robot_id: int = -1

    def __post_init__(self) -> None:
        if self.role not in ROLES:
            raise ValueError(f"role {self.role!r} is not one of {', '.join(ROLES)}")
        if self.role == "robot":
            if isinstance(self.robot_id, bool) or not 0 <= self.robot_id <= MAX_ROBOT_ID:
                raise ValueError(f"robot id {self.robot_id!r} outside [0, {MAX_ROBOT_ID}]")
        elif self.robot_id != -1:
            raise ValueError(f"a {self.role} identity has no robot id")

    @property
    def cn(self) -> str:
        """The certificate common name: ``robot-2``, ``world``, ``observer``, ``router``."""
        return f"robot-{self.robot_id}" if self.role == "robot" else self.role

    @classmethod
    def robot(cls, robot_id: int) -> Identity:
        return cls("robot", robot_id)

    @property
    def code(self) -> int:
        """The compact wire code of the identity: the robot id, or -1 world, -2 observer,
        -3 router (one msgpack byte for the roles and robots up to 127)."""
        return self.robot_id if self.role == "robot" else -ROLES.index(self.role)

    @classmethod
    def from_code(cls, code: int) -> Identity:
        if type(code) is not int or not -len(ROLES) < code <= MAX_ROBOT_ID:
            raise TrustError(f"signer code {str(code)[:24]} names no fleet identity")
        return cls.robot(code) if code >= 0 else cls(ROLES[-code])

    @classmethod
    def parse(cls, cn: str) -> Identity:
        """The identity of a common name; :class:`TrustError` for anything else."""
        if not isinstance(cn, str) or len(cn) > 16:
            raise TrustError(f"common name {str(cn)[:32]!r} names no fleet identity")
        m = _ROBOT_CN.fullmatch(cn)
        if m:
            rid = int(m.group(1))
            if rid > MAX_ROBOT_ID:
                raise TrustError(f"common name {cn!r}: robot id outside [0, {MAX_ROBOT_ID}]")
            return cls.robot(rid)
        if cn in ("world", "observer", "router"):
            return cls(cn)
        raise TrustError(f"common name {cn!r} names no fleet identity")


# --------------------------------------------------------------------------- the folder


@dataclass(frozen=True)
class FleetPaths:
    """Where a credentials folder keeps each file (see the module docstring)."""

    root: Path

    @property
    def ca(self) -> Path:
        return self.root / "ca.pem"

    @property
    def ca_key(self) -> Path:
        return self.root / "ca-private" / "ca.key"

    @property
    def certs(self) -> Path:
        return self.root / "certs"

    @property
    def keys(self) -> Path:
        return self.root / "keys"

    def cert(self, who: Identity) -> Path:
        return self.certs / f"{who.cn}.pem"

    def key(self, who: Identity) -> Path:
        return self.keys / f"{who.cn}.key"


def _name(cn: str) -> x509.Name:
    return x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "nao-formation fleet"),
            x509.NameAttribute(NameOID.COMMON_NAME, cn),
        ]
    )


def _write(path: Path, data: bytes, private: bool) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if private:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
    else:
        path.write_bytes(data)


def _pem_key(key: ed25519.Ed25519PrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )


def create_fleet(
    out: Path | str,
    robot_ids: Iterable[int],
    hosts: Iterable[str] = (),
    valid_days: int = 365,
    now: datetime.datetime | None = None,
) -> FleetPaths:
    """Create a fleet CA and a key and certificate for every identity under ``out``.

    ``robot_ids`` get ``robot-{id}``; ``world``, ``observer`` and ``router`` are always
    made. ``hosts`` are extra DNS names or IP addresses the router is reached at
    (``localhost``, ``127.0.0.1`` and ``router`` are always included: zenoh checks the
    router's name on connect). Refuses a folder that already holds a fleet.
    """
    paths = FleetPaths(Path(out))
    if paths.ca.exists():
        raise ValueError(f"{paths.root} already holds a fleet (ca.pem); use another folder")
    ids = sorted({int(r) for r in robot_ids})
    if not ids:
        raise ValueError("a fleet needs at least one robot id")
    if not 1 <= valid_days <= 3650:
        raise ValueError(f"valid_days {valid_days} outside [1, 3650]")
    now = now or datetime.datetime.now(datetime.UTC)
    start, end = now - datetime.timedelta(hours=1), now + datetime.timedelta(days=valid_days)
    ca_key = ed25519.Ed25519PrivateKey.generate()
    ca_name = _name("nao-formation fleet CA")
    ca = (
        x509.CertificateBuilder()
        .subject_name(ca_name)
        .issuer_name(ca_name)
        .public_key(ca_key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start)
        .not_valid_after(end)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                key_cert_sign=True,
                crl_sign=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .sign(ca_key, None)
    )
    names: list[x509.GeneralName] = []
    for h in ("localhost", "router", "127.0.0.1", *hosts):
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            names.append(x509.DNSName(h))
    who = [Identity.robot(r) for r in ids] + [Identity(r) for r in ("world", "observer", "router")]
    for ident in who:
        key = ed25519.Ed25519PrivateKey.generate()
        builder = (
            x509.CertificateBuilder()
            .subject_name(_name(ident.cn))
            .issuer_name(ca_name)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(start)
            .not_valid_after(end)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(
                x509.ExtendedKeyUsage(
                    [ExtendedKeyUsageOID.CLIENT_AUTH, ExtendedKeyUsageOID.SERVER_AUTH]
                ),
                critical=False,
            )
        )
        # Every certificate names the router's hosts: zenoh verifies the listener's name,
        # and in a router chain any process may be the listening side.
        builder = builder.add_extension(x509.SubjectAlternativeName(names), critical=False)
        cert = builder.sign(ca_key, None)
        _write(paths.key(ident), _pem_key(key), private=True)
        _write(paths.cert(ident), cert.public_bytes(serialization.Encoding.PEM), private=False)
    _write(paths.ca_key, _pem_key(ca_key), private=True)
    _write(paths.ca, ca.public_bytes(serialization.Encoding.PEM), private=False)
    return paths


def _load_cert(path: Path, ca: x509.Certificate, now: datetime.datetime) -> x509.Certificate:
    try:
        cert = x509.load_pem_x509_certificate(path.read_bytes())
    except (OSError, ValueError) as exc:
        raise TrustError(f"{path}: not a PEM certificate: {exc}") from None
    try:
        cert.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature):
        raise TrustError(f"{path}: not issued by this fleet's CA") from None
    if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
        raise TrustError(f"{path}: certificate expired or not yet valid")
    if not isinstance(cert.public_key(), ed25519.Ed25519PublicKey):
        raise TrustError(f"{path}: not an Ed25519 certificate")
    return cert


def _cn(cert: x509.Certificate) -> str:
    attrs = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    if len(attrs) != 1:
        raise TrustError("certificate has no single common name")
    value = attrs[0].value
    return value if isinstance(value, str) else value.decode("ascii", "replace")


class Credentials:
    """A credentials folder, checked: the CA, the roster, and the private keys present.

    The roster holds every certificate under ``certs/`` that the fleet CA issued, is
    valid now and names a fleet identity; anything else is refused with the reason (a
    forged or foreign certificate must not widen the fleet).
    """

    def __init__(self, root: Path | str, now: datetime.datetime | None = None) -> None:
        self.paths = FleetPaths(Path(root))
        now = now or datetime.datetime.now(datetime.UTC)
        try:
            self.ca = x509.load_pem_x509_certificate(self.paths.ca.read_bytes())
        except (OSError, ValueError) as exc:
            raise TrustError(f"no fleet CA at {self.paths.ca}: {exc}") from None
        self.roster: dict[Identity, ed25519.Ed25519PublicKey] = {}
        if not self.paths.certs.is_dir():
            raise TrustError(f"no roster folder {self.paths.certs}")
        for path in sorted(self.paths.certs.glob("*.pem")):
            cert = _load_cert(path, self.ca, now)
            ident = Identity.parse(_cn(cert))
            if path.name != f"{ident.cn}.pem":
                raise TrustError(f"{path}: certificate names {ident.cn!r}, not its file name")
            pub = cert.public_key()
            assert isinstance(pub, ed25519.Ed25519PublicKey)
            self.roster[ident] = pub

    @property
    def root(self) -> Path:
        return self.paths.root

    def robots(self) -> list[int]:
        """Robot ids of the roster, sorted."""
        return sorted(i.robot_id for i in self.roster if i.role == "robot")

    def own_robot_keys(self) -> list[int]:
        """Robot ids whose private key this folder holds, sorted (for ``--id auto``)."""
        return [r for r in self.robots() if self.paths.key(Identity.robot(r)).is_file()]

    def signer(self, who: Identity, epoch_ms: int | None = None) -> Signer:
        """The :class:`Signer` of ``who``: its private key, checked against its certificate."""
        path = self.paths.key(who)
        try:
            key = serialization.load_pem_private_key(path.read_bytes(), password=None)
        except (OSError, ValueError, TypeError) as exc:
            raise TrustError(f"no usable private key for {who.cn} at {path}: {exc}") from None
        if not isinstance(key, ed25519.Ed25519PrivateKey):
            raise TrustError(f"{path}: not an Ed25519 key")
        pub = self.roster.get(who)
        raw = serialization.Encoding.Raw, serialization.PublicFormat.Raw
        if pub is None or pub.public_bytes(*raw) != key.public_key().public_bytes(*raw):
            raise TrustError(f"{path}: the key does not match {who.cn}'s certificate")
        return Signer(who, key, epoch_ms)

    def verifier(self, max_age: float = MAX_AGE_S) -> Verifier:
        return Verifier(self.roster, max_age=max_age)


# --------------------------------------------------------------------------- envelope


def _signed_bytes(key: str, by: int, epoch: int, seq: int, dt: int, bind: bytes, p: bytes) -> bytes:
    head = msgpack.packb([key, by, epoch, seq, dt, bind], use_bin_type=True)
    assert isinstance(head, bytes)
    return SIGNATURE_CONTEXT + head + p


class Signer:
    """Seals payloads for one identity: epoch (ms), sequence numbers, signatures.

    Thread-safe: sequence numbers are unique and increasing per signer.
    """

    def __init__(
        self,
        who: Identity,
        key: ed25519.Ed25519PrivateKey,
        epoch_ms: int | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.who = who
        self._key = key
        self.clock = clock
        self.epoch = int(epoch_ms if epoch_ms is not None else clock() * 1000)
        self._seq = 0
        self._lock = threading.Lock()

    def seal(self, key: str, payload: bytes, bind: bytes = b"") -> bytes:
        """The envelope of ``payload`` for ``key`` (``bind``: the request it answers)."""
        return self.seal_request(key, payload, bind)[0]

    def seal_request(self, key: str, payload: bytes, bind: bytes = b"") -> tuple[bytes, bytes]:
        """The envelope, and the nonce its replies must bind to (:attr:`Opened.nonce`)."""
        with self._lock:
            self._seq += 1
            seq = self._seq
        dt = max(0, int(self.clock() * 1000) - self.epoch)  # ms since the epoch: compact
        by = self.who.code
        sig = self._key.sign(_signed_bytes(key, by, self.epoch, seq, dt, bind, payload))
        data = msgpack.packb(
            [ENVELOPE_VERSION, by, self.epoch, seq, dt, payload, sig], use_bin_type=True
        )
        assert isinstance(data, bytes)
        return data, _nonce(self.who.cn, self.epoch, seq)


def _nonce(cn: str, epoch: int, seq: int) -> bytes:
    data = msgpack.packb([cn, epoch, seq], use_bin_type=True)
    assert isinstance(data, bytes)
    return data


@dataclass(frozen=True)
class Opened:
    """A verified envelope: who signed it, when, and the payload."""

    who: Identity
    epoch: int
    seq: int
    payload: bytes

    @property
    def nonce(self) -> bytes:
        """What a reply to this request binds to."""
        return _nonce(self.who.cn, self.epoch, self.seq)


@dataclass
class _Window:
    epoch: int
    top: int
    seen: set[int] = field(default_factory=set)


class Verifier:
    """Opens envelopes: signature by a roster member, freshness, no replays.

    Replay state is kept only for roster members (bounded by the roster), each a set of
    at most :data:`REPLAY_WINDOW` sequence numbers.
    """

    def __init__(
        self,
        roster: dict[Identity, ed25519.Ed25519PublicKey],
        max_age: float = MAX_AGE_S,
        clock: Callable[[], float] = time.time,
        window: int = REPLAY_WINDOW,
    ) -> None:
        if not max_age > 0:
            raise ValueError(f"max_age {max_age} must be > 0")
        self.roster = dict(roster)
        self.max_age = max_age
        self.clock = clock
        self.window = window
        self._state: dict[Identity, dict[int, _Window]] = {}
        self._lock = threading.Lock()

    def open(self, key: str, data: bytes, bind: bytes = b"", replay: bool = True) -> Opened:
        """Check and unwrap one envelope received on ``key``; :class:`TrustError` if not.

        ``bind`` must equal what the signer bound (a reply: the request's nonce).
        ``replay=False`` skips the replay window (replies, which their binding already
        makes unique).
        """
        obj = unpack_bounded(data, MAX_SEALED_BYTES, max_bin_bytes=MAX_MESSAGE_BYTES)
        if not isinstance(obj, list) or len(obj) != 7:
            raise TrustError("not a sealed envelope (unsigned or foreign payload)")
        v, by, e, n, dt, p, s = obj
        if type(v) is not int or v != ENVELOPE_VERSION:
            raise TrustError(f"envelope version {v!r}, this build speaks {ENVELOPE_VERSION}")
        for name, num in (("epoch", e), ("sequence", n), ("timestamp", dt)):
            if type(num) is not int or not 0 <= num < 2**62:
                raise TrustError(f"envelope {name} is not a non-negative int")
        if not isinstance(p, bytes) or not isinstance(s, bytes) or len(s) != 64:
            raise TrustError("envelope payload or signature malformed")
        who = Identity.from_code(by)
        if who not in self.roster:
            raise TrustError(f"signer {who.cn} is not in the fleet roster")
        try:
            self.roster[who].verify(s, _signed_bytes(key, by, e, n, dt, bind, p))
        except InvalidSignature:
            raise TrustError(f"bad signature from {who.cn} on {key}") from None
        age = self.clock() - (e + dt) / 1000.0
        if abs(age) > self.max_age:
            raise TrustError(
                f"stale message from {who.cn}: {age:+.1f} s old (limit {self.max_age:g})"
            )
        if replay:
            self._check_replay(who, e, n)
        return Opened(who, e, n, p)

    def _check_replay(self, who: Identity, epoch: int, seq: int) -> None:
        with self._lock:
            epochs = self._state.setdefault(who, {})
            st = epochs.get(epoch)
            if st is None:
                if len(epochs) >= EPOCHS_KEPT and epoch < min(epochs):
                    raise TrustError(f"replay from {who.cn}: epoch {epoch} is older than kept")
                epochs[epoch] = _Window(epoch, seq, {seq})
                while len(epochs) > EPOCHS_KEPT:
                    del epochs[min(epochs)]
                return
            if seq in st.seen or seq <= st.top - self.window:
                raise TrustError(f"replay from {who.cn}: sequence {seq} already seen or too old")
            st.seen.add(seq)
            if seq > st.top:
                st.top = seq
                if len(st.seen) > self.window:
                    floor = st.top - self.window
                    st.seen = {x for x in st.seen if x > floor}


# --------------------------------------------------------------------------- zenoh settings


def tls_settings(creds: Credentials, who: Identity) -> dict[str, Any]:
    """zenoh ``transport/link/tls``: mutual TLS against the fleet CA with ``who``'s key."""
    key, cert = str(creds.paths.key(who)), str(creds.paths.cert(who))
    return {
        "root_ca_certificate": str(creds.paths.ca),
        "enable_mtls": True,
        "listen_private_key": key,
        "listen_certificate": cert,
        "connect_private_key": key,
        "connect_certificate": cert,
        "verify_name_on_connect": True,
    }


_ALL = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
]


def _rule(rid: str, messages: list[str], flows: list[str], keys: list[str]) -> dict[str, Any]:
    return {
        "id": rid,
        "messages": messages,
        "flows": flows,
        "permission": "allow",
        "key_exprs": keys,
    }


def acl_settings(roster: Iterable[Identity]) -> dict[str, Any]:
    """zenoh ``access_control`` for a router: deny by default, each common name its role.

    Ingress is what a subject may send; egress what the router may deliver to it.
    """
    rules = [
        # every fleet member may watch membership and hear the fleet's statuses
        _rule("hear-fleet", ["declare_subscriber"], ["ingress"], ["nao/**", "world/clock"]),
        _rule(
            "watch-alive",
            ["declare_liveliness_subscriber", "liveliness_query"],
            ["ingress"],
            ["nao/alive/*"],
        ),
        _rule(
            "deliver-fleet",
            ["put", "liveliness_token", "declare_subscriber"],
            ["egress"],
            ["nao/**", "world/clock"],
        ),
        # the agreed record sets (issue #9): any member asks, every robot serves its own
        _rule("ask-records", ["query"], ["ingress"], [KEY_RECORDS_ALL]),
        _rule(
            "deliver-records",
            ["query", "reply", "declare_queryable"],
            ["egress"],
            [KEY_RECORDS_ALL],
        ),
        # the world: serves and publishes world/**, hears membership
        _rule("world-serve", ["declare_queryable", "reply", "put"], ["ingress"], ["world/**"]),
        _rule("world-take", ["query", "declare_subscriber"], ["egress"], ["world/**"]),
        # observers: evaluation reads ground truth too
        _rule("observe", ["declare_subscriber"], ["ingress"], ["world/**"]),
        _rule("observe-deliver", ["put"], ["egress"], ["world/**"]),
    ]
    subjects = [
        {"id": "world", "cert_common_names": ["world"]},
        {"id": "observer", "cert_common_names": ["observer"]},
        {"id": "members", "cert_common_names": sorted(i.cn for i in roster if i.role != "router")},
    ]
    policies = [
        {
            "id": "members",
            "rules": [
                "hear-fleet",
                "watch-alive",
                "deliver-fleet",
                "ask-records",
                "deliver-records",
            ],
            "subjects": ["members"],
        },
        {"id": "world", "rules": ["world-serve", "world-take"], "subjects": ["world"]},
        {"id": "observer", "rules": ["observe", "observe-deliver"], "subjects": ["observer"]},
    ]
    for who in sorted(roster):
        if who.role != "robot":
            continue
        i = who.robot_id
        rules += [
            _rule(f"r{i}-out", ["put"], ["ingress"], [f"nao/{i}/**"]),
            _rule(f"r{i}-alive", ["liveliness_token"], ["ingress"], [f"nao/alive/{i}"]),
            _rule(f"r{i}-serve", ["declare_queryable", "reply"], ["ingress"], [f"nao/{i}/records"]),
            _rule(f"r{i}-ask", ["query"], ["ingress"], [f"world/robot/{i}/**", "world/register"]),
            _rule(
                f"r{i}-answer",
                ["reply", "declare_queryable"],
                ["egress"],
                [f"world/robot/{i}/**", "world/register"],
            ),
        ]
        subjects.append({"id": who.cn, "cert_common_names": [who.cn]})
        policies.append(
            {
                "id": who.cn,
                "rules": [
                    f"r{i}-out",
                    f"r{i}-alive",
                    f"r{i}-serve",
                    f"r{i}-ask",
                    f"r{i}-answer",
                ],
                "subjects": [who.cn],
            }
        )
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }
