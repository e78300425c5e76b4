"""The agent's settings (docs/design.md §1; NAO paper 5.2.2): one immutable, validated value.

The runner (:mod:`agent.phases.runner`) takes an :class:`AgentConfig`; ``python -m agent``
builds it from the command line (``agent.__main__.agent_config``), and
:meth:`AgentConfig.to_argv` writes that command line back: the one place where a tool
that starts agents writes their flags (``tools.harness.procs.agent_command``).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

from agent.core.agreed_params import ParamValue
from agent.core.formation.frame.research import DEFAULT_STEP
from agent.core.formation.params import (
    D_E,
    ORIENTATIONS,
    PHI_E_DEG,
    PLAN_STRATEGIES,
    PlanParams,
)
from agent.core.formation.shape.schema import parse_shape, shape_from_dict
from agent.core.formation.shape.spec import BUILTIN, PYRAMID, Shape
from agent.core.formation.view.route import Route
from agent.core.nao import HEAD_YAW_LIMIT
from agent.core.perception.camera import CameraModel
from agent.core.perception.sensor_fault import SensorFault

#: Head yaws of one sweep (paper 5.2.2 iii): the camera model's, 26.6° apart, so that every
#: NAO at >= 0.5 m is wholly inside some image (7 evenly spaced yaws, 39.8° apart, left
#: gaps where a NAO closer than about 0.8 m fell between two images and was dropped as
#: cut by the border).
SEARCH_YAWS = CameraModel().sweep_yaws(limit=HEAD_YAW_LIMIT)


def _yaml(text: str) -> object:
    """A YAML formation file's document (safe loading: plain data only); ``ValueError``
    with the line and column of a syntax error."""
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise ValueError(f"shape file: not YAML ({exc.problem}{where})") from exc
    except yaml.YAMLError as exc:
        raise ValueError(f"shape file: not YAML ({exc})") from exc


def load_shape(spec: str) -> Shape:
    """The shape ``spec`` names: a built-in (``pyramid``, ``line``, ``column``, ``wedge``,
    ``circle``, ``grid``) or the path of a formation file (JSON, or YAML for a ``.yaml``
    or ``.yml`` file: the same fields, docs/formation.md "Shapes"). ``ValueError`` naming
    the file and the bad field, or the missing file."""
    if spec in BUILTIN:
        return BUILTIN[spec]
    path = Path(spec)
    if not path.is_file():
        raise ValueError(
            f"shape {spec!r}: neither a built-in ({', '.join(BUILTIN)}) nor a formation file"
        )
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"shape file {spec}: {exc}") from exc
    try:
        yaml_file = path.suffix.lower() in (".yaml", ".yml")
        shape = shape_from_dict(_yaml(text)) if yaml_file else parse_shape(text)
        PlanParams(shape=shape)  # its slots far enough apart for two robots
    except ValueError as exc:
        raise ValueError(f"shape file {spec}: {exc}") from exc
    return dataclasses.replace(shape, source=str(path.resolve()))


def _shape_argument(spec: str) -> Shape:
    try:
        return load_shape(spec)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def add_plan_arguments(p: argparse.ArgumentParser) -> None:
    """``--orientation``, ``--strategy`` and ``--shape`` (the agent's and the demo's, which
    gives them to every agent): part of the agreed parameters
    (:meth:`AgentConfig.agreed_params`)."""
    p.add_argument(
        "--orientation",
        choices=ORIENTATIONS,
        default="pca",
        help="pyramid orientation: pca (the fleet's principal axis, NAO paper eq. 12), north "
        "(the common frame's y axis) or cp (the AUV paper's circle pattern: walk to a circle "
        "round the frame robot first; the robot at 90° leads a formation facing north)",
    )
    p.add_argument(
        "--strategy",
        choices=PLAN_STRATEGIES,
        default="default",
        help="slot assignment strategy of the planner (agent/core/formation/plan.py)",
    )
    p.add_argument(
        "--shape",
        type=_shape_argument,
        default=PYRAMID,
        metavar="NAME|FILE",
        help=f"the formation: a built-in ({', '.join(BUILTIN)}; default pyramid) or a "
        "formation file (JSON: the slots as a tree, docs/formation.md)",
    )


@dataclass(frozen=True)
class AgentConfig:
    """What one agent is told: its robot, the fleet, the formation (d_e, phi_e,
    orientation, strategy, shape) and limits."""

    robot_id: int
    fleet_size: int | None = None
    d_e: float = D_E
    phi_e: float = math.radians(PHI_E_DEG)
    orientation: str = "pca"  # one of formation.params.ORIENTATIONS (pca, north, cp)
    strategy: str = "default"  # assignment strategy, one of formation.params.PLAN_STRATEGIES
    shape: Shape = PYRAMID  # the formation's shape (agent/core/formation/shape/spec.py)
    timeout: float = 120.0  # s without news (a new record or digest) before agreement fails
    wave_timeout: float = 600.0  # s to wait for earlier waves, and for the fleet to hold
    settle: float = 3.0  # s of unchanged membership when no fleet size is given
    # s a member whose liveliness token vanished, and who published nothing since, still
    # counts as a member (agent.core.grace.Grace): a lossy link's lease expiry and
    # reconnection is no departure; a crashed agent is noticed this much later.
    member_grace: float = 20.0
    search_yaws: tuple[float, ...] = SEARCH_YAWS
    rotation_tolerance: float = math.radians(2.0)
    # Re-publication backoff cap: a peer that lacks our record says so in its digest,
    # which re-arms us at once, so long waits (others still searching) need few re-sends.
    backoff_max: float = 16.0
    correct: bool = True  # final visual alignment to the parent (see Hold.correct)
    # with the circle pattern (orientation cp): fine-tune the place on the circle from a
    # look at the centre robot (AUV III.B.2.a and Tables 1-2's "tune")
    cp_tune: bool = True
    max_correction: float = 0.3  # m
    march: Route | None = None  # march in formation after hold; None: stop at hold
    # s to stay once the fleet holds, listening for the operator's reshape command
    # (agent/phases/transitions/reshaping.py), again after each reshape; 0: exit at done
    reshape_wait: float = 0.0
    march_step: float = 0.1  # m per leader step: half a follower's 20 cm, so they keep up
    march_pause: float = 4.0  # the leader rests this many times each step's duration
    lost_rounds: int = 3  # head searches for a lost parent before the fleet halts
    # Re-search (NAO paper 4.1.3 rule 2, agent/core/formation/frame/research.py): rounds before the
    # fleet stops, the first exploration leg (m), and how long the robots that keep their
    # place wait for the others to explore and search again (s).
    research_rounds: int = 2
    explore_step: float = DEFAULT_STEP
    research_timeout: float = 300.0
    # test tool (agent/core/perception/sensor_fault.py): corrupt this robot's own record
    sensor_fault: SensorFault | None = None
    # publish thumbnails of the analysed frames for viewers on nao/{id}/camera
    # (agent/phases/camera_feed.py); off by default, opt-in on real fleets
    publish_camera: bool = False
    # the digest of the recogniser's calibration (agent/core/perception/calibration.py),
    # reported in this robot's status and record; "" when not told
    calibration: str = ""

    @property
    def phi_e_deg(self) -> float:
        """φ_e in degrees as ``--phi-e-deg`` gives it: the shortest decimal whose radians are
        exactly :attr:`phi_e` (30.0 for the default)."""
        return float(_degrees_text(self.phi_e))

    def to_argv(self, *, claim_id: bool = False) -> list[str]:
        """The ``python -m agent`` flags that give this config, the inverse of its parser:
        ``agent_config(parse_args(c.to_argv()), c.robot_id) == c``. Only the settings that
        differ from the defaults are written (the agent's defaults have their one home
        here); a shape other than the pyramid as ``--shape NAME|FILE``, from its
        ``source``. ``claim_id``: ``--id auto`` (the agent claims a robot from the world).
        ``ValueError`` for a setting that no flag carries (:data:`NO_FLAG`) when it is not
        its default, and for a shape with no source (built in code, not loaded)."""
        fixed = [f for f in NO_FLAG if getattr(self, f) != _DEFAULTS[f]]
        if fixed:
            raise ValueError(f"no python -m agent flag sets {', '.join(fixed)}")
        argv = ["--id", "auto" if claim_id else str(self.robot_id)]
        if self.fleet_size is not None:
            argv += ["--fleet-size", str(self.fleet_size)]
        if self.phi_e != _DEFAULTS["phi_e"]:
            argv += ["--phi-e-deg", _degrees_text(self.phi_e)]
        for name, flag in FLAGS.items():
            value = getattr(self, name)
            if value != _DEFAULTS[name]:
                argv.append(f"{flag}={value!r}" if isinstance(value, float) else f"{flag}={value}")
        if self.shape != PYRAMID:  # a built-in's name or a formation file's path
            if not self.shape.source:
                raise ValueError(
                    f"no python -m agent flag sets the shape {self.shape.name!r}: it came "
                    "from no formation file (its source)"
                )
            argv += ["--shape", self.shape.source]
        if not self.correct:
            argv.append("--no-correct")
        if not self.cp_tune:
            argv.append("--no-cp-tune")
        if self.march is not None and self.march.distance is not None:
            argv.append(f"--march={self.march.distance!r}")
        elif self.march is not None and self.march.to is not None:
            argv.append(f"--march-to={self.march.to[0]!r},{self.march.to[1]!r}")
        if self.sensor_fault is not None:
            argv.append(f"--sensor-fault={self.sensor_fault.kind}:{self.sensor_fault.amount!r}")
        if self.publish_camera:
            argv.append("--publish-camera")
        return argv

    @property
    def radius(self) -> float:
        """The robots' safety radius (m), the planner's."""
        return PlanParams(d_e=self.d_e, phi_e=self.phi_e).radius

    def plan_params(self) -> PlanParams:
        """The planning parameters this agent plans with (the formation seam takes them)."""
        return PlanParams(
            d_e=self.d_e,
            phi_e=self.phi_e,
            orientation=self.orientation,
            strategy=self.strategy,
            shape=self.shape,
        )

    def agreed_params(self) -> dict[str, ParamValue]:
        """What every agent must share to plan and march alike (digest in DigestMsg)."""
        pp = self.plan_params()
        route = None if self.march is None else self.march.key()
        return {
            "d_e": pp.d_e,
            "phi_e": pp.phi_e,
            "radius": pp.radius,
            "orientation": pp.orientation,
            "strategy": pp.strategy,
            "shape": pp.shape.digest,
            "route": route,
            "march_step": self.march_step if self.march is not None else None,
            "research_rounds": self.research_rounds,
        }

    def __post_init__(self) -> None:
        if self.fleet_size is not None and self.fleet_size < 1:
            raise ValueError(f"fleet size must be >= 1, got {self.fleet_size}")
        if self.fleet_size is not None:  # a formation file with fewer slots: refused now
            self.shape.check_fleet(self.fleet_size)
        if not (math.isfinite(self.d_e) and self.d_e > 0.0):
            raise ValueError(f"d_e must be > 0 m, got {self.d_e}")
        if not (math.isfinite(self.phi_e) and 0.0 < self.phi_e < math.pi / 2):
            raise ValueError(f"phi_e must be in (0°, 90°), got {math.degrees(self.phi_e)}°")
        self.plan_params()  # orientation and strategy: ValueError when unknown
        for name in ("timeout", "wave_timeout", "settle", "member_grace", "reshape_wait"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {v}")
        if not (math.isfinite(self.march_step) and 0.02 <= self.march_step <= 0.2):
            raise ValueError(f"march_step must be in [0.02, 0.2] m, got {self.march_step}")
        if not (math.isfinite(self.march_pause) and 0.0 <= self.march_pause <= 20.0):
            raise ValueError(f"march_pause must be in [0, 20], got {self.march_pause}")
        if not 0 <= self.research_rounds <= 10:
            raise ValueError(f"research_rounds must be in [0, 10], got {self.research_rounds}")
        if not (math.isfinite(self.explore_step) and 0.2 <= self.explore_step <= 5.0):
            raise ValueError(f"explore_step must be in [0.2, 5] m, got {self.explore_step}")
        if not (math.isfinite(self.research_timeout) and self.research_timeout > 0.0):
            raise ValueError(f"research_timeout must be > 0 s, got {self.research_timeout}")
        if self.calibration and (
            len(self.calibration) != 64
            or any(c not in "0123456789abcdef" for c in self.calibration)
        ):
            raise ValueError(f"calibration must be a SHA-256 hex digest, got {self.calibration!r}")
        if self.lost_rounds < 1:
            raise ValueError(f"lost_rounds must be >= 1, got {self.lost_rounds}")
        for y in self.search_yaws:
            if abs(y) > HEAD_YAW_LIMIT + 1e-9:
                raise ValueError(
                    f"search yaw {math.degrees(y):.1f}° outside "
                    f"±{math.degrees(HEAD_YAW_LIMIT):.1f}°"
                )


#: The settings written as ``FLAG=VALUE`` by :meth:`AgentConfig.to_argv` (the others:
#: ``--id``, ``--fleet-size``, ``--phi-e-deg``, ``--shape``, ``--no-correct``,
#: ``--no-cp-tune``, the route,
#: the sensor fault and ``--publish-camera``).
FLAGS = {
    "d_e": "--d-e",
    "orientation": "--orientation",
    "strategy": "--strategy",
    "timeout": "--timeout",
    "wave_timeout": "--wave-timeout",
    "member_grace": "--member-grace",
    "reshape_wait": "--reshape-wait",
    "research_rounds": "--research-rounds",
    "explore_step": "--explore-step",
}
#: The settings that no ``python -m agent`` flag carries (tests and the runner set them).
NO_FLAG = (
    "settle",
    "search_yaws",
    "rotation_tolerance",
    "backoff_max",
    "max_correction",
    "march_step",
    "march_pause",
    "lost_rounds",
    "research_timeout",
)
_DEFAULTS = {f.name: f.default for f in dataclasses.fields(AgentConfig)}


def _degrees_text(rad: float) -> str:
    """The shortest decimal text of degrees whose ``math.radians`` is exactly ``rad``
    (``--phi-e-deg`` takes degrees; the config keeps radians)."""
    deg = math.degrees(rad)
    candidates = [repr(round(deg, k)) for k in range(16)] + [repr(deg)]
    near = deg
    for _ in range(8):  # the degrees one rounding away, both sides
        near = math.nextafter(near, math.inf)
        candidates.append(repr(near))
    near = deg
    for _ in range(8):
        near = math.nextafter(near, -math.inf)
        candidates.append(repr(near))
    for text in candidates:
        if math.radians(float(text)) == rad:
            return text
    raise ValueError(f"phi_e {rad!r} rad is no value of --phi-e-deg")
