"""Fleet credentials (docs/design.md §8 "Trust", layer 1): identities, the credentials folder,
creating a fleet, revoking a key, loading and checking certificates (issuer, validity
period, revocation: :mod:`agent.wire.revocation`). See :mod:`agent.wire.trust`.
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
from agent.wire.identity import ROLES, Identity, TrustError
from agent.wire.revocation import (
    REASONS,
    Revocation,
    RevocationList,
    build_revocations,
    load_revocations,
)

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
    def crl(self) -> Path:
        """The revocation list, signed by the CA (public; every host)."""
        return self.root / "crl.pem"

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

    ``robot_ids`` get ``robot-{id}``; ``world``, ``observer``, ``router`` and ``render``
    are always made. ``hosts`` are extra DNS names or IP addresses the router is reached at
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
    who = [Identity.robot(r) for r in ids] + [Identity(r) for r in ROLES[1:]]
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


class CertificateRevoked(TrustError):
    """A certificate of the fleet that the fleet's revocation list withdraws."""

    def __init__(self, message: str, cert: x509.Certificate, revocation: Revocation) -> None:
        super().__init__(message)
        self.cert = cert
        self.revocation = revocation


def _read_cert(path: Path, ca: x509.Certificate) -> x509.Certificate:
    try:
        cert = x509.load_pem_x509_certificate(path.read_bytes())
    except (OSError, ValueError) as exc:
        raise TrustError(f"{path}: not a PEM certificate: {exc}") from None
    try:
        cert.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature):
        raise TrustError(f"{path}: not issued by this fleet's CA") from None
    return cert


def _load_cert(
    path: Path,
    ca: x509.Certificate,
    now: datetime.datetime,
    revoked: RevocationList | None = None,
) -> x509.Certificate:
    cert = _read_cert(path, ca)
    if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
        raise TrustError(f"{path}: certificate expired or not yet valid")
    if not isinstance(cert.public_key(), ed25519.Ed25519PublicKey):
        raise TrustError(f"{path}: not an Ed25519 certificate")
    gone = revoked.of(cert) if revoked is not None else None
    if gone is not None:
        msg = f"{path}: certificate revoked by the fleet CA ({gone.describe()})"
        raise CertificateRevoked(msg, cert, gone)
    return cert


def _load_ca(paths: FleetPaths) -> x509.Certificate:
    try:
        return x509.load_pem_x509_certificate(paths.ca.read_bytes())
    except (OSError, ValueError) as exc:
        raise TrustError(f"no fleet CA at {paths.ca}: {exc}") from None


def _cn(cert: x509.Certificate) -> str:
    attrs = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    if len(attrs) != 1:
        raise TrustError("certificate has no single common name")
    value = attrs[0].value
    return value if isinstance(value, str) else value.decode("ascii", "replace")


def revoke(
    root: Path | str,
    who: Iterable[Identity],
    reason: str = "unspecified",
    now: datetime.datetime | None = None,
) -> list[Identity]:
    """Add the certificates of ``who`` to the fleet's revocation list (``crl.pem``).

    Needs the CA's private key (``ca-private/ca.key``). The list is re-signed with one
    more CRL number; a certificate already on it keeps its entry (idempotent). Returns
    the identities newly revoked, sorted; when there are none the file is left as it is.
    """
    if reason not in REASONS:
        raise ValueError(f"reason {reason!r} is not one of {', '.join(REASONS)}")
    paths = FleetPaths(Path(root))
    now = now or datetime.datetime.now(datetime.UTC)
    ca = _load_ca(paths)
    try:
        ca_key = serialization.load_pem_private_key(paths.ca_key.read_bytes(), password=None)
    except (OSError, ValueError, TypeError) as exc:
        raise ValueError(f"revoking needs the CA's private key at {paths.ca_key}: {exc}") from None
    raw = serialization.Encoding.Raw, serialization.PublicFormat.Raw
    ca_pub = ca.public_key()
    if (
        not isinstance(ca_key, ed25519.Ed25519PrivateKey)
        or not isinstance(ca_pub, ed25519.Ed25519PublicKey)
        or ca_key.public_key().public_bytes(*raw) != ca_pub.public_bytes(*raw)
    ):
        raise TrustError(f"{paths.ca_key} is not the private key of {paths.ca}")
    current = load_revocations(paths.crl, ca, now)
    entries = dict(current.entries)
    added: list[Identity] = []
    for ident in sorted(set(who)):
        cert = _read_cert(paths.cert(ident), ca)
        if _cn(cert) != ident.cn:
            raise TrustError(f"{paths.cert(ident)}: certificate names {_cn(cert)!r}")
        if cert.serial_number not in entries:
            entries[cert.serial_number] = Revocation(cert.serial_number, now, reason)
            added.append(ident)
    if added:
        pem = build_revocations(ca, ca_key, entries.values(), current.number + 1, now)
        tmp = paths.crl.with_name(paths.crl.name + ".tmp")
        _write(tmp, pem, private=False)
        os.replace(tmp, paths.crl)
    return added


