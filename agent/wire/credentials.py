"""Fleet credentials (DESIGN.md §8 "Trust", layer 1): identities, the credentials folder,
creating a fleet, loading and checking certificates. See :mod:`agent.wire.trust`.
"""

from __future__ import annotations

import datetime
import ipaddress
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import ed25519
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from agent.wire.envelope import MAX_AGE_S, Signer, Verifier
from agent.wire.identity import Identity, TrustError

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
