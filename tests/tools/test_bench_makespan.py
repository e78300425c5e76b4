"""tools/bench/makespan.py: the start families (seeded, spaced, each seed its own layout),
the tuned-on and held-out sets (disjoint seeds, a family only held out), one fleet measured
(the lower bound below CAPT's makespan, the plan's clearance), the summary of appended rows
and the usage errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.distance import pdist

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
    tuned, held = mk.SETS["tuned"], mk.SETS["held-out"]
    assert not set(tuned["seeds"]) & set(held["seeds"])
    assert set(held["families"]) - set(tuned["families"]) == {"clusters"}
    with pytest.raises(ValueError, match="unknown family"):
        mk.starts("spiral", 5, 0)


def test_one_fleet_measured(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    r = mk.evaluate("nao", 5, 0, "line")
    assert r["safe"] and r["lb"] <= r["capt"] + 1e-9 and r["makespan"] >= r["lb"] - 1e-9
    assert r["ms_capt"] == pytest.approx(r["makespan"] / r["capt"])
    # the critical chain adds up to the makespan, its last robot walks its whole path
    assert sum(x for _, _, x in r["chain"]) == pytest.approx(r["makespan"])
    assert r["chain"][-1][1] == r["chain"][-1][2]
    rows = tmp_path / "rows.jsonl"
    assert mk.main(["--set", "held-out", "--families", "nao", "--sizes", "4", "--seeds", "1",
                    "--shapes", "pyramid,wedge", "--json", str(rows), "--chain"]) == 0  # fmt: skip
    assert [json.loads(x)["shape"] for x in rows.read_text().splitlines()] == ["pyramid", "wedge"]
    capsys.readouterr()
    assert mk.main(["--summary", str(rows)]) == 0
    out = capsys.readouterr().out
    assert "shape wedge" in out and "all" in out and "unsafe: none" in out


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
