"""The typed seams of the runner (issue #11; DESIGN.md §8 "Bodies").

The phase machine (:mod:`agent.runner`) depends only on these three protocols:

- :class:`Body`: the robot's forehead camera at a head yaw, walk, turn and stop
  (implemented by :class:`agent.robot.ZenohBody` over the world's queryables,
  :class:`agent.body_naoqi.NaoqiBody` over the qi protocol of a real or virtual NAO,
  and :class:`agent.body_world.WorldBody` on an in-process :class:`sim.world.World`);
- :class:`Perception`: detector, fixed-frame conversion, merging and the visual compass
  (NAO paper §3), and the same for the static obstacles (§5.1.2;
  :class:`agent.adapters.PerceptionAdapter`);
- :class:`Formation`: agreed records → plan → this robot's goals, or who searches
  again (§4;
  :class:`agent.adapters.FormationAdapter`).

Results and errors are dataclasses. A body raises :class:`BodyError` when the robot or
its world refuses or fails an action, and ``ValueError`` for a request that is wrong
before anything is sent (a head yaw outside ±119.5°, a non-finite distance).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from agent.formation.plan import Plan, PlanParams
from agent.formation.research import Research
from agent.perception.compass import CompassResult
from agent.perception.detector import Detection
from agent.perception.obstacles import ObstacleDetection
from agent.protocol import NeighborRecordMsg

#: (points (k, 2) in the fixed frame, confidences (k,), orientations (k,))
Sightings = tuple[np.ndarray, np.ndarray, np.ndarray]
#: merged neighbours: (points (m, 2), orientations (m,), confidences (m,))
Neighbours = tuple[np.ndarray, np.ndarray, np.ndarray]


@dataclass(frozen=True)
class Frame:
    """One camera image (BGR uint8, (H, W, 3)), the head yaw actually applied (rad) and
    the robot's time when it was taken (sim time in the simulation)."""

    image: np.ndarray
    yaw: float
    t_sim: float


@dataclass(frozen=True)
class MotionResult:
    """How a walk or turn ended: ``done``, or ``contact`` (stopped by a contact or, on a
    NAO, by its own move-failure protection), at the robot's time ``t_sim``."""

    status: Literal["done", "contact"]
    t_sim: float
    detail: str = ""


@dataclass(eq=False)
class BodyError(RuntimeError):
    """The robot (or its world) refused or failed ``action``; ``reason`` says why."""

    action: str
    reason: str

    def __post_init__(self) -> None:
        super().__init__(str(self))

    def __str__(self) -> str:
        return f"{self.action}: {self.reason}"


class Body(Protocol):
    """One NAO's body as the agent drives it. Actions block until they are over."""

    @property
    def robot_id(self) -> int: ...

    @property
    def t_sim(self) -> float:
        """The latest robot time seen (s)."""
        ...

    def camera(self, yaw: float) -> Frame:
        """The forehead image with the head turned to ``yaw`` (rad, + left, ±119.5°)."""
        ...

    def walk(self, distance: float) -> MotionResult:
        """Walk ``distance`` m straight ahead (< 0: backwards)."""
        ...

    def turn(self, angle: float) -> MotionResult:
        """Turn on the spot by ``angle`` rad (+ CCW)."""
        ...

    def stop(self) -> None:
        """Stop walking (idempotent; harmless when idle)."""
        ...

    def close(self) -> None:
        """Release the connection (idempotent)."""
        ...


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
