"""A capture folder: the images of a calibration's views and their manifest (NAO paper 5.2.1:
the data set the M-base and D-base are built from, one a user can look at and reuse).

Layout:

- ``manifest.json``: ``{"version": 1, "plan": {...}, "robots": {"observer": {"id", "url"},
  "subject": {...}}, "camera": {...}, "shots": [...]}``; each shot: its id, set, kind,
  distance (m, body centre to body centre), bearing, orientation (NAO-j's measured, and
  the planned one), both head yaws (deg; NAO-i's as planned and as its sensor read it),
  the robot's time and the image file;
- ``shots.jsonl``: the same shot records, one line each, appended as they are taken (what
  a resumed capture continues from; a torn last line is ignored);
- ``images/ID.png``: the forehead image of NAO-i, lossless;
- ``contact_sheet.png``: thumbnails of the views (:mod:`tools.calibrate.sheet`).
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from agent.core.perception.calibration import camera_params
from agent.core.perception.camera import CameraModel
from tools.calibrate.plan import PlanSpec, Shot

CAPTURE_VERSION = 1
MANIFEST = "manifest.json"
JOURNAL = "shots.jsonl"
IMAGES = "images"


@dataclass(frozen=True)
class ShotRecord:
    """A view as taken: the planned shot, NAO-j's orientation as measured, NAO-i's head
    yaw as its sensor read it (deg), the robot's time and the image file."""

    shot: Shot
    orientation_deg: float
    observer_yaw_read_deg: float
    t: float
    file: str
    orientation_source: str = "plan"

    def to_dict(self) -> dict[str, Any]:
        s = self.shot
        return {
            "id": s.id,
            "set": s.set,
            "kind": s.kind,
            "distance": s.distance,
            "bearing_deg": s.bearing_deg,
            "orientation_target_deg": s.orientation_deg,
            "orientation_deg": round(self.orientation_deg, 4),
            "orientation_source": self.orientation_source,
            "observer_yaw_deg": s.observer_yaw_deg,
            "observer_yaw_read_deg": round(self.observer_yaw_read_deg, 4),
            "subject_yaw_deg": s.subject_yaw_deg,
            "t": round(self.t, 4),
            "file": self.file,
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> ShotRecord:
        shot = Shot(
            str(doc["id"]),
            str(doc["set"]),
            str(doc["kind"]),
            float(doc["distance"]),
            float(doc["bearing_deg"]),
            float(doc["orientation_target_deg"]),
            float(doc["observer_yaw_deg"]),
            float(doc["subject_yaw_deg"]),
        )
        return cls(
            shot,
            float(doc["orientation_deg"]),
            float(doc["observer_yaw_read_deg"]),
            float(doc["t"]),
            str(doc["file"]),
            str(doc.get("orientation_source", "plan")),
        )


def plan_order(shot_id: str) -> tuple[int, str]:
    """A view's place in its plan: ids are a set's letter and the plan's running number."""
    digits = shot_id[1:]
    return (int(digits), shot_id) if digits.isdigit() else (-1, shot_id)


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


class CaptureFolder:
    """A capture folder, opened to add views (:meth:`create_or_resume`) or to read them
    (:meth:`load`)."""

    def __init__(self, path: Path, header: dict[str, Any], records: list[ShotRecord]) -> None:
        self.path = Path(path)
        self.header = header
        self.records: dict[str, ShotRecord] = {r.shot.id: r for r in records}
        self.spec = PlanSpec.from_dict(header["plan"])

    @classmethod
    def create_or_resume(
        cls,
        path: Path,
        spec: PlanSpec,
        robots: dict[str, dict[str, Any]],
        camera: CameraModel,
        extra: dict[str, Any] | None = None,
    ) -> CaptureFolder:
        """A new capture folder, or the one at ``path`` to continue (same plan and
        camera, else ``ValueError``)."""
        path = Path(path)
        if (path / MANIFEST).is_file():
            old = cls.load(path)
            if old.spec != spec:
                raise ValueError(
                    f"{path} was started with another plan ({old.header['plan']}); resume it "
                    "with the same options, or capture into a new folder"
                )
            if old.header.get("camera") != camera_params(camera):
                raise ValueError(f"{path} was captured with another camera model")
            old.header["robots"] = robots
            return old
        path.mkdir(parents=True, exist_ok=True)
        (path / IMAGES).mkdir(exist_ok=True)
        header = {
            "version": CAPTURE_VERSION,
            "plan": spec.to_dict(),
            "robots": robots,
            "camera": camera_params(camera),
            **(extra or {}),
        }
        out = cls(path, header, [])
        out.write_manifest()
        return out

    @classmethod
    def load(cls, path: Path) -> CaptureFolder:
        """Read a capture folder (the manifest's shots and the journal's)."""
        path = Path(path)
        mf = path / MANIFEST
        if not mf.is_file():
            raise ValueError(f"{path} is not a capture folder: no {MANIFEST}")
        try:
            doc = json.loads(mf.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{mf}: not JSON: {exc}") from None
        if doc.get("version") != CAPTURE_VERSION:
            raise ValueError(f"{mf}: version {doc.get('version')!r}, expected {CAPTURE_VERSION}")
        shots = doc.pop("shots", [])
        try:
            records = [ShotRecord.from_dict(s) for s in shots]
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{mf}: a bad shot record ({exc})") from None
        journal = path / JOURNAL
        if journal.is_file():
            for line in journal.read_text().splitlines():
                # a line torn by a crash (the last one) is not a record
                with contextlib.suppress(json.JSONDecodeError, KeyError, TypeError, ValueError):
                    records.append(ShotRecord.from_dict(json.loads(line)))
        return cls(path, doc, records)

    def add(self, record: ShotRecord, image: np.ndarray) -> None:
        """Save a view's image and journal its record."""
        img = self.path / record.file
        img.parent.mkdir(parents=True, exist_ok=True)
        tmp = img.with_name(img.stem + ".tmp.png")
        if not cv2.imwrite(str(tmp), image):
            raise OSError(f"cannot write {tmp}")
        os.replace(tmp, img)
        with open(self.path / JOURNAL, "a", encoding="utf-8") as f:
            f.write(json.dumps(record.to_dict(), sort_keys=True) + "\n")
        self.records[record.shot.id] = record

    def write_manifest(self) -> None:
        """The manifest with every shot taken so far (in the plan's order)."""
        doc = dict(self.header)
        doc["shots"] = [r.to_dict() for r in self.taken()]
        _write_atomic(self.path / MANIFEST, json.dumps(doc, indent=1, sort_keys=True) + "\n")

    def taken(self, set_: str | None = None) -> list[ShotRecord]:
        """The views taken, in the plan's order (of one set)."""
        recs = sorted(self.records.values(), key=lambda r: plan_order(r.shot.id))
        return [r for r in recs if set_ is None or r.shot.set == set_]

    def image(self, record: ShotRecord) -> np.ndarray:
        path = self.path / record.file
        img = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError(f"{path}: missing or not an image")
        return img
