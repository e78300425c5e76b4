"""``python -m agent``: one identical agent process per NAO (docs/design.md §1–3).

    python -m agent --id N|auto [--fleet-size N] [--connect EP]... [--listen EP]...
                    [--world-connect EP]...
                    [--no-multicast-scouting] [--mode peer|client] [--d-e M]
                    [--phi-e-deg 30] [--orientation pca|cp] [--strategy S]
                    [--shape NAME|FILE]
                    [--timeout S] [--member-grace S] [--join-timeout S]
                    [--research-rounds K] [--explore-step M]
                    [--reshape-wait S] [--body zenoh|naoqi]
                    [--nao tcp://HOST:9559] [--state-dir DIR] [--publish-camera]
                    [--exit-record FILE]

The body is the simulated world over zenoh (``--body zenoh``, the default) or a NAO
over its qi protocol (``--body naoqi --nao tcp://nao.local:9559``: a real robot, or a
virtual one served by ``python -m sim --naoqi``). Agents always talk zenoh to each other.

Every agent of a fleet must be started with the same planning parameters (``--d-e``,
``--phi-e-deg``, ``--orientation``, ``--strategy``, ``--shape``, the route): the agreement
compares their digests and stops the whole fleet, naming the odd robot, when they differ.
``--shape`` is a built-in (``pyramid``, the default, ``line``, ``column``, ``wedge``,
``circle``, ``grid``) or a formation file (docs/formation.md "Shapes"); a malformed file
is a usage error naming the bad field, before the agent joins the fleet; so is a file with
fewer slots than ``--fleet-size`` robots (without ``--fleet-size`` the plan stops on it).

``--world-connect EP`` (so that loss on the robots' radio spares the body): the body's queries to
the world (register, camera, walk, turn) go through a second zenoh session connected to ``EP`` (the
router's world port, ``agent.wire.WORLD_PORT``); records, digests, statuses and liveliness stay on
the first. Without it one session carries both.

``--publish-camera`` (for viewers): publish a small JPEG of each analysed camera frame, with
its detections, on ``nao/{id}/camera`` for viewers (at most 2 frames/s, ~10 kB/s; see
docs/agent.md). Off by default: opt in on a real fleet.

Exit status: 0 when the robot holds its place in the pyramid, 1 on a safe stop
(failed agreement, planning or motion; the reason is logged and published), 2 on a
usage error.
"""

from __future__ import annotations

import os

# One BLAS thread per agent, set before numpy is imported (many agents share a host's cores). An
# agent's linear algebra is small (a least squares over its fleet's sightings), and with many agents
# on one host (the simulation, ``docker compose --scale agent=50``) OpenBLAS's thread pools
# spun against each other: at 50 agents planning at once the machine spent its time in
# the kernel and a 2-second plan took minutes. An explicit setting still wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import contextlib
import dataclasses
import functools
import json
import logging
import math
import sys
from typing import TYPE_CHECKING

from agent.config import AgentConfig, add_plan_arguments
from agent.core.formation.params import D_E, PHI_E_DEG
from agent.core.nao import NAOQI_PORT
from agent.core.perception.sensor_fault import HELP as SENSOR_FAULT_HELP
from agent.core.perception.sensor_fault import SensorFault
from agent.wire import MAX_ROBOT_ID, NetworkSpec, add_network_arguments, network_spec