class Credentials:
    """A credentials folder, checked: the CA, the roster, and the private keys present.

    The roster holds every certificate under ``certs/`` that the fleet CA issued, is
    valid now, is not revoked and names a fleet identity; anything else is refused with
    the reason (a forged or foreign certificate must not widen the fleet). Revoked
    certificates are left out of the roster and listed in :attr:`revoked`; a revocation
    list (``crl.pem``) the CA did not sign, or that cannot be read, is refused.
    """

    def __init__(self, root: Path | str, now: datetime.datetime | None = None) -> None:
        self.paths = FleetPaths(Path(root))
        now = now or datetime.datetime.now(datetime.UTC)
        self.ca = _load_ca(self.paths)
        self.revocations = load_revocations(self.paths.crl, self.ca, now)
        self.roster: dict[Identity, ed25519.Ed25519PublicKey] = {}
        #: Identities whose certificate under ``certs/`` the revocation list withdraws.
        self.revoked: dict[Identity, Revocation] = {}
        if not self.paths.certs.is_dir():
            raise TrustError(f"no roster folder {self.paths.certs}")
        for path in sorted(self.paths.certs.glob("*.pem")):
            try:
                cert = _load_cert(path, self.ca, now, self.revocations)
            except CertificateRevoked as exc:
                self.revoked[self._identity(path, exc.cert)] = exc.revocation
                continue
            pub = cert.public_key()
            assert isinstance(pub, ed25519.Ed25519PublicKey)
            self.roster[self._identity(path, cert)] = pub

    @staticmethod
    def _identity(path: Path, cert: x509.Certificate) -> Identity:
        ident = Identity.parse(_cn(cert))
        if path.name != f"{ident.cn}.pem":
            raise TrustError(f"{path}: certificate names {ident.cn!r}, not its file name")
        return ident

    def check_active(self, who: Identity) -> None:
        """Refuse to act as ``who`` when its certificate is revoked (a clear message)."""
        gone = self.revoked.get(who)
        if gone is not None:
            raise TrustError(
                f"{who.cn}'s certificate is revoked by the fleet CA ({gone.describe()}, "
                f"{self.paths.crl}): this key may no longer join the fleet"
            )

    @property
    def root(self) -> Path:
        return self.paths.root

    def robots(self) -> list[int]:
        """Robot ids of the roster, sorted."""
        return sorted(i.robot_id for i in self.roster if i.role == "robot")

    def own_robot_keys(self) -> list[int]:
        """Robot ids whose private key this folder holds, sorted (for ``--id auto``)."""
        return [r for r in self.robots() if self.paths.key(Identity.robot(r)).is_file()]

    def revoked_robot_keys(self) -> list[int]:
        """Robot ids whose private key this folder holds but whose certificate is revoked,
        sorted (``--id auto`` says so when these are all it has)."""
        ids = (i.robot_id for i in self.revoked if i.role == "robot")
        return sorted(r for r in ids if self.paths.key(Identity.robot(r)).is_file())

    def signer(self, who: Identity, epoch_ms: int | None = None) -> Signer:
        """The :class:`Signer` of ``who``: its private key, checked against its certificate."""
        self.check_active(who)
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
        return Verifier(self.roster, max_age=max_age, revoked=self.revoked)
