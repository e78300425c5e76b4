"""``python -m sim``: start the simulated world and serve it on the bus.

Prints ``sim ready robots=1,2,3`` on stdout once every queryable is declared; logs go to
stderr. Stops cleanly on SIGINT/SIGTERM.

With ``--naoqi`` every robot is also a virtual NAO (:mod:`sim.naoqi_gateway`): NAOqi
services over the qi protocol, one service directory per robot on its own port, each
announced before the ready line as ``sim naoqi robot=ID url=tcp://HOST:PORT``.

``--look SPEC`` changes what the world looks like (:mod:`sim.camera.look`: the NAOs' orange,
light, colour temperature, noise, motion blur, auto exposure); ``--free-looks`` makes
camera requests cost no sim time (:mod:`sim.server.glances`: by default a look costs a robot
the time a NAO takes to turn its head, settle and capture).

With ``--reply-delay MAX_S`` the world is slow: every camera and motion reply is held
for a seeded random delay up to ``MAX_S`` s (:mod:`sim.server.delays`), the world serving on.
"""

from __future__ import annotations

import argparse
import signal
import sys
from dataclasses import replace
from typing import Any

from agent.wire import add_network_arguments, network_spec, picture
from sim import scenarios
from sim.camera import renderer
from sim.camera.look import HELP as LOOK_HELP
from sim.camera.look import Look
from sim.physics.world import World
from sim.server.delays import check_max_delay
from sim.server.server import WorldServer


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m sim",
        description=(
            "The simulated world: a PyBullet room with NAO robots, serving each robot's "
            "forehead camera and walking over zenoh (keys world/**, see docs/design.md §3). "
            "Prints 'sim ready robots=...' on stdout when it serves."
        ),
    )
    p.add_argument(
        "--robots", type=int, default=3, help="robots of a generated scenario (ids 1..N)"
    )
    p.add_argument("--seed", type=int, default=7, help="seed of the scenario, textures and noise")
    p.add_argument(
        "--scenario",
        help="scenario JSON file (replaces --robots/--seed/--obstacles/--clutter/--light/--isolated)",
    )
    p.add_argument("--obstacles", type=int, default=0, help="static cylinders (generated)")
    p.add_argument("--clutter", type=int, default=0, help="orange lookalike cubes (generated)")
    p.add_argument(
        "--isolated",
        action="store_true",
        help="the last robot (generated) stands 2-3 m from every other (far end of sight)",
    )
    p.add_argument("--light", type=float, default=1.0, help="light intensity (1.0 = default)")
    p.add_argument(
        "--headings",
        type=scenarios.Headings.parse,
        default=scenarios.Headings(),
        metavar="KIND",
        help=scenarios.HEADINGS_HELP,
    )
    p.add_argument(
        "--look",
        default=None,
        metavar="SPEC",
        help=LOOK_HELP + "; replaces a --scenario file's look",
    )
    p.add_argument(
        "--free-looks",
        action="store_true",
        help="camera requests cost no sim time (recordings made before looks were charged; "
        "default: a look costs the head turn, settling and capture, sim/server/glances.py)",
    )
    p.add_argument("--no-noise", action="store_true", help="noiseless walking and turning")
    p.add_argument(
        "--noise-scale",
        type=float,
        default=1.0,
        metavar="K",
        help="multiply the walking and turning noise by K "
        "(default 1; see sim/physics/locomotion.py)",
    )
    p.add_argument(
        "--speed",
        type=float,
        default=0.0,
        help="pace the sim clock at K x real time (default 0: as fast as possible)",
    )
    p.add_argument("--truth-rate", type=float, default=10.0, help="truth/clock publications per s")
    p.add_argument(
        "--render-workers",
        type=int,
        default=0,
        help="render camera images in K worker processes (default 0: in the world process)",
    )
    p.add_argument(
        "--reply-delay",
        type=float,
        default=0.0,
        metavar="MAX_S",
        help="a slow world: hold every camera and motion reply for a random delay in "
        "[0, MAX_S] s, drawn from the scenario's seed (default 0: at once; sim/server/delays.py)",
    )
    add_network_arguments(p, ("peer", "client", "router"))
    p.add_argument(
        "--naoqi",
        action="store_true",
        help="also serve every robot as a virtual NAO over qi (ALMotion, ALVideoDevice, ...)",
    )
    p.add_argument("--naoqi-host", default="127.0.0.1", help="address the virtual NAOs listen on")
    p.add_argument(
        "--naoqi-port",
        type=int,
        default=0,
        help="port of the first robot's NAO, the next robots on the following ports "
        "(default 0: a free port each)",
    )
    p.add_argument(
        "--renderer",
        choices=renderer.RENDERERS,
        default=renderer.DEFAULT,
        help=renderer.RENDERER_HELP,
    )
    p.add_argument(
        "--camera-encoding",
        choices=picture.ENCODINGS,
        default=picture.DEFAULT_ENCODING,
        help=picture.ENCODING_HELP,
    )
    p.add_argument("--gui", action="store_true", help="open the PyBullet GUI (needs a display)")
    p.add_argument("--dump-scenario", metavar="FILE", help="write the scenario used to FILE")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if not (args.speed >= 0 and args.speed < float("inf")):
            raise ValueError(f"--speed {args.speed}: must be >= 0 (0: as fast as possible)")
        if not (0 < args.truth_rate <= 1000):
            raise ValueError(f"--truth-rate {args.truth_rate}: must be in (0, 1000]")
        check_max_delay(args.reply_delay)
        if args.scenario:
            sc = scenarios.load(args.scenario)
        else:
            light = scenarios.LightSpec(intensity=args.light)
            sc = scenarios.generate(
                args.robots,
                args.seed,
                obstacles=args.obstacles,
                clutter=args.clutter,
                light=light,
                isolated=args.isolated,
                headings=args.headings,
            )
        if args.look is not None:
            sc = replace(sc, look=Look.parse(args.look))
        if args.dump_scenario:
            scenarios.dump(sc, args.dump_scenario)
        net = network_spec(args, "world")
    except (OSError, ValueError) as exc:
        print(f"sim: {exc}", file=sys.stderr)
        return 2
    try:
        world = World(
            sc,
            gui=args.gui,
            noise=not args.no_noise,
            noise_scale=args.noise_scale,
            renderer=args.renderer,
        )
    except (ValueError, RuntimeError) as exc:  # RuntimeError: --renderer egl did not load
        print(f"sim: {exc}", file=sys.stderr)
        return 2
    print(f"sim: renderer {world.renderer} ({world.renderer_why})", file=sys.stderr, flush=True)
    if not sc.look.is_default():
        print(f"sim: look {sc.look}", file=sys.stderr, flush=True)
    with world:
        try:
            server = WorldServer(
                world,
                net,
                speed=args.speed,
                truth_rate=args.truth_rate,
                render_workers=args.render_workers,
                reply_delay=args.reply_delay,
                reply_delay_seed=sc.seed,
                free_looks=args.free_looks,
                camera_encoding=args.camera_encoding,
            )
        except ValueError as exc:
            print(f"sim: {exc}", file=sys.stderr)
            return 2

        def on_signal(signum: int, frame: Any) -> None:
            server.stop()

        signal.signal(signal.SIGINT, on_signal)
        signal.signal(signal.SIGTERM, on_signal)
        try:
            server.open()
        except Exception as exc:
            print(f"sim: cannot open the zenoh session: {exc}", file=sys.stderr)
            server.close()
            return 1
        gateway = None
        if args.naoqi:
            from sim.naoqi_gateway import NaoqiGateway

            try:
                gateway = NaoqiGateway(server, args.naoqi_host, args.naoqi_port)
                for rid, url in gateway.open().items():
                    print(f"sim naoqi robot={rid} url={url}", flush=True)
            except Exception as exc:
                print(f"sim: cannot serve the virtual NAOs: {exc}", file=sys.stderr)
                server.close()
                return 1
        ids = ",".join(str(r) for r in world.robot_ids)
        print(f"sim ready robots={ids} room={sc.room:g} seed={sc.seed}", flush=True)
        try:
            server.serve()
        finally:
            if gateway is not None:
                gateway.close()
            server.close()
    print("sim stopped", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
