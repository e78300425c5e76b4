"""The typed seams of the runner (a body that may be a real NAO; docs/design.md §8 "Bodies").

The phase machine (:mod:`agent.phases.runner`) and its collaborators depend on the
:class:`agent.body.base.Body` protocol and on these two (the seams between the
collaborators themselves are in :mod:`agent.phases.roles`):

- :class:`Perception`: detector, fixed-frame conversion, merging and the visual compass
  (NAO paper §3), and the same for the static obstacles (§5.1.2;
  :class:`agent.adapters.PerceptionAdapter`);
- :class:`Formation`: agreed records → plan → this robot's goals, or who searches
  again (§4; :class:`agent.adapters.FormationAdapter`).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from agent.core.formation.frame.research import Research
from agent.core.formation.params import PlanParams
from agent.core.formation.plan import Plan
from agent.core.perception.compass import CompassResult
from agent.core.perception.detector import Detection
from agent.core.perception.obstacles import ObstacleDetection
from agent.wire import NeighborRecordMsg

#: (points (k, 2) in the fixed frame, confidences (k,), orientations (k,))
Sightings = tuple[np.ndarray, np.ndarray, np.ndarray]
#: merged neighbours: (points (m, 2), orientations (m,), confidences (m,), best (m,)):
#: best is the index, among the merged sightings concatenated in order, of the one whose
#: orientation and confidence each neighbour carries
Neighbours = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


class Perception(Protocol):
    """Detector, fixed-frame conversion, merging and visual compass (NAO paper §3)."""

    def detect(self, image: np.ndarray, yaw: float) -> list[Detection]: ...

    def to_fixed(self, dets: list[Detection], heading: float) -> Sightings: ...

    def merge(self, sightings: list[Sightings]) -> Neighbours: ...

    def measure_turn(self, before: np.ndarray, after: np.ndarray) -> CompassResult: ...

    def measure_walk(self, before: np.ndarray, after: np.ndarray) -> CompassResult: ...

    def detect_obstacles(self, image: np.ndarray, yaw: float) -> list[ObstacleDetection]: ...

    def obstacles_fixed(self, dets: list[ObstacleDetection], heading: float) -> np.ndarray: ...

    def merge_obstacles(self, sightings: list[np.ndarray]) -> np.ndarray: ...


class Formation(Protocol):
    """The formation core (NAO paper §4, AUV III): records → plan → goals."""

    def plan(self, msgs: tuple[NeighborRecordMsg, ...], params: PlanParams) -> Plan:
        """The plan of the agreed records with the agreed parameters (d_e, φ_e,
        orientation, strategy: :meth:`agent.config.AgentConfig.plan_params`)."""
        ...

    def members(self, plan: Plan) -> list[int]: ...

    def goals(self, plan: Plan, me: int) -> tuple[list[np.ndarray], float]: ...

    def research(self, msgs: tuple[NeighborRecordMsg, ...], round_: int, step: float) -> Research:
        """Who searches again in re-search round ``round_`` (4.1.3 rule 2), and where."""
        ...
