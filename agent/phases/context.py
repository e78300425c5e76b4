"""What every collaborator of the phase machine shares (docs/design.md §1, §8; NAO paper 4.1.1).

The phase machine (:mod:`agent.phases.runner`) is split into collaborators, one per
concern (membership, motion, safe steps, search, agreement, re-search, waves, hold; crash
recovery in agent/recovery/); they share this small, read-only :class:`Context` and
nothing else of each other but the typed roles of :mod:`agent.phases.roles`:

* the robot's seams: the bus, its :class:`~agent.body.base.Body`, its configuration,
  its :class:`~agent.seams.Perception` and :class:`~agent.seams.Formation`,
  and a clock;
* its :class:`Beliefs`. Heading: the agent's heading in its fixed frame starts at
  :data:`NORTH` (every robot faces north at the start, 4.1.1) and changes only by
  visual-compass measurements of its own turns and steps (eq. 2), or, when the compass
  fails, by the turn it commanded. Position: (0, 0) in the fixed frame at the start,
  dead-reckoned from the commanded steps along the believed heading. Agents never read
  ground truth;
* its :class:`~agent.phases.reporting.Reporter`: the phase, the statuses, the timeline
  and the journal.

Every other piece of a robot's state has one owner, which the others reach through a
role: its record and round (the search, :class:`~agent.phases.roles.Surveyor`), the
agreed plan with its leg and the pyramid axis (:class:`~agent.phases.waves.Itinerary`,
:class:`~agent.phases.roles.Course`), what it hears of the fleet (the membership,
:class:`~agent.phases.roles.Fleet`), its journal (crash recovery,
:class:`~agent.phases.roles.Recovery`).

:class:`AgentFailure` is the one way a collaborator stops the robot safely.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from agent.body.base import Body
from agent.config import AgentConfig
from agent.net.bus import Bus
from agent.phases.reporting import Reporter
from agent.seams import Formation, Perception

#: Every robot faces north of its fixed frame at the start (4.1.1).
NORTH = math.pi / 2


class AgentFailure(RuntimeError):
    """A reason to stop safely (status ``failed``); the text is the reason."""


@dataclass
class Beliefs:
    """The robot's beliefs about itself in its fixed frame (see the module docstring)."""

    heading: float = NORTH
    position: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(2))
    compass_gain: float = 1.0  # calibrated by the search's half turn (search.py)


@dataclass(frozen=True)
class Context:
    """The seams, beliefs and reporter of one robot, shared by its collaborators."""

    bus: Bus
    body: Body
    cfg: AgentConfig
    perception: Perception
    formation: Formation
    clock: Callable[[], float]
    beliefs: Beliefs
    report: Reporter

    @classmethod
    def of(
        cls,
        bus: Bus,
        body: Body,
        cfg: AgentConfig,
        perception: Perception,
        formation: Formation,
        clock: Callable[[], float] = time.monotonic,
    ) -> Context:
        """The context of a robot starting afresh: facing north at (0, 0), phase ``start``."""
        return cls(
            bus, body, cfg, perception, formation, clock, Beliefs(), Reporter(bus, body, cfg, clock)
        )

    @property
    def me(self) -> int:
        return self.cfg.robot_id
