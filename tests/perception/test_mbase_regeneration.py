"""Regenerating the M-base with the tool gives the packaged file (same content digest)."""

from __future__ import annotations

from pathlib import Path

import pytest

from agent.core.perception.dbase import DBase
from agent.core.perception.mbase import MBase
from tools import build_mbase


@pytest.mark.slow  # rebuilds the packaged M-base from its renders: CI's slow tier
def test_packaged_mbase_regenerates_identically(tmp_path: Path) -> None:
    packaged = MBase.load()
    assert build_mbase.main(["--out", str(tmp_path)]) == 0
    fresh = MBase.load(tmp_path)
    assert fresh.digest() == packaged.digest()
    assert len(fresh) >= 72 and fresh.meta["step_deg"] == 5.0


def test_packaged_dbase_belongs_to_packaged_mbase() -> None:
    mb, db = MBase.load(), DBase.load()
    assert db.mbase_digest == mb.digest()
    assert len(db) == len(mb)
    fitted = [f for f in db.fits if f is not None and f.n > 0]
    assert len(fitted) >= 60
    assert min(f.r2 for f in fitted) > 0.99
    assert all(0.3 < f.a < 0.7 for f in fitted)
