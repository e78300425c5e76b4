"""tools/fit_noise.py's null scale of a test statistic (the bias test's, χ²₃, and the
heading test's, χ²₁): known answers; and its count of masks read the other way round."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from tools.corpus import runs_of
from tools.fit_noise import BIAS_QUANTILES, match, null_scale, reversal_by_view


@pytest.mark.parametrize("dof", [1, 3])
def test_a_statistic_with_the_chi2_tail_keeps_it(dof: int) -> None:
    stats = chi2.ppf(np.linspace(0.0005, 0.9995, 2000), dof)
    assert null_scale(stats, dof) == pytest.approx(1.0, abs=0.02)


def test_a_heavier_tail_is_scaled_by_its_worst_quantile_ratio() -> None:
    base = chi2.ppf(np.linspace(0.0005, 0.9995, 2000), 1)
    stats = np.where(base > chi2.isf(0.1, 1), 3.0 * base, base)  # the top 10 % tripled
    want = max(float(np.quantile(stats, q)) / float(chi2.isf(1 - q, 1)) for q in BIAS_QUANTILES)
    assert null_scale(stats, 1) == pytest.approx(want) and want > 2.5


def test_a_lighter_tail_or_none_is_one() -> None:
    assert null_scale(0.5 * chi2.ppf(np.linspace(0.01, 0.99, 99), 1), 1) == 1.0
    assert null_scale(np.array([]), 3) == 1.0


def test_the_excess_rate_counts_only_what_the_model_does_not_put_there() -> None:
    from tools.fit_noise import TURNED_P, excess_rate

    assert excess_rate(np.array([])) == 0.0
    assert excess_rate(np.full(500, 0.5)) == 0.0
    one = np.concatenate([np.full(499, 0.5), [1e-5]])  # 1 of 500, the model expects 0.5
    assert excess_rate(one) == 0.0
    many = np.concatenate([np.full(480, 0.5), np.full(20, 1e-5)])  # 20 of 500: a mechanism
    assert excess_rate(many) == pytest.approx((20 - 500 * TURNED_P) / 500)


def test_the_front_back_share_is_counted_on_masks_turned_back_by_times() -> None:
    """w180: of the masks turned back to their target's start heading, those read the
    other way round; masks of records without times say nothing of it and are not
    counted."""
    runs = runs_of(Path("tests/data/frames/n10_random_s1024.json"))
    flip = match(runs).flip
    counted = flip[np.isfinite(flip)]
    assert counted.size > 20 and set(np.unique(counted)) <= {0.0, 1.0}
    assert 0.05 < float(counted.mean()) < 0.5
    untimed = [replace(r, records=tuple(replace(m, seen_at=(), stances=()) for m in r.records))
               for r in runs]  # fmt: skip
    assert not np.isfinite(match(untimed).flip).any()


def test_the_front_back_share_by_reading_is_counted_per_bin() -> None:
    """reversal_by_view: per 30° bin of |θ| as read, (k + 1) / (n + 2) of the timed masks
    read the other way round; masks without times (nan) and without a reading left out;
    a bin without a mask keeps the overall rate."""
    deg = math.radians
    view = np.array([deg(10), deg(-20), deg(10), deg(100), deg(-170), math.pi, math.nan, deg(5)])
    flip = np.array([0.0, 1.0, 0.0, 1.0, 1.0, 1.0, 1.0, math.nan])
    got = reversal_by_view(flip, view, 0.25)
    assert got == pytest.approx((2 / 5, 0.25, 0.25, 2 / 3, 0.25, 3 / 4))
