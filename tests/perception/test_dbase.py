import json

import numpy as np
import pytest

from agent.core.perception.dbase import DBase, Fit, fit_distance_model


def test_fit_recovers_exact_model() -> None:
    d = np.linspace(0.5, 1.45, 20)
    rg = 0.5 / (d - 0.1)  # d = 0.5 / r_g + 0.1 (the paper's a, b)
    f = fit_distance_model(rg, d)
    assert f.a == pytest.approx(0.5, abs=1e-6)
    assert f.b == pytest.approx(0.1, abs=1e-6)
    assert f.r2 == pytest.approx(1.0)
    assert f.rmse < 1e-6 and f.n == 20


def test_fit_quality_on_noisy_samples() -> None:
    rng = np.random.default_rng(3)
    d = np.linspace(0.5, 1.45, 20)
    rg = 0.6 / d * (1 + rng.normal(0, 0.01, d.size))
    f = fit_distance_model(rg, d)
    assert 0.95 < f.r2 < 1.0
    assert 0.0 < f.rmse < 0.03


def test_distance_and_fallback(tmp_path) -> None:  # type: ignore[no-untyped-def]
    db = DBase([Fit(0.5, 0.1, 1.0, 0.0, 20), None, Fit(0.7, 0.1, 1.0, 0.0, 20)], "abc")
    assert db.distance(0, 0.5) == pytest.approx(1.1)
    assert db.coefficients(1).a == pytest.approx(0.6)  # median of the fitted masks
    db.save(tmp_path)
    back = DBase.load(tmp_path)
    assert back.mbase_digest == "abc" and back.fits[1] is None
    assert back.distance(2, 0.7) == pytest.approx(1.1)


def test_bad_inputs(tmp_path) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match="differ"):
        fit_distance_model(np.ones(3), np.ones(4))
    with pytest.raises(ValueError, match="at least 3"):
        fit_distance_model(np.ones(2), np.ones(2))
    with pytest.raises(ValueError, match="> 0"):
        fit_distance_model(np.array([1.0, 0.0, 2.0]), np.ones(3))
    with pytest.raises(ValueError, match="identifiable"):
        fit_distance_model(np.ones(4), np.arange(4.0))
    with pytest.raises(ValueError, match="at least one"):
        DBase([None], "x")
    db = DBase([Fit(0.5, 0.1, 1, 0, 3)], "x")
    with pytest.raises(ValueError, match="scale"):
        db.distance(0, 0.0)
    with pytest.raises(ValueError, match="mask index"):
        db.distance(1, 0.5)
    with pytest.raises(ValueError, match="no D-base"):
        DBase.load(tmp_path)
    (tmp_path / "dbase.json").write_text('{"version": 99}')
    with pytest.raises(ValueError, match="version"):
        DBase.load(tmp_path)


def test_offset_model_recovers_pixel_rim_over_a_wide_range() -> None:
    """Far away a blob loses a constant rim: r_g = k/d - δ; eq. 6 with offset c = δ fits it
    exactly, the paper's 2-parameter form does not (it is what a narrow range gives)."""
    d = np.linspace(0.5, 3.0, 30)
    rg = 0.45 / (d - 0.05) - 0.006
    f = fit_distance_model(rg, d)
    assert f.c == pytest.approx(0.006, abs=1e-4)
    assert f.a == pytest.approx(0.45, abs=1e-3) and f.b == pytest.approx(0.05, abs=1e-3)
    assert f.rmse < 1e-4 and f.distance(float(rg[-1])) == pytest.approx(3.0, abs=1e-3)
    paper = fit_distance_model(rg, d, offset=False)
    assert paper.c == 0.0 and paper.rmse > 10 * f.rmse
    narrow = fit_distance_model(rg[:6], d[:6])  # 0.5-0.95 m: c is not identifiable
    assert narrow.c == 0.0


def test_version_1_files_read_as_the_paper_model(tmp_path) -> None:  # type: ignore[no-untyped-def]
    doc = {
        "version": 1,
        "mbase_digest": "abc",
        "fits": [{"a": 0.5, "b": 0.1, "r2": 1.0, "rmse": 0.0, "n": 20}],
    }
    (tmp_path / "dbase.json").write_text(json.dumps(doc))
    db = DBase.load(tmp_path)
    assert db.fits[0] is not None and db.fits[0].c == 0.0
    assert db.distance(0, 0.5) == pytest.approx(1.1)
    with pytest.raises(ValueError, match="model range"):
        DBase([Fit(0.5, 0.1, 1, 0, 3, c=-0.2)], "x").distance(0, 0.1)


def test_scale_kind_height_or_algorithm_1() -> None:
    fit = [Fit(0.5, 0.1, 1.0, 0.0, 20)]
    paper = DBase(fit, "x")
    assert paper.scale_kind == "min" and paper.group_scale(0.4, 80, 200) == 0.4
    height = DBase(fit, "x", meta={"scale": "height"})
    assert height.group_scale(0.4, 80, 200) == pytest.approx(0.4 * 1.0)
    assert height.group_scale(0.3, 90, 200) == pytest.approx(0.45)
    with pytest.raises(ValueError, match="heights"):
        height.group_scale(0.3, 0, 200)
    with pytest.raises(ValueError, match="unknown D-base scale"):
        _ = DBase(fit, "x", meta={"scale": "area"}).scale_kind
