"""The roles the runner's collaborators play for each other (typed seams; docs/design.md §1, §8).

The phase machine (:mod:`agent.phases.runner`) composes one collaborator per concern; each
depends on the shared :class:`~agent.phases.context.Context` and on these protocols, never
on the runner nor on the class of a collaborator it is handed (the hold phase builds its
own :class:`~agent.phases.march.Marcher`):

- :class:`Hearing`: keep hearing the fleet while waiting
  (:class:`~agent.phases.membership.Membership`);
- :class:`Fleet`: the members, the agreement under way, the early records
  (:class:`~agent.phases.membership.Membership`);
- :class:`Listening`: hear the fleet and watch what it says
  (:class:`~agent.phases.membership.Membership`);
- :class:`Mover`: look, turn and step, measured by the visual compass
  (:class:`~agent.phases.motion.Motion`);
- :class:`Surveyor`: search where the robot stands and make its record
  (:class:`~agent.phases.search.Search`);
- :class:`Stepper`: walk to a goal, every step checked first
  (:class:`~agent.phases.safe_steps.SafeSteps`);
- :class:`Planner`: the plan of an agreed record set (:class:`~agent.phases.waves.Waves`).
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from typing import Protocol

import numpy as np

from agent.body.base import Frame, MotionResult
from agent.core.agreement import Agreement, Decision
from agent.core.control import PidGains
from agent.core.formation.plan import Plan
from agent.net.bus import Event
from agent.phases.membership import Peer
from agent.seams import Sightings
from agent.wire import DigestMsg, NeighborRecordMsg, RecordSetReply


class Hearing(Protocol):
    """What every wait needs: hear the fleet and answer it (NAO paper 4.1.2)."""

    def pump(self, timeout: float = 0.0) -> None: ...

    def wait_until(self, deadline: float) -> None: ...


class Listening(Hearing, Protocol):
    """Hearing, and watching every record, digest and status accepted (a journal resumes only a run
    still going)."""

    observers: list[Callable[[Event], None]]


class Fleet(Listening, Protocol):
    """The fleet as one agent knows it (docs/design.md §8 "Faults")."""

    peers: dict[int, Peer]
    agreement: Agreement[NeighborRecordMsg] | None
    early_records: dict[int, NeighborRecordMsg]
    early_digests: dict[int, DigestMsg]
    served: RecordSetReply | None

    def peer(self, rid: int) -> Peer: ...

    def open_round(self, agr: Agreement[NeighborRecordMsg]) -> None: ...

    def retire(self) -> None: ...

    def pin_sessions(self, members: set[int]) -> None: ...

    def arrived(self, among: Collection[int] | None = None) -> bool: ...

    def fleet_stop(self) -> str: ...


class Mover(Protocol):
    """Turns and steps measured by the visual compass (NAO paper 4.2, 5.2.2)."""

    last_frame: Frame | None  # the compass reference (head yaw 0); None: look afresh
    steps: int  # straight steps walked so far

    def look(self, yaw: float = 0.0) -> Frame: ...

    def reference(self) -> Frame: ...

    def rotate(self, angle: float, gains: PidGains = ..., label: str = "") -> float: ...

    def walk_step(self, distance: float) -> MotionResult: ...

    def side_step(self, distance: float) -> MotionResult: ...


class Surveyor(Protocol):
    """Search and localise (NAO paper 5.2.2 (iii), 3.1–3.2, 4.1.2)."""

    def sweep(self) -> list[Sightings]: ...

    def localise(self, sightings: list[Sightings]) -> NeighborRecordMsg: ...


class Stepper(Protocol):
    """Distance control to a goal with safe steps (NAO paper 4.2; execution noise moves robots off
    their planned corridors)."""

    def walk_to(
        self, goal: np.ndarray, progress: Callable[[float], None], backward_within: float = 0.0
    ) -> None: ...

    def forget(self) -> None: ...


class Planner(Protocol):
    """The plan of the agreed records (NAO paper 4.1.2–4.2, AUV III)."""

    def make_plan(self, decision: Decision[NeighborRecordMsg]) -> Plan: ...
