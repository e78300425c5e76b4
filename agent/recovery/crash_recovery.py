"""Crash recovery as the phase machine uses it: one journal, written and read back
(docs/design.md §8 "Faults"; the room's entry point, agent/recovery/__init__.py).

:class:`CrashRecovery` is the :class:`~agent.phases.roles.Recovery` of an agent that keeps
a journal: :class:`~agent.recovery.journaling.Journaling` writes it (it is the phases'
:class:`~agent.phases.reporting.Recorder`), :class:`~agent.recovery.resume.Resumption`
reads it back when the agent starts. ``python -m agent --state-dir DIR`` builds one on the
runner's :class:`~agent.phases.roles.Crew`.
"""

from __future__ import annotations

import numpy as np

from agent.phases.reporting import Phase
from agent.phases.roles import Crew
from agent.recovery.journal import Journal
from agent.recovery.journaling import Journaling
from agent.recovery.resume import Resumption
from agent.wire import NeighborRecordMsg


class CrashRecovery:
    """The journal ``journal`` of the robot of ``crew``, written and resumed from."""

    def __init__(self, journal: Journal, crew: Crew) -> None:
        self.journaling = Journaling(journal, crew.ctx, crew.fleet, crew.course, crew.survey)
        self.resumption = Resumption(self.journaling, crew)

    def start(self) -> tuple[Phase, NeighborRecordMsg | None]:
        """Where to start (:meth:`~agent.recovery.resume.Resumption.start`)."""
        return self.resumption.start()

    def finish(self, end: str) -> None:
        """The final record (:meth:`~agent.recovery.journaling.Journaling.finish`)."""
        self.journaling.finish(end)

    def save(self, command: str = "", value: float = 0.0, request_id: int = 0) -> None:
        """The state now (:meth:`~agent.recovery.journaling.Journaling.save`)."""
        self.journaling.save(command, value, request_id)

    def reference(self, image: np.ndarray) -> None:
        """The reference view (:meth:`~agent.recovery.journaling.Journaling.reference`)."""
        self.journaling.reference(image)
