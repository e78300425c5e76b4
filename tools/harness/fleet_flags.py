"""The command-line flags of a fleet run, read into a :class:`~tools.harness.fleet.FleetSpec`:
``tools.demo``'s, and those an evaluation tool passes on (``--demo-arg``).

:func:`add_fleet_arguments` adds them to a parser, :func:`fleet_spec` reads the parsed
namespace into a spec (a usage error where the spec or the agent's config refuses a
value), :func:`parse_fleet_spec` does both for a list of flags. Every default has its home
elsewhere: the agent's in :class:`agent.config.AgentConfig`, the formation's in
:mod:`agent.core.formation.params`, the run's in :class:`~tools.harness.fleet.FleetSpec`.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from agent.config import AgentConfig, add_plan_arguments, load_shape
from agent.core.formation.params import D_E, PHI_E_DEG
from agent.core.formation.shape.spec import Shape
from agent.core.formation.view.route import Route
from agent.core.perception.calibration import CalibrationError, load
from sim import scenarios
from sim.camera.look import HELP as LOOK_HELP
from sim.camera.look import Look, look_arg
from sim.camera.renderer import RENDERERS
from tools.harness.fleet import MAX_RENDER_WORKERS, FleetSpec
from tools.harness.view.live import add_live_arguments, check_live_argument

LOG_LEVELS = ("DEBUG", "INFO", "WARNING")


def agent_arg(text: str) -> tuple[int, str]:
    """``ID:ARG`` of ``--agent-arg``: (robot id, one argument of its agent)."""
    rid, sep, arg = text.partition(":")
    if not sep or not rid.isdigit() or not arg.startswith("--"):
        raise argparse.ArgumentTypeError(f"expected ID:--flag[=value], got {text!r}")
    return int(rid), arg


def add_agent_arguments(p: argparse.ArgumentParser, agreement: bool = True) -> None:
    """The agents' pyramid (``--d-e``, ``--phi-e-deg``) and, with ``agreement``, their
    agreement timeout and log level (``--agree-timeout``, ``--agent-log-level``): what
    every tool that starts a fleet lets its user set (:func:`agent_settings` reads them)."""
    p.add_argument("--d-e", type=float, default=D_E, help="the pyramid's edge length d_e (m)")
    p.add_argument("--phi-e-deg", type=float, default=PHI_E_DEG, help="the pyramid's φ_e (deg)")
    if agreement:
        p.add_argument("--agree-timeout", type=float, default=AgentConfig.timeout,
                       help="the agents' agreement timeout (python -m agent --timeout)")  # fmt: skip
        p.add_argument("--agent-log-level", default=None, choices=LOG_LEVELS,
                       help="(default: the agent's)")  # fmt: skip


def agent_settings(p: argparse.ArgumentParser, a: argparse.Namespace, **more: Any) -> AgentConfig:
    """Every agent's settings from the flags of :func:`add_agent_arguments` in ``a`` and
    ``more`` (``timeout=a.agree_timeout``, ...); a usage error where the config refuses one."""
    phi_e = math.radians(a.phi_e_deg) if math.isfinite(a.phi_e_deg) else math.nan
    try:
        return AgentConfig(robot_id=0, d_e=a.d_e, phi_e=phi_e, **more)
    except ValueError as exc:
        p.error(str(exc))


def add_fleet_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of one fleet run (``tools.demo``'s, without its own ``--out``, ``--json``,
    ``--batch`` and ``--view``)."""
    add = p.add_argument
    add("--robots", type=int, default=FleetSpec.robots)
    add("--seed", type=int, default=FleetSpec.seed)
    add("--obstacles", type=int, default=FleetSpec.obstacles,
        help="K obstacles on the straight paths of the fleet's plan (tools.lib.obstacle_scenario)")  # fmt: skip
    add_agent_arguments(p)
    add_plan_arguments(p)  # given to every agent
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scenario", type=Path, default=None, metavar="FILE",
                       help="world scenario JSON (sim/scenarios): robot count and ids from the file")  # fmt: skip
    where.add_argument("--isolated", action="store_true",
                       help="generated scenario with one robot 2-3 m from every other")  # fmt: skip
    add("--headings", type=scenarios.Headings.parse, default=scenarios.Headings(), metavar="KIND",
        help=scenarios.HEADINGS_HELP + " (a generated scenario; the world gets its file)")  # fmt: skip
    add("--timeout", type=float, default=None,
        help="wall limit for the agents (s; default max(600, 20 s a robot))")  # fmt: skip
    add("--auto-ids", action="store_true", help="agents claim robots (--id auto)")
    add("--no-correct", action="store_true", help="agents skip the final alignment")
    add("--no-cp-tune", action="store_true",
        help="with --orientation cp: agents do not fine-tune their places on the circle")  # fmt: skip
    add("--research-rounds", type=int, default=None, metavar="K",
        help="re-search rounds (NAO paper 4.1.3 rule 2) before the agents stop (agent default)")  # fmt: skip
    march = p.add_mutually_exclusive_group()
    march.add_argument("--march", type=float, default=None, metavar="D",
                       help="after hold, the fleet marches D m along the pyramid's axis")  # fmt: skip
    march.add_argument("--march-to", default=None, metavar="X,Y",
                       help="after hold, the leader marches to (X, Y) m in the common frame")  # fmt: skip
    add("--reshape", action="append", default=[], type=_shape_arg, metavar="NAME|FILE",
        help="once the fleet holds, the operator commands it to take this shape (repeat: "
        "one after the other; docs/formation.md Reshaping); the final shape is judged")  # fmt: skip
    add("--reshape-wait", type=float, default=None, metavar="S",
        help=f"agents stay S s for a reshape command once the fleet holds (default with "
        f"--reshape: {RESHAPE_WAIT:g})")  # fmt: skip
    add("--publish-camera", action=argparse.BooleanOptionalAction, default=True,
        help="agents publish thumbnails of their camera frames with detections for viewers "
        "(run.mcap's /nao/ID/camera channels); on in the demo, off on real fleets")  # fmt: skip
    add("--world-timeout", type=float, default=FleetSpec.world_timeout)
    add("--noise-scale", type=float, default=FleetSpec.noise_scale, metavar="K",
        help="the world multiplies its walking and turning noise by K (python -m sim)")  # fmt: skip
    add("--look", type=look_arg, default=Look(), metavar="SPEC",
        help="python -m sim's --look: " + LOOK_HELP)  # fmt: skip
    add("--free-looks", action="store_true",
        help="python -m sim --free-looks: camera requests cost no sim time")  # fmt: skip
    add("--calibration", type=Path, default=None, metavar="DIR",
        help="every agent's --calibration: the recogniser's calibration folder built by "
        "python -m tools.calibrate (default: the built-in one)")  # fmt: skip
    add("--body", choices=("zenoh", "naoqi"), default=FleetSpec.body,
        help="agents drive the world over zenoh, or its virtual NAOs over qi (sim --naoqi)")  # fmt: skip
    add("--world-arg", action="append", default=[], help="extra argument for python -m sim")
    add("--renderer", choices=RENDERERS, default=None,
        help="python -m sim's and the render workers' --renderer (default: theirs, auto)")  # fmt: skip
    add("--render-service", type=int, default=0, metavar="K",
        help="K render workers (python -m sim.server.render_worker --shard i/K) draw the "
        f"cameras instead of the world (for large fleets, K <= {MAX_RENDER_WORKERS}; default 0: the world)")  # fmt: skip
    add("--agent-arg", action="append", default=[], type=agent_arg, metavar="ID:ARG",
        help="extra argument for robot ID's agent only, e.g. 3:--orientation=cp (an odd agent)")  # fmt: skip
    add("--credentials", type=Path, default=None,
        help="fleet credentials folder (default: a throwaway fleet in OUT/fleet)")  # fmt: skip
    add("--insecure", action="store_true", help="no TLS, access control or signatures (dev only)")
    add("--rogue", type=float, default=FleetSpec.rogue, metavar="S",
        help="attack the fleet with tools.rogue for S seconds while it works (docs/security.md)")  # fmt: skip
    add("--rogue-replay", type=Path, default=None, metavar="FILE",
        help="the rogue also replays this capture of an earlier run (rogue-*.capture)")  # fmt: skip
    add_live_arguments(p)
    add("--plain-links", action="store_true",
        help="tests: signatures over plain TCP links (no TLS/ACL), as behind a bad router")  # fmt: skip


