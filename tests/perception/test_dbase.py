import numpy as np
import pytest

from agent.perception.dbase import DBase, Fit, fit_distance_model


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
