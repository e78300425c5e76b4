"""tools/bench/makespan.py: the start families (seeded, spaced, each seed its own layout),
the tuned-on and held-out sets (disjoint seeds, a family only held out), one fleet measured
(the lower bound below CAPT's makespan, the plan's clearance), the summary of appended rows
and the usage errors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.distance import pdist

from agent.core.formation.waves.gates import gated_makespan
from tools.bench import makespan as mk


@pytest.mark.parametrize("family", mk.FAMILIES)
def test_a_family_is_seeded_and_spaced(family: str) -> None:
    for n in (3, 15, 40):
        a, d_e = mk.starts(family, n, 1000)
        b, _ = mk.starts(family, n, 1000)
        np.testing.assert_array_equal(a, b)  # deterministic
        assert a.shape == (n, 2) and pdist(a).min() >= 0.4 - 1e-9  # 2·radius at least
        assert d_e == (0.8 if family == "nao" else 2.0)
    # another seed, another layout (not only another jitter)
    assert not np.allclose(mk.starts(family, 15, 0)[0], mk.starts(family, 15, 1)[0])


def test_the_held_out_set_shares_no_seed_and_holds_a_family_back() -> None:
    tuned, held, fresh = mk.SETS["tuned"], mk.SETS["held-out"], mk.SETS["fresh"]
    assert not set(tuned["seeds"]) & set(held["seeds"])
    # the second held-out set: the held-out families on seeds of no other set
    assert not set(fresh["seeds"]) & (set(tuned["seeds"]) | set(held["seeds"]))
    assert fresh["families"] == held["families"]
    assert set(held["families"]) - set(tuned["families"]) == {"clusters"}
    with pytest.raises(ValueError, match="unknown family"):
        mk.starts("spiral", 5, 0)


def test_one_fleet_measured(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    r = mk.evaluate("nao", 5, 0, "line")
    assert r["safe"] and r["lb"] <= r["capt"] + 1e-9 and r["makespan"] >= r["lb"] - 1e-9
    assert r["ms_capt"] == pytest.approx(r["makespan"] / r["capt"])
    # the critical chain adds up to the start-only makespan, its last robot walks its
    # whole path; holding only where needed never ends later than waiting at the start
    assert sum(x for _, _, x in r["chain"]) == pytest.approx(r["start_only"])
    assert r["makespan"] <= r["start_only"] + 1e-9
    assert r["chain"][-1][1] == r["chain"][-1][2]
    rows = tmp_path / "rows.jsonl"
    assert mk.main(["--set", "held-out", "--families", "nao", "--sizes", "4", "--seeds", "1",
                    "--shapes", "pyramid,wedge", "--json", str(rows), "--chain"]) == 0  # fmt: skip
    assert [json.loads(x)["shape"] for x in rows.read_text().splitlines()] == ["pyramid", "wedge"]
    capsys.readouterr()
    assert mk.main(["--summary", str(rows)]) == 0
    out = capsys.readouterr().out
    assert "shape wedge" in out and "all" in out and "unsafe: none" in out


def test_the_makespan_is_the_gated_one() -> None:
    # robot 1 crosses robot 0's path at right angles, both at arc 10, and waits for it
    # (start-only: until 0 is 2r past the crossing, then 1 walks its 20 m: 30.4); gated,
    # 1 walks at once and holds before 0's path until 0 is past the crossing's milestone
    paths = [np.array([[0.0, 0.0], [20.0, 0.0]]), np.array([[10.0, -10.0], [10.0, 10.0]])]
    after, waves = [[], [0]], np.array([0, 1])
    gated = gated_makespan(paths, after, waves, 0.4, 0.2, [[], [10.4]])
    assert 20.0 < gated <= 20.0 + 0.5 + 0.4 * math.sqrt(2.0) + 0.2 + 1e-9
    # nobody to wait for: each robot's own length
    assert gated_makespan(paths, [[], []], np.array([0, 0]), 0.4, 0.2) == pytest.approx(20.0)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--families", "clusters"], "not in the tuned set"),
        (["--families", "spiral"], "expected some of"),
        (["--shapes", "star"], "expected some of"),
        (["--sizes", "0"], "expected ints >= 1"),
    ],
)
def test_usage_errors(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        mk.main(argv)
    assert exc.value.code == 2 and message in capsys.readouterr().err