#: Seconds the demo's agents stay for a reshape command once the fleet holds (the
#: operator sends it at once; after the last transition the run ends this much later).
RESHAPE_WAIT = 20.0


def _shape_arg(spec: str) -> Shape:
    try:
        return load_shape(spec)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _route(a: argparse.Namespace) -> Route | None:
    if a.march is not None:
        return Route(distance=a.march)
    if a.march_to is not None:
        xy = a.march_to.split(",")
        if len(xy) != 2:
            raise ValueError(f"--march-to wants X,Y, got {a.march_to!r}")
        return Route(to=(float(xy[0]), float(xy[1])))
    return None


def _calibration(p: argparse.ArgumentParser, folder: Path | None) -> Path | None:
    """``--calibration``'s folder, absolute, once it loads (a bad one: a usage error naming
    what is wrong, before any process starts)."""
    if folder is None:
        return None
    try:
        load(folder)
    except CalibrationError as exc:
        p.error(f"--calibration {folder}: {exc}")
    return folder.resolve()


def fleet_spec(p: argparse.ArgumentParser, a: argparse.Namespace) -> FleetSpec:
    """The spec of the flags of :func:`add_fleet_arguments` in ``a`` (``--scenario`` sets
    ``a.robots``, ``a.seed`` and ``a.scenario_ids`` from its file); ``p.error`` (a usage
    error, exit 2) where a value is refused."""
    check_live_argument(p, a.live)
    a.scenario_ids = None
    if a.scenario is not None:
        try:
            sc = scenarios.load(a.scenario)
        except (OSError, ValueError) as exc:
            p.error(f"--scenario {a.scenario}: {exc}")
        a.scenario_ids = sorted(r.id for r in sc.robots)
        a.robots, a.seed = len(a.scenario_ids), sc.seed
    rounds = {} if a.research_rounds is None else {"research_rounds": a.research_rounds}
    wait = a.reshape_wait if a.reshape_wait is not None else (RESHAPE_WAIT if a.reshape else 0.0)
    try:
        agent = agent_settings(
            p,
            a,
            orientation=a.orientation,
            strategy=a.strategy,
            shape=a.shape,
            timeout=a.agree_timeout,
            correct=not a.no_correct,
            cp_tune=not a.no_cp_tune,
            march=_route(a),
            publish_camera=a.publish_camera,
            reshape_wait=wait,
            **rounds,
        )
        return FleetSpec(
            robots=a.robots,
            seed=a.seed,
            agent=agent,
            agent_args=tuple(a.agent_arg),
            agent_log_level=a.agent_log_level,
            auto_ids=a.auto_ids,
            body=a.body,
            scenario=a.scenario,
            scenario_ids=None if a.scenario_ids is None else tuple(a.scenario_ids),
            isolated=a.isolated,
            headings=a.headings,
            obstacles=a.obstacles,
            noise_scale=a.noise_scale,
            look=a.look,
            free_looks=a.free_looks,
            calibration=_calibration(p, a.calibration),
            world_args=tuple(a.world_arg),
            renderer=a.renderer,
            render_workers=a.render_service,
            insecure=a.insecure,
            credentials=a.credentials,
            plain_links=a.plain_links,
            timeout=a.timeout,
            world_timeout=a.world_timeout,
            rogue=a.rogue,
            rogue_replay=a.rogue_replay,
            live=a.live,
            reshapes=tuple(a.reshape),
        )
    except ValueError as exc:
        p.error(str(exc))


def parse_fleet_spec(argv: list[str], prog: str = "fleet flags") -> FleetSpec:
    """The spec of a list of fleet flags (an evaluation tool's ``--demo-arg``s and its own);
    ``SystemExit`` (2) on a usage error."""
    p = argparse.ArgumentParser(prog=prog)
    add_fleet_arguments(p)
    return fleet_spec(p, p.parse_args(argv))
