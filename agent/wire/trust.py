"""Fleet trust (docs/design.md §8): credentials, the signed envelope, TLS and access control.

Three layers, each useful without the others:

1. **Fleet credentials.** One Ed25519 fleet CA signs one certificate per identity:
   ``robot-{id}``, ``world``, ``observer``, ``router``, ``render``. The certificate's common name *is*
   the identity; the same Ed25519 key serves the TLS link and the end-to-end signatures.
   Layout of a credentials folder (``python -m tools.fleet init``)::

       ca.pem                 fleet CA certificate (public; every host)
       certs/{cn}.pem         every identity's certificate: the roster (public; every host)
       crl.pem                revoked certificates, signed by the CA (public; every host;
                              ``python -m tools.fleet revoke``, :mod:`agent.wire.revocation`)
       keys/{cn}.key          private keys: a host gets only its own
       ca-private/ca.key      the CA's private key: keep it offline

   A revoked certificate leaves the roster: no verifier trusts its signatures (not even
   ones made before the revocation), the router's access control has no rule for its
   common name, and a process holding it refuses to start.

2. **Transport.** Every zenoh link is TLS with mutual authentication against the fleet
   CA (:func:`tls_settings`), and the router's access control (:func:`acl_settings`) gives
   each common name its role: robot i publishes ``nao/i/**``, declares ``nao/alive/i``,
   serves ``nao/i/records`` (the agreed record sets, any member may ask) and
   queries ``world/robot/i/**`` and ``world/register``; the world serves ``world/**``;
   render workers (cameras drawn by other processes) serve ``world/robot/*/camera``, ask
   ``world/scenario`` and follow ``world/truth/poses``; observers only subscribe.

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
consistency check (``agent/core/formation/frame/neighbour_check.py``) is the defence there.

This module uses ``cryptography`` only (no hand-written crypto) and is part of the wire
contract: ``sim/`` reaches it through ``agent.wire``. The three layers live in
:mod:`agent.wire.credentials` (with :mod:`agent.wire.revocation`), :mod:`agent.wire.access`
and :mod:`agent.wire.envelope`;
this module gathers their public names.
"""

from agent.wire.access import acl_settings, tls_settings
from agent.wire.credentials import CertificateRevoked, Credentials, FleetPaths, create_fleet, revoke
from agent.wire.envelope import (
    ENVELOPE_VERSION,
    EPOCHS_KEPT,
    MAX_AGE_S,
    MAX_SEALED_BYTES,
    REPLAY_WINDOW,
    SIGNATURE_CONTEXT,
    Opened,
    Signer,
    Verifier,
)
from agent.wire.identity import ROLES, Identity, TrustError
from agent.wire.revocation import REASONS, Revocation, RevocationList

__all__ = [
    "ENVELOPE_VERSION",
    "EPOCHS_KEPT",
    "MAX_AGE_S",
    "MAX_SEALED_BYTES",
    "REASONS",
    "REPLAY_WINDOW",
    "ROLES",
    "SIGNATURE_CONTEXT",
    "CertificateRevoked",
    "Credentials",
    "FleetPaths",
    "Identity",
    "Opened",
    "Revocation",
    "RevocationList",
    "Signer",
    "TrustError",
    "Verifier",
    "acl_settings",
    "create_fleet",
    "revoke",
    "tls_settings",
]
