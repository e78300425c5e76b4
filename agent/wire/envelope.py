"""The signed envelope (docs/design.md §8 "Trust", layer 3: end to end).

Every payload travels sealed (:meth:`Signer.seal`): a msgpack array ``[1, signer, epoch,
seq, dt, payload, signature]``. :class:`Verifier` checks the signature against the
roster, the age and replays. See :mod:`agent.wire.trust` for the whole picture.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import msgpack
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives.asymmetric import ed25519

from agent.wire.codec import unpack_bounded
from agent.wire.fields import MAX_MESSAGE_BYTES
from agent.wire.identity import Identity, TrustError

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

    ``revoked`` names identities whose key the fleet CA has withdrawn
    (:mod:`agent.wire.revocation`): they are never trusted, even when also in ``roster``,
    and their envelopes are refused, including ones captured before the revocation.
    Replay state is kept only for roster members (bounded by the roster), each a set of
    at most twice :data:`REPLAY_WINDOW` sequence numbers: the numbers at or below the
    window's floor are refused by the floor itself, so the set is pruned to the window only
    once it holds twice as many, which costs a message O(1) on average (pruning it at
    every message past the window would cost each message of a member that has sent
    1024 a pass over 1024 numbers, ~0.2 ms of CPU).
    """

    def __init__(
        self,
        roster: dict[Identity, ed25519.Ed25519PublicKey],
        max_age: float = MAX_AGE_S,
        clock: Callable[[], float] = time.time,
        window: int = REPLAY_WINDOW,
        revoked: Iterable[Identity] = (),
    ) -> None:
        if not max_age > 0:
            raise ValueError(f"max_age {max_age} must be > 0")
        self.revoked = frozenset(revoked)
        self.roster = {who: key for who, key in roster.items() if who not in self.revoked}
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
        if who in self.revoked:
            raise TrustError(f"signer {who.cn}'s key is revoked by the fleet CA")
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
                if len(st.seen) > 2 * self.window:  # amortised: see the class docstring
                    floor = st.top - self.window
                    st.seen = {x for x in st.seen if x > floor}
