import json

import numpy as np
import pytest

from agent.core.perception.mbase import MBase, canonical, cut_mask
from tests.perception.synth import synthetic_mbase


def test_save_load_round_trip(tmp_path) -> None:  # type: ignore[no-untyped-def]
    mb = synthetic_mbase([0, 45, 90, 135])
    mb.save(tmp_path)
    back = MBase.load(tmp_path)
    assert back.digest() == mb.digest()
    assert len(back) == 4
    for a, b in zip(mb.masks, back.masks):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(back.centre_offset, mb.centre_offset)
    meta = json.loads((tmp_path / "mbase.json").read_text())
    assert meta["count"] == 4 and meta["synthetic"] is True


def test_tampered_file_is_rejected(tmp_path) -> None:  # type: ignore[no-untyped-def]
    synthetic_mbase([0, 90]).save(tmp_path)
    meta = json.loads((tmp_path / "mbase.json").read_text())
    meta["digest"] = "0" * 64
    (tmp_path / "mbase.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="digest"):
        MBase.load(tmp_path)
    meta["version"] = 0
    (tmp_path / "mbase.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match="version"):
        MBase.load(tmp_path)


def test_cut_mask_and_canonical() -> None:
    m = np.zeros((100, 200), np.uint8)
    m[40:50, 90:110] = 255
    m[60:70, 60:80] = 255
    cut = cut_mask(m, horizon_row=45.0, centre_col=100.0)
    assert cut.crop.shape == (30, 50) and cut.n_tuples == 2
    assert cut.top_offset == -5.0 and cut.centre_offset == pytest.approx(15.0)
    v = canonical(cut.crop)
    assert np.linalg.norm(v) == pytest.approx(1.0)


def test_bad_inputs(tmp_path) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match="at least one"):
        MBase([], [], [], [], [], [])
    with pytest.raises(ValueError, match="empty"):
        MBase([np.zeros((3, 3))], [0.0], [False], [3], [0.0], [0.0])
    with pytest.raises(ValueError, match="entries"):
        MBase([np.ones((3, 3))], [0.0, 1.0], [False], [3], [0.0], [0.0])
    with pytest.raises(ValueError, match="no M-base"):
        MBase.load(tmp_path)
    with pytest.raises(ValueError, match="no orange"):
        cut_mask(np.zeros((50, 50), np.uint8), 10.0, 25.0)
    with pytest.raises(ValueError, match="no foreground"):
        canonical(np.zeros((4, 4)))
