"""Stand-ins shared by the hardening tests (zenoh payloads that must not be copied)."""

from __future__ import annotations


class FakeZBytes:
    """A zenoh payload stand-in: its length is known, and copying it when it is too big
    fails the test (``to_bytes`` without ``data``)."""

    def __init__(self, n: int, data: bytes | None = None) -> None:
        self.n, self.data = n, data

    def __len__(self) -> int:
        return self.n

    def to_bytes(self) -> bytes:
        assert self.data is not None, "an oversized payload was copied"
        return self.data


def zb(data: bytes) -> FakeZBytes:
    """A payload that may be copied."""
    return FakeZBytes(len(data), data)
