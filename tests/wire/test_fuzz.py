"""Property-based fuzz of the wire codec (every input hardened): nothing but ProtocolError leaves
decode.

Each hypothesis example draws a seed and runs a batch of ``BATCH`` mutants of one message
type through :func:`agent.wire.decode` (generators of :mod:`tools.lib.fuzz_payloads`, shared
with ``python -m tools.fuzz``), so that CI sees ``EXAMPLES * BATCH`` = 20 000 hostile
payloads per type in a few seconds; pure-hypothesis strategies add structures hypothesis
can shrink.
Derandomized: the same inputs on every run, no flakiness.
"""

from __future__ import annotations

import contextlib

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from agent import wire as P
from tools import fuzz
from tools.lib import fuzz_payloads

BATCH = 500
EXAMPLES = 40
PER_TYPE = BATCH * EXAMPLES

CI = settings(
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)


def only_protocol_errors(data: bytes, expect: type[P.Message] | None = None) -> bool:
    """True if ``data`` decodes, False if it is rejected; anything else fails the test."""
    try:
        P.decode(data, expect)
        return True
    except P.ProtocolError:
        return False


@pytest.mark.parametrize("tag", fuzz_payloads.TAGS)
@settings(CI, max_examples=EXAMPLES)
@given(seed=st.integers(0, 2**32 - 1))
def test_mutants_of_every_type_raise_only_protocol_error(tag: str, seed: int) -> None:
    c = fuzz.TypeCounts()
    for data in fuzz_payloads.payloads(seed, tag, BATCH):
        fuzz.decode_one(data, c)
    assert c.crashed == 0, c.crashes
    assert c.accepted + c.rejected == BATCH


def test_ci_runs_20000_payloads_per_type() -> None:
    assert PER_TYPE >= 20_000
    assert set(fuzz_payloads.TAGS) == set(P.message_types())


def test_the_mutants_are_neither_all_valid_nor_all_garbage() -> None:
    res = fuzz.fuzz(len(fuzz_payloads.TAGS) * 600, seed=3)
    for tag, c in res.items():
        assert c.crashed == 0, c.crashes
        assert c.accepted > 10 and c.rejected > 300, (tag, vars(c))


msgpack_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.floats()
    | st.text(max_size=12)
    | st.binary(max_size=12),
    lambda inner: (
        st.lists(inner, max_size=6)
        | st.dictionaries(st.text(max_size=4) | st.binary(max_size=3), inner, max_size=4)
    ),
    max_leaves=12,
)
FIELD_NAMES = sorted({f for cls in P.message_types().values() for f in cls.SCHEMA})


@settings(CI, max_examples=600)
@given(
    tag=st.sampled_from(fuzz_payloads.TAGS) | st.text(max_size=8),
    version=st.sampled_from([1, 1, 1, True, 1.0, 2, "1", None]),
    fields=st.dictionaries(
        st.sampled_from(FIELD_NAMES) | st.text(max_size=6) | st.binary(max_size=4),
        msgpack_values,
        max_size=10,
    ),
    use_bin_type=st.booleans(),
)
def test_hypothesis_maps_raise_only_protocol_error(
    tag: str, version: object, fields: dict[object, object], use_bin_type: bool
) -> None:
    data = msgpack.packb({"v": version, "t": tag, **fields}, use_bin_type=use_bin_type)
    if only_protocol_errors(data):
        assert version == 1 and type(version) is int
    for cls in P.message_types().values():
        only_protocol_errors(data, cls)


@settings(CI, max_examples=2000)
@given(data=st.binary(max_size=300))
def test_hypothesis_bytes_raise_only_protocol_error(data: bytes) -> None:
    only_protocol_errors(data)
    with contextlib.suppress(P.ProtocolError):
        P.unpack_bounded(data)


@settings(CI, max_examples=200)
@given(obj=msgpack_values)
def test_unpack_bounded_round_trips_what_fits(obj: object) -> None:
    data = msgpack.packb(obj, use_bin_type=True)
    try:
        out = P.unpack_bounded(data)
    except P.ProtocolError:
        return
    assert msgpack.packb(out, use_bin_type=True) == data


@pytest.mark.parametrize("key", ["nao/alive/{}", "nao/{}/record", "world/robot/{}/walk"])
@settings(CI, max_examples=300)
@given(raw=st.text(max_size=8).filter(lambda s: "/" not in s))
def test_key_ids_have_exactly_one_spelling(key: str, raw: str) -> None:
    try:
        rid = P.id_from_key(key.format(raw))
    except P.ProtocolError:
        return
    assert raw == str(rid) and 0 <= rid <= P.MAX_ROBOT_ID


def test_worst_payloads_stay_under_50_mb() -> None:
    for m in fuzz.memory():
        assert "CRASHED" not in m.outcome, m
        assert m.peak < fuzz.MEMORY_TARGET, m
        assert m.size <= P.MAX_MESSAGE_BYTES


def test_flood_requests_are_all_malformed() -> None:
    import random

    reqs = list(fuzz_payloads.malformed_requests(random.Random(1), 900))
    assert len(reqs) == 900
    kinds = {key.rsplit("/", 1)[-1] for key, _ in reqs}
    assert kinds == {"camera", "walk", "turn", "register"}
    for key, payload in reqs:
        assert not fuzz_payloads._world_accepts(key, payload) or "/9/" in key


def test_tool_prints_counts_and_meets_the_targets(capsys: pytest.CaptureFixture[str]) -> None:
    assert fuzz.main(["--n", "1400", "--no-memory", "--seed", "5"]) == 0
    out = capsys.readouterr().out
    assert "crashed" in out and "payloads/s" in out and "all targets met" in out
    assert fuzz.main(["--n", "-1"]) == 2


@pytest.mark.system
def test_flood_against_a_world_it_starts() -> None:
    # correctness only: every malformed request is answered and the valid one served;
    # the timing target is measured by python -m tools.fuzz --flood (10 000 requests)
    fr = fuzz.flood(None, n=300, seed=2)
    assert fr.finished == 300 and fr.error_replies == 300
    assert fr.during_s > 0 and len(fr.baseline_s) == 5
    assert "rejected=300" in fr.world_summary and "dropped=0" in fr.world_summary
