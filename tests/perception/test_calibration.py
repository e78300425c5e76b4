"""A calibration folder (agent/core/perception/calibration.py): written, read back with the
same digest, and every bad file named with what is wrong with it."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from agent.core.perception.calibration import (
    FILES,
    Calibration,
    CalibrationError,
    builtin,
    digest_of,
    load,
)
from agent.core.perception.dbase import DBase
from agent.core.perception.segmentation import ORANGE, OrangeRange

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def cal() -> Calibration:
    return builtin()


@pytest.fixture(scope="module")
def saved(cal: Calibration, tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("cal")
    cal.save(d, {"note": "the built-in calibration, saved"})
    return d


@pytest.fixture()
def folder(saved: Path, tmp_path: Path) -> Path:
    d = tmp_path / "cal"
    shutil.copytree(saved, d)
    return d


def _error(d: Path) -> str:
    with pytest.raises(CalibrationError) as exc:
        load(d)
    return str(exc.value)


def test_a_saved_folder_reads_back_with_the_same_digest(cal: Calibration, saved: Path) -> None:
    got = load(saved)
    assert got.digest == cal.digest and len(got.digest) == 64
    assert got.orange == ORANGE and got.source == str(saved)
    assert got.meta["note"] == "the built-in calibration, saved"
    assert json.loads((saved / "calibration.json").read_text())["digest"] == cal.digest


def test_the_digest_follows_the_content(cal: Calibration) -> None:
    other = OrangeRange((3, 170, 50), (10, 255, 255))
    assert digest_of(cal.mbase, cal.dbase, other) != cal.digest
    assert digest_of(cal.mbase, cal.dbase, ORANGE) == cal.digest


def test_not_a_folder(tmp_path: Path) -> None:
    assert "not a directory" in _error(tmp_path / "nowhere")


def test_every_missing_file_gets_a_line(tmp_path: Path) -> None:
    text = _error(tmp_path)
    assert len(text.splitlines()) == 1 + len(FILES)
    for name in FILES:
        assert f"{tmp_path / name}: missing" in text


@pytest.mark.parametrize(
    ("name", "content", "why"),
    [
        ("orange.json", "{", "not JSON"),
        ("orange.json", '{"hsv_low": [2, 170, 50], "hsv_high": [200, 255, 255]}', "hue"),
        ("orange.json", "[1, 2]", "hsv_low"),
        ("mbase.json", "nope", "not JSON"),
        ("mbase.npz", "not an archive", "mbase.npz: "),
        ("calibration.json", '{"version": 7}', "version 7"),
        ("calibration.json", "[]", "JSON object"),
    ],
)
def test_a_bad_file_is_named_with_the_reason(
    folder: Path, name: str, content: str, why: str
) -> None:
    (folder / name).write_text(content)
    text = _error(folder)
    line = next(ln for ln in text.splitlines() if f"{folder / name}:" in ln)
    assert why in line


def test_a_dbase_without_a_field_or_with_an_impossible_fit(folder: Path) -> None:
    doc = json.loads((folder / "dbase.json").read_text())
    k = next(i for i, f in enumerate(doc["fits"]) if f is not None)
    del doc["fits"][k]["a"]
    (folder / "dbase.json").write_text(json.dumps(doc))
    assert "dbase.json: no field 'a'" in _error(folder)
    doc["fits"][k]["a"] = -1.0
    (folder / "dbase.json").write_text(json.dumps(doc))
    assert "finite a > 0" in _error(folder)


def test_a_dbase_of_another_mbase(folder: Path, cal: Calibration) -> None:
    DBase(cal.dbase.fits, "0" * 64, dict(cal.dbase.meta)).save(folder)
    assert "another M-base" in _error(folder)


def test_a_file_changed_after_the_build_breaks_the_digest(folder: Path) -> None:
    (folder / "orange.json").write_text(json.dumps(OrangeRange((3, 170, 50)).to_dict()))
    text = _error(folder)
    assert "calibration.json: digest" in text and "changed after the build" in text
    assert len(text.splitlines()) == 2  # the one bad file


def test_a_calibration_for_another_camera(folder: Path) -> None:
    doc = json.loads((folder / "calibration.json").read_text())
    doc["camera"]["hfov_deg"] = 72.6
    (folder / "calibration.json").write_text(json.dumps(doc))
    assert "made for the camera" in _error(folder)


def test_two_bad_files_two_lines(folder: Path) -> None:
    (folder / "orange.json").unlink()
    (folder / "mbase.json").write_text("{")
    lines = _error(folder).splitlines()[1:]
    assert len(lines) == 2
    assert "mbase.json: not JSON" in lines[0] and "orange.json: missing" in lines[1]


def test_the_agent_refuses_a_bad_folder_before_it_joins(tmp_path: Path) -> None:
    res = subprocess.run(
        [sys.executable, "-m", "agent", "--id", "3", "--calibration", str(tmp_path),
         "--insecure", "--no-multicast-scouting"],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert res.returncode == 2, res.stderr[-2000:]
    assert "--calibration: calibration folder" in res.stderr
    assert f"{tmp_path / 'dbase.json'}: missing" in res.stderr