if TYPE_CHECKING:
    from collections.abc import Callable

    from agent.net.bus import Bus
    from agent.phases.roles import Crew, Recovery


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m agent", description=__doc__.split("\n\n")[0])
    p.add_argument("--id", required=True, help="robot id, or 'auto' to claim one from the world")
    p.add_argument("--fleet-size", type=int, default=None, help="require exactly N members")
    add_network_arguments(p, ("peer", "client"))
    p.add_argument(
        "--world-connect",
        action="append",
        default=[],
        metavar="EP",
        help="a second session for the world (body) connects here (the router's world port)",
    )
    p.add_argument("--d-e", type=float, default=D_E, help="expected parent-child distance (m)")
    p.add_argument(
        "--phi-e-deg", type=float, default=PHI_E_DEG, help="expected parent-child angle (deg)"
    )
    add_plan_arguments(p)
    p.add_argument(
        "--timeout",
        type=float,
        default=AgentConfig.timeout,
        help="agreement timeout: seconds without news from the fleet (s)",
    )
    p.add_argument(
        "--member-grace",
        type=float,
        default=AgentConfig.member_grace,
        help="s a member whose liveliness token vanished still counts (lossy links)",
    )
    p.add_argument(
        "--wave-timeout",
        type=float,
        default=AgentConfig.wave_timeout,
        help="wait limit for earlier waves (s)",
    )
    p.add_argument(
        "--join-timeout",
        type=float,
        default=300.0,
        help="s to keep trying to open the zenoh sessions while starting (lossy links)",
    )
    p.add_argument(
        "--research-rounds",
        type=int,
        default=None,
        help="re-search rounds (NAO paper 4.1.3 rule 2) before the fleet stops (agreed; default 2)",
    )
    p.add_argument(
        "--explore-step",
        type=float,
        default=None,
        help="first exploration leg of a robot that searches again (m, default 2)",
    )
    p.add_argument(
        "--reshape-wait",
        type=float,
        default=0.0,
        metavar="S",
        help=(
            "once the fleet holds its shape, stay S s listening for the operator's reshape "
            "command (python -m tools.fleet reshape), again after each reshape; 0 (default): "
            "exit at done"
        ),
    )
    p.add_argument(
        "--no-correct",
        action="store_true",
        help="skip the final visual alignment to the parent (the papers' open-loop ending)",
    )
    p.add_argument(
        "--no-cp-tune",
        action="store_true",
        help="with --orientation cp: do not fine-tune the place on the circle from a look at "
        "the centre robot (the AUV paper's 'no tune' rows)",
    )
    march = p.add_mutually_exclusive_group()
    march.add_argument(
        "--march",
        type=float,
        metavar="D",
        default=None,
        help="after hold, march D m along the pyramid's axis (agreed by the whole fleet)",
    )
    march.add_argument(
        "--march-to",
        metavar="X,Y",
        default=None,
        help="after hold, march the pyramid's leader to (X, Y) m in the common frame",
    )
    p.add_argument(
        "--body",
        choices=("zenoh", "naoqi"),
        default="zenoh",
        help="what the agent drives: the simulated world over zenoh, or a NAO over qi",
    )
    p.add_argument(
        "--nao",
        metavar="URL",
        default=None,
        help=f"qi URL of the NAO for --body naoqi (e.g. tcp://nao.local:{NAOQI_PORT})",
    )
    p.add_argument(
        "--state-dir",
        metavar="DIR",
        default=None,
        help="keep a durable journal here and resume from it after a crash",
    )
    p.add_argument(
        "--exit-record",
        metavar="FILE",
        default=None,
        help='append {"robot": ID} to FILE once this agent knows its robot (after --id auto '
        "claimed it), so that a supervisor can file the process's real exit status under the "
        'robot: it appends {"exit": CODE} when the process ends (docker-compose.yml)',
    )
    p.add_argument(
        "--sensor-fault",
        type=SensorFault.parse,
        default=None,
        metavar="KIND:AMOUNT",
        help=SENSOR_FAULT_HELP + " (evaluation only: tools.eval_headings)",
    )
    p.add_argument(
        "--publish-camera",
        action="store_true",
        help="publish thumbnails of the analysed camera frames with their detections on "
        "nao/ID/camera for viewers (at most 2 frames/s; off by default)",
    )
    p.add_argument(
        "--calibration",
        metavar="DIR",
        default=None,
        help="the recogniser's calibration folder (M-base, D-base, orange range), built from "
        "your own robots by python -m tools.calibrate (docs/real-naos.md); default: the "
        "built-in one, rendered from the simulated NAOs",
    )
    p.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    args = p.parse_args(argv)
    if args.id != "auto":
        try:
            rid = int(args.id)
        except ValueError:
            p.error(f"--id must be an integer or 'auto', got {args.id!r}")
        if not 0 <= rid <= MAX_ROBOT_ID:
            p.error(f"--id {rid} outside [0, {MAX_ROBOT_ID}]")
    if args.body == "naoqi":
        if not args.nao:
            p.error(f"--body naoqi needs --nao URL (e.g. tcp://nao.local:{NAOQI_PORT})")
        if args.id == "auto":
            p.error("--body naoqi needs a fixed --id (the robot at --nao)")
        if "://" not in args.nao:
            p.error(f"--nao {args.nao!r} is not a URL like tcp://HOST:{NAOQI_PORT}")
    elif args.nao:
        p.error("--nao needs --body naoqi")
    if args.fleet_size is not None and args.fleet_size < 1:
        p.error("--fleet-size must be >= 1")
    if args.fleet_size is not None:  # a formation file too short for the fleet: at start
        try:
            args.shape.check_fleet(args.fleet_size)
        except ValueError as exc:
            p.error(f"--shape: {exc}")
    if not (math.isfinite(args.d_e) and args.d_e > 0):
        p.error("--d-e must be > 0")
    if not 0 < args.phi_e_deg < 90:
        p.error("--phi-e-deg must be in (0, 90)")
    if not (math.isfinite(args.timeout) and args.timeout > 0):
        p.error("--timeout must be > 0")
    if not (math.isfinite(args.member_grace) and args.member_grace >= 0):
        p.error("--member-grace must be >= 0")
    if not (math.isfinite(args.join_timeout) and args.join_timeout >= 0):
        p.error("--join-timeout must be >= 0")
    if args.research_rounds is not None and not 0 <= args.research_rounds <= 10:
        p.error("--research-rounds must be in [0, 10]")
    if args.explore_step is not None and not (
        math.isfinite(args.explore_step) and 0.2 <= args.explore_step <= 5.0
    ):
        p.error("--explore-step must be in [0.2, 5] m")
    args.route = None
    try:
        from agent.core.formation.view.route import Route

        if args.march is not None:
            args.route = Route(distance=args.march)
        elif args.march_to is not None:
            parts = args.march_to.split(",")
            if len(parts) != 2:
                raise ValueError(f"--march-to wants X,Y, got {args.march_to!r}")
            args.route = Route(to=(float(parts[0]), float(parts[1])))
    except ValueError as exc:
        p.error(str(exc))
    return args


