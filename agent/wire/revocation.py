"""The fleet's revocation list (docs/design.md §8 "Trust"; RFC 5280 §5, the X.509 CRL): the
certificates the fleet CA has withdrawn before they expire (a stolen or retired robot).

``crl.pem`` in a credentials folder is public and signed by the fleet CA; it lists the
withdrawn certificates' serial numbers, each with a date and an RFC 5280 reason. This
module reads one (checked against the CA: a list the CA did not sign, or one that cannot
be read, is a :class:`TrustError`, so a process fails closed rather than trusting keys
it was told to drop) and builds one (``cryptography``'s ``CertificateRevocationListBuilder``;
no hand-written crypto). :mod:`agent.wire.credentials` applies it.
"""

from __future__ import annotations

import datetime
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric import ed25519

from agent.wire.identity import TrustError

#: The reasons ``tools.fleet revoke --reason`` accepts, as RFC 5280 §5.3.1 reason codes.
REASONS: dict[str, x509.ReasonFlags] = {
    "unspecified": x509.ReasonFlags.unspecified,
    "key-compromise": x509.ReasonFlags.key_compromise,
    "retired": x509.ReasonFlags.cessation_of_operation,
    "superseded": x509.ReasonFlags.superseded,
    "affiliation-changed": x509.ReasonFlags.affiliation_changed,
}
_NAMES = {flag: name for name, flag in REASONS.items()}


@dataclass(frozen=True)
class Revocation:
    """One withdrawn certificate: its serial number, since when, and why."""

    serial: int
    date: datetime.datetime
    reason: str = "unspecified"

    def __post_init__(self) -> None:
        if self.reason not in REASONS:
            raise ValueError(f"reason {self.reason!r} is not one of {', '.join(REASONS)}")

    def describe(self) -> str:
        return f"{self.reason}, since {self.date:%Y-%m-%d %H:%M} UTC"


@dataclass(frozen=True)
class RevocationList:
    """A checked revocation list: its number (increasing per issue) and entries by serial."""

    number: int = 0
    entries: Mapping[int, Revocation] = field(default_factory=dict)

    def of(self, cert: x509.Certificate) -> Revocation | None:
        """The revocation of ``cert``, or None when it is not revoked."""
        return self.entries.get(cert.serial_number)


def _entry(rc: x509.RevokedCertificate) -> Revocation:
    reason = "unspecified"
    for ext in rc.extensions:
        if isinstance(ext.value, x509.CRLReason):
            reason = _NAMES.get(ext.value.reason, "unspecified")
    return Revocation(rc.serial_number, rc.revocation_date_utc, reason)


def load_revocations(path: Path, ca: x509.Certificate, now: datetime.datetime) -> RevocationList:
    """The revocation list at ``path`` checked against the fleet CA ``ca``.

    No file: nothing is revoked. A file that is not a PEM CRL, is not signed by ``ca``,
    or is past its next update is a :class:`TrustError` (fail closed).
    """
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return RevocationList()
    except OSError as exc:
        raise TrustError(f"{path}: cannot read the revocation list: {exc}") from None
    try:
        crl = x509.load_pem_x509_crl(data)
    except ValueError as exc:
        raise TrustError(f"{path}: not a PEM revocation list: {exc}") from None
    ca_key = ca.public_key()
    if not isinstance(ca_key, ed25519.Ed25519PublicKey):
        raise TrustError("the fleet CA has no Ed25519 key")
    if crl.issuer != ca.subject or not crl.is_signature_valid(ca_key):
        raise TrustError(f"{path}: revocation list not signed by this fleet's CA")
    until = crl.next_update_utc
    if until is not None and now > until:
        raise TrustError(f"{path}: revocation list expired on {until:%Y-%m-%d}")
    try:
        number = crl.extensions.get_extension_for_class(x509.CRLNumber).value.crl_number
    except x509.ExtensionNotFound:
        number = 0
    entries = {rc.serial_number: _entry(rc) for rc in crl}
    return RevocationList(number, dict(sorted(entries.items())))


def build_revocations(
    ca: x509.Certificate,
    ca_key: ed25519.Ed25519PrivateKey,
    entries: Iterable[Revocation],
    number: int,
    now: datetime.datetime,
) -> bytes:
    """A PEM revocation list of ``entries`` signed by the fleet CA, valid until the CA is.

    ``number`` is the CRL number (RFC 5280 §5.2.3): one more than the list it replaces.
    """
    builder = (
        x509.CertificateRevocationListBuilder()
        .issuer_name(ca.subject)
        .last_update(now)
        .next_update(max(now, ca.not_valid_after_utc))
        .add_extension(x509.CRLNumber(number), critical=False)
    )
    for e in sorted(entries, key=lambda r: r.serial):
        rc = (
            x509.RevokedCertificateBuilder()
            .serial_number(e.serial)
            .revocation_date(e.date)
            .add_extension(x509.CRLReason(REASONS[e.reason]), critical=False)
            .build()
        )
        builder = builder.add_revoked_certificate(rc)
    return builder.sign(ca_key, None).public_bytes(serialization.Encoding.PEM)
