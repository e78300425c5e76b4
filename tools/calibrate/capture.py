"""Capture: two NAOs take the calibration's views (NAO paper 5.2.1 and 5.2.2 (i)).

NAO-i (observer) and NAO-j (subject) are bodies over qi (:class:`agent.body.naoqi.NaoqiBody`,
the same as an agent's; against real NAOs or the virtual ones of ``python -m sim
--naoqi``). For each placement of the plan (:mod:`tools.calibrate.plan`) the tool asks a
person to put NAO-j there facing NAO-i (the ``prompt``, injectable); then NAO-j turns
itself on the spot through the placement's orientations, in steps of at most
``MAX_STEP_DEG``, and measures each turn with its own visual compass (NAO paper 3.2.1) on
two images of its forehead camera: a turn that missed its target by more than
``TOLERANCE_DEG`` is topped up, and the orientation recorded is the measured one (the
commanded one when the compass could not tell). NAO-j turns its own head for the head
views; NAO-i turns its head and takes the picture.

Every view is saved as it is taken (:mod:`tools.calibrate.folder`), so a capture stopped
for any reason (Ctrl-C, a robot's error, a flat battery) resumes where it stopped when the
same command is run again: the person places NAO-j once more for the placement that was
under way. A progress bar shows the views done and the time left; at the end the
manifest and the contact sheet are written.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, TextIO

import numpy as np

from agent.body.base import Frame, MotionResult
from agent.core.perception.compass import VisualCompass
from tools.calibrate.folder import IMAGES, CaptureFolder, ShotRecord
from tools.calibrate.plan import FACING_DEG, Shot
from tools.calibrate.sheet import contact_sheet
from tools.harness.progress import Progress

MAX_STEP_DEG = 30.0  # the compass needs the two images to overlap (60.9° field of view)
#: a turn closer than this to its target is left as it is: a NAO does not turn by a
#: fraction of a degree (the simulated one errs by 1.1° (σ) on any turn, sim/physics/locomotion.py)
TOLERANCE_DEG = 1.5
EXTRA_TURNS = 4  # top-up turns after the planned steps


class Robot(Protocol):
    """What the capture needs of a NAO (:class:`agent.body.naoqi.NaoqiBody` has it)."""

    @property
    def robot_id(self) -> int: ...
    def camera(self, yaw: float) -> Frame: ...
    def turn(self, angle: float, request_id: int = 0) -> MotionResult: ...


@dataclass(frozen=True)
class Placement:
    """Where a person puts NAO-j (facing NAO-i, NAO-i not moved)."""

    set: str
    observer: int
    subject: int
    distance: float
    bearing_deg: float

    def text(self) -> str:
        b = self.bearing_deg
        where = (
            "straight ahead of"
            if abs(b) < 1e-9
            else f"{abs(b):.0f}° to the {'left' if b > 0 else 'right'} of"
        )
        return (
            f"[{self.set}] Place NAO-j (robot {self.subject}) {where} NAO-i (robot "
            f"{self.observer}), its body centre {self.distance:.2f} m from NAO-i's, facing "
            "NAO-i. Do not move NAO-i."
        )


Prompt = Callable[[Placement], None]


def console_prompt(placement: Placement) -> None:
    """Ask on the terminal; Enter when done (end of input stops the capture)."""
    print(placement.text(), file=sys.stderr, flush=True)
    try:
        input("  Press Enter when NAO-j stands there (Ctrl-C stops; run again to resume) ")
    except EOFError:
        raise KeyboardInterrupt from None


class CaptureError(RuntimeError):
    """The capture cannot go on (a robot stopped by a contact, say)."""


def wrap_deg(a: float) -> float:
    """An angle in (-180, 180]."""
    r = math.fmod(a + 180.0, 360.0)
    r = r + 360.0 if r <= 0 else r
    return r - 180.0


class Turner:
    """NAO-j turning itself and its head; keeps its orientation as measured."""

    def __init__(self, subject: Robot, compass: VisualCompass | None) -> None:
        self.subject = subject
        self.compass = compass
        self.orientation = FACING_DEG
        self.source = "plan"
        self.head = 0.0
        self._view: np.ndarray | None = None
        self.compass_misses = 0
        self.turns = 0
        self.missed = 0  # views where NAO-j stayed off its orientation by > TOLERANCE_DEG

    def placed(self) -> None:
        """A person has just put NAO-j there, facing NAO-i."""
        self.orientation, self.source, self._view = FACING_DEG, "plan", None

    def look(self) -> np.ndarray:
        """NAO-j's own image at head yaw 0 (kept until it moves)."""
        if self._view is None or self.head != 0.0:
            self._view = self.subject.camera(0.0).image
            self.head = 0.0
        return self._view

    def head_to(self, yaw_deg: float) -> None:
        """Turn NAO-j's head (a picture of its own camera waits for the joint)."""
        if yaw_deg != self.head:
            self.subject.camera(math.radians(yaw_deg))
            self.head = yaw_deg

    def turn_to(self, target_deg: float) -> None:
        """Turn NAO-j on the spot until its measured orientation is within the tolerance."""
        need = abs(wrap_deg(target_deg - self.orientation))
        for _ in range(math.ceil(need / MAX_STEP_DEG) + EXTRA_TURNS):
            delta = wrap_deg(target_deg - self.orientation)
            if abs(delta) <= TOLERANCE_DEG:
                return
            step = max(-MAX_STEP_DEG, min(MAX_STEP_DEG, delta))
            before = self.look()
            res = self.subject.turn(math.radians(step))
            self.turns += 1
            if res.status != "done":
                raise CaptureError(
                    f"NAO-j's turn was stopped ({res.detail or res.status}): check the robots "
                    "and the floor, then run again to resume"
                )
            self._view = None
            after = self.look()
            measured, how = step, "command"
            if self.compass is not None:
                c = self.compass.measure(before, after)
                if c.ok:
                    measured, how = math.degrees(c.dtheta), "compass"
                else:
                    self.compass_misses += 1
            self.orientation = (self.orientation + measured) % 360.0
            if how == "command":
                self.source = "command"
            elif self.source == "plan":
                self.source = "compass"
        if abs(wrap_deg(target_deg - self.orientation)) > TOLERANCE_DEG:
            self.missed += 1  # the view keeps its measured orientation (the manifest's)


