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
- :class:`Surveyor`: search where the robot stands and make its record, of the current
  re-search round (:class:`~agent.phases.search.Search`);
- :class:`Stepper`: walk to a goal, every step checked first
  (:class:`~agent.phases.safe_steps.SafeSteps`);
- :class:`Planner`: the plan of an agreed record set (:class:`~agent.phases.waves.Waves`);
- :class:`Course`: the agreed plan and this robot's way through it
  (:class:`~agent.phases.waves.Itinerary`);
- :class:`Recovery`: crash recovery (agent/recovery/, which builds on the phases and is
  handed the runner's :class:`Crew`; the phases never import it): where a restarted
  agent starts, the journal written meanwhile, and how the run ended.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from agent.body.base import Frame, MotionResult
from agent.core.agreement import Agreement, Decision
from agent.core.control import PidGains
from agent.core.formation.plan import Plan
from agent.core.formation.shape.spec import Shape
from agent.net.bus import Event
from agent.phases.context import Context
from agent.phases.membership import Peer
from agent.phases.reporting import Phase, Recorder
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

    def pin_sessions(self, members: set[int], plan_digest: str) -> None: ...

    def arrived(self, among: Collection[int] | None = None, digest: str = "") -> bool: ...

    def fleet_stop(self, plan: Plan | None) -> str: ...


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
    """Search and localise (NAO paper 5.2.2 (iii), 3.1–3.2, 4.1.2); the record of the
    current re-search round (4.1.3 rule 2)."""

    @property
    def round(self) -> int: ...

    @property
    def record(self) -> NeighborRecordMsg | None: ...

    def sweep(self) -> list[Sightings]: ...

    def localise(self, sightings: list[Sightings]) -> NeighborRecordMsg: ...

    def begin_round(self, round_: int) -> None: ...

    def restore(self, record: NeighborRecordMsg) -> None: ...

    def restarted(self, start_heading: float) -> None: ...


class Stepper(Protocol):
    """Distance control to a goal with safe steps (NAO paper 4.2; execution noise moves robots off
    their planned corridors)."""

    def walk_to(
        self,
        goal: np.ndarray,
        progress: Callable[[float], None],
        backward_within: float = 0.0,
        gate: Callable[[float], None] | None = None,
    ) -> None: ...

    def forget(self) -> None: ...


class Planner(Protocol):
    """The plan of the agreed records (NAO paper 4.1.2–4.2, AUV III)."""

    def make_plan(self, decision: Decision[NeighborRecordMsg]) -> Plan: ...


class Course(Protocol):
    """The agreed plan and this robot's way through it (NAO paper 4.1.2–4.2)."""

    @property
    def planned(self) -> Plan | None: ...

    @property
    def plan(self) -> Plan: ...

    @property
    def common(self) -> Plan: ...

    @property
    def shape(self) -> Shape | None: ...

    @property
    def digest(self) -> str: ...

    @property
    def history(self) -> tuple[str, ...]: ...

    @property
    def leg(self) -> int: ...

    @property
    def final_heading(self) -> float: ...

    def follow(
        self, plan: Plan, common: Plan | None = None, shape: Shape | None = None
    ) -> None: ...

    def at_leg(self, leg: int) -> None: ...

    def face(self, final_heading: float) -> None: ...


class Recovery(Recorder, Protocol):
    """Crash recovery as the runner uses it (docs/design.md §8 "Faults"): the journal
    (:class:`~agent.phases.reporting.Recorder`), where to start, how the run ended."""

    def start(self) -> tuple[Phase, NeighborRecordMsg | None]:
        """The phase to enter (``search`` afresh) and the record to agree on."""
        ...

    def finish(self, end: str) -> None:
        """The run is over for this robot: ``done``, ``failed`` or ``stopped``."""


@dataclass(frozen=True)
class Crew:
    """The runner's collaborators that crash recovery works with (agent/recovery/)."""

    ctx: Context
    fleet: Fleet
    motion: Mover
    planner: Planner
    course: Course
    survey: Surveyor
