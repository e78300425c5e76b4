"""tools/snapshot.py in-process (the remote path is tested in test_server.py)."""

from __future__ import annotations

from pathlib import Path

import cv2
import pytest

from tools import snapshot


def test_camera_snapshot(tmp_path: Path) -> None:
    out = tmp_path / "view.png"
    args = ["--robots", "2", "--seed", "3", "--place", "1:0:0:90", "--place", "2:0:0.6:270"]
    assert snapshot.main([*args, "--yaw", "0", "--out", str(out)]) == 0
    img = cv2.imread(str(out))
    assert img is not None and img.shape == (480, 640, 3)
    mask = cv2.inRange(cv2.cvtColor(img, cv2.COLOR_BGR2HSV), (2, 170, 50), (10, 255, 255))
    n, _, stats, _ = cv2.connectedComponentsWithStats(mask)
    assert sum(1 for i in range(1, n) if stats[i][4] > 30) == 3


def test_top_down_snapshot(tmp_path: Path) -> None:
    out = tmp_path / "top.png"
    assert (
        snapshot.main(["--robots", "4", "--obstacles", "1", "--top-down", "--out", str(out)]) == 0
    )
    img = cv2.imread(str(out))
    assert img is not None and img.shape[0] > 300


@pytest.mark.parametrize(
    "argv",
    [
        ["--place", "1:0:0"],
        ["--place", "a:0:0:0"],
        ["--robot", "9"],
        ["--yaw", "150"],
        ["--robots", "0"],
        ["--scenario", "/nonexistent/scenario.json"],
    ],
)
def test_bad_arguments_exit_2(tmp_path: Path, argv: list[str]) -> None:
    assert snapshot.main([*argv, "--out", str(tmp_path / "x.png")]) == 2
    assert not (tmp_path / "x.png").exists()