def capture(
    observer: Robot,
    subject: Robot,
    folder: CaptureFolder,
    prompt: Prompt = console_prompt,
    *,
    compass: bool = True,
    stream: TextIO | None = None,
) -> CaptureFolder:
    """Take every view of ``folder``'s plan not yet taken; write the manifest and the
    contact sheet (also when stopped)."""
    shots = folder.spec.shots()
    todo = [s for s in shots if s.id not in folder.records]
    progress = Progress(max(1, len(shots)), "capture", stream=stream)
    progress.done = len(shots) - len(todo)
    turner = Turner(subject, VisualCompass() if compass else None)
    where: tuple[str, float, float] | None = None
    try:
        for shot in todo:
            if shot.placement != where:
                if where is not None:
                    folder.write_manifest()
                turner.head_to(0.0)
                prompt(
                    Placement(
                        shot.set,
                        observer.robot_id,
                        subject.robot_id,
                        shot.distance,
                        shot.bearing_deg,
                    )
                )
                turner.placed()
                where = shot.placement
            _take(observer, turner, folder, shot)
            progress.step(f"{shot.id} {shot.set} {shot.kind} d={shot.distance:.2f} m "
                          f"θ={turner.orientation % 360.0:.1f}°")  # fmt: skip
        turner.head_to(0.0)
    finally:
        progress.close()
        folder.header["turns"] = folder.header.get("turns", 0) + turner.turns
        for key, n in (("compass_misses", turner.compass_misses), ("off_target", turner.missed)):
            folder.header[key] = folder.header.get(key, 0) + n
        folder.write_manifest()
        if folder.records:
            contact_sheet(folder)
    return folder


def _take(observer: Robot, turner: Turner, folder: CaptureFolder, shot: Shot) -> None:
    if shot.kind != "none":
        turner.turn_to(shot.orientation_deg)
    turner.head_to(shot.subject_yaw_deg)
    frame = observer.camera(math.radians(shot.observer_yaw_deg))
    rec = ShotRecord(
        shot,
        turner.orientation,
        math.degrees(frame.yaw),
        frame.t_sim,
        f"{IMAGES}/{shot.id}.png",
        turner.source,
    )
    folder.add(rec, frame.image)