def agent_config(args: argparse.Namespace, rid: int) -> AgentConfig:
    """The agent's settings from its flags (:meth:`AgentConfig.to_argv` writes them back);
    ``rid``: the robot it drives (``--id``, or the one it claimed)."""
    optional = {"research_rounds": args.research_rounds, "explore_step": args.explore_step}
    return AgentConfig(
        robot_id=rid,
        fleet_size=args.fleet_size,
        d_e=args.d_e,
        phi_e=math.radians(args.phi_e_deg),
        orientation=args.orientation,
        strategy=args.strategy,
        shape=args.shape,
        timeout=args.timeout,
        wave_timeout=args.wave_timeout,
        member_grace=args.member_grace,
        correct=not args.no_correct,
        cp_tune=not args.no_cp_tune,
        reshape_wait=args.reshape_wait,
        march=args.route,
        sensor_fault=args.sensor_fault,
        publish_camera=args.publish_camera,
        **{k: v for k, v in optional.items() if v is not None},
    )


def open_bus(args: argparse.Namespace, log: logging.Logger) -> tuple[Bus, Bus, int]:
    """The agent's bus, its world (body) bus and its robot id.

    The world bus is the bus itself unless ``--world-connect`` gives the world's own
    endpoints (then it is a second session, opened first, that registers and drives the
    body). Secure, ``--id N``: the sessions open with robot N's key. Secure, ``--id
    auto``: for each robot key in the credentials folder (sorted), open a world session
    with it and ask the world for that id; the world grants an id only to the key that
    owns it, so the first free one wins; revoked keys are skipped, and a folder holding
    only revoked ones is refused saying so. Insecure: ``--id auto`` takes the lowest free id.
    """
    from agent.body.zenoh_world import register
    from agent.net.bus import Bus, BusConfig, open_retrying

    def session(spec: BusConfig) -> Bus:
        """A session, tried again for ``--join-timeout`` s (a lossy start only delays)."""
        return open_retrying(lambda: Bus(spec), args.join_timeout)

    from agent.body.base import BodyError
    from agent.wire.trust import Credentials, Identity

    def opened(spec: NetworkSpec, world: Bus | None, rid: int) -> tuple[Bus, Bus, int]:
        if world is None:  # one session for both
            bus = session(spec)
            return bus, bus, rid
        try:
            return session(spec), world, rid
        except BaseException:
            world.close()
            raise

    def world_bus(spec: NetworkSpec) -> Bus | None:
        if not args.world_connect:
            return None
        return session(dataclasses.replace(spec, connect=tuple(args.world_connect), listen=()))

    if args.id != "auto":
        rid = int(args.id)
        spec = network_spec(args, f"robot-{rid}")
        return opened(spec, world_bus(spec), rid)
    spec = network_spec(args, "robot-0")
    creds = Credentials(spec.credentials) if spec.secure else None
    candidates = [-1] if creds is None else creds.own_robot_keys()
    revoked = [] if creds is None else creds.revoked_robot_keys()
    if creds is not None and revoked:
        gone = [f"robot-{r} ({creds.revoked[Identity.robot(r)].describe()})" for r in revoked]
        if not candidates:
            raise ValueError(
                f"{spec.credentials} holds only revoked robot keys: the fleet CA revoked "
                f"{', '.join(gone)} in {creds.paths.crl}; this key may no longer join the "
                "fleet (docs/security.md, 'Revoking a key')"
            )
        log.warning("not claiming with revoked keys: %s", ", ".join(gone))
    if not candidates:
        raise ValueError(f"{spec.credentials} holds no robot key to claim a robot with")
    reasons = []
    for want in candidates:
        mine = dataclasses.replace(spec, identity=f"robot-{want}") if want >= 0 else spec
        wbus = world_bus(mine)
        asker = wbus if wbus is not None else session(mine)
        try:
            got = register(asker, want, timeout=30.0)
        except BodyError as exc:
            asker.close()
            reasons.append(str(exc))
            continue
        log.info("claimed robot %d%s", got, " with its key" if want >= 0 else "")
        if wbus is None:
            return asker, asker, got
        return opened(mine, wbus, got)
    if not spec.secure:
        raise BodyError("register", reasons[0])
    raise BodyError(
        "register", f"no robot could be claimed with keys {candidates}: {'; '.join(reasons)}"
    )


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    logging.basicConfig(
        level=args.log_level,
        format="%(asctime)s agent[%(process)d] %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    log = logging.getLogger("agent")
    # Imported here so that `--help` and usage errors need no zenoh session.
    from agent.body.base import Body, BodyError
    from agent.body.zenoh_world import ZenohBody, camera_waits
    from agent.net.bus import BusError
    from agent.phases.runner import Runner, report_unavailable

    calibration = None
    if args.calibration is not None:  # a bad folder is a usage error: before any session
        from agent.core.perception.calibration import CalibrationError, load

        try:
            calibration = load(args.calibration)
        except CalibrationError as exc:
            print(f"python -m agent: --calibration: {exc}", file=sys.stderr)
            return 2
    try:
        opened = open_bus(args, log)
    except ValueError as exc:  # usage: bad flags, no credentials (TrustError is one too)
        print(f"python -m agent: {exc}", file=sys.stderr)
        return 2
    except (BodyError, BusError) as exc:  # no world, no robot to claim, no session
        log.error("%s", exc)
        return 1
    bus, world_bus, rid = opened
    if args.exit_record:
        try:
            with open(args.exit_record, "a", encoding="utf-8") as f:
                f.write(json.dumps({"robot": rid}) + "\n")
        except OSError as exc:  # the supervisor then files the exit under no robot
            log.warning("no exit record in %s: %s", args.exit_record, exc)
    with bus, contextlib.ExitStack() as stack:
        if world_bus is not bus:
            stack.enter_context(world_bus)
        try:
            from agent.adapters import FormationAdapter, PerceptionAdapter

            perception = PerceptionAdapter(calibration)
            formation = FormationAdapter()
        except (ValueError, OSError, ImportError) as exc:
            return report_unavailable(bus, rid, f"perception or formation unavailable: {exc}")
        cal = perception.calibration
        log.info("calibration %s (%s)", cal.digest[:16], cal.source)
        body: Body
        if args.body == "naoqi":
            from agent.body.naoqi import NaoqiBody

            try:
                body = NaoqiBody(args.nao, rid)
            except BodyError as exc:
                return report_unavailable(bus, rid, str(exc))
        else:
            attempt, total = camera_waits(args.fleet_size)  # the world's queue (large fleets)
            body = ZenohBody(world_bus, rid, camera_timeout=total, camera_attempt=attempt)
        recovery: Callable[[Crew], Recovery] | None = None
        if args.state_dir:
            from agent.recovery.crash_recovery import CrashRecovery
            from agent.recovery.journal import Journal

            try:
                recovery = functools.partial(CrashRecovery, Journal(args.state_dir, rid))
            except (OSError, ValueError) as exc:
                log.error("no journal in %s: %s", args.state_dir, exc)
        try:
            runner = Runner(
                bus,
                body,
                dataclasses.replace(agent_config(args, rid), calibration=cal.digest),
                perception,
                formation,
                recovery=recovery,
            )
            log.info("robot %d builds the shape %s", rid, args.shape.text())
            code = runner.run()
        finally:
            body.close()
        st = bus.stats
        log.info(
            "robot %d exit %d: published %d B (%s), compass %d/%d failed, "
            "%d drift(s) re-measured, rejected %d (untrusted %d), dropped %d",
            rid,
            code,
            st.total_published,
            ", ".join(
                f"{k} {v} B/{st.published_count[k]}" for k, v in sorted(st.published_bytes.items())
            ),
            runner.motion.compass_failures,
            runner.motion.compass_uses,
            runner.motion.drift_checks,
            st.rejected,
            st.untrusted,
            st.dropped,
        )
        log.info("robot %d phases (wall/CPU s): %s", rid, runner.ctx.report.timeline.costs())
        return code


if __name__ == "__main__":
    raise SystemExit(main())
