"""The contact sheet of a capture folder: thumbnails of its views, each labelled with its
set, distance and orientation, to look the data set over at a glance (NAO paper 5.2.1's
captures)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from tools.calibrate.folder import CaptureFolder

THUMB_W, THUMB_H = 160, 120
COLUMNS = 10
MAX_THUMBS = 120


def contact_sheet(folder: CaptureFolder, path: Path | None = None) -> Path:
    """Write ``contact_sheet.png`` (at most ``MAX_THUMBS`` views, evenly chosen)."""
    recs = folder.taken()
    if not recs:
        raise ValueError(f"{folder.path}: no views taken yet")
    idx = np.unique(np.linspace(0, len(recs) - 1, min(MAX_THUMBS, len(recs))).round().astype(int))
    rows = (len(idx) + COLUMNS - 1) // COLUMNS
    sheet = np.full((rows * (THUMB_H + 4), COLUMNS * (THUMB_W + 4), 3), 255, np.uint8)
    for n, i in enumerate(idx):
        r = recs[int(i)]
        try:
            thumb = cv2.resize(folder.image(r), (THUMB_W, THUMB_H), interpolation=cv2.INTER_AREA)
        except ValueError:
            thumb = np.zeros((THUMB_H, THUMB_W, 3), np.uint8)
        s = r.shot
        label = f"{s.set[0]} {s.distance:.2f}m {r.orientation_deg:.0f}d"
        if s.subject_yaw_deg:
            label += f" h{s.subject_yaw_deg:+.0f}"
        cv2.rectangle(thumb, (0, 0), (THUMB_W, 16), (0, 0, 0), -1)
        cv2.putText(thumb, label, (3, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1)
        y, x = (n // COLUMNS) * (THUMB_H + 4), (n % COLUMNS) * (THUMB_W + 4)
        sheet[y : y + THUMB_H, x : x + THUMB_W] = thumb
    out = folder.path / "contact_sheet.png" if path is None else Path(path)
    if not cv2.imwrite(str(out), sheet):
        raise OSError(f"cannot write {out}")
    return out
