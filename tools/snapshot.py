"""``python -m tools.snapshot``: what a robot's forehead camera sees, or a plan view.

Starts a world in-process (``--robots N --seed S`` or ``--scenario FILE``), or joins a
running one over zenoh (``--connect ENDPOINT``), and saves robot ``--robot``'s camera
image at head yaw ``--yaw`` (degrees) to ``--out``. ``--top-down`` saves instead a plan
view (matplotlib) with the room, every robot's id and heading, obstacles, clutter and
the chosen robot's field of view. ``--place ID:X:Y:HEADING_DEG`` (repeatable, in-process
only) moves robots first, e.g. to look at a NAO 0.6 m ahead turned by some angle::

    python -m tools.snapshot --robots 2 --place 1:0:0:90 --place 2:0:0.6:270 --out front.png

``--look SPEC`` (in-process) draws the world in a look (:mod:`sim.camera.look`).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path

import cv2

from agent.wire import add_network_arguments
from sim import scenarios
from sim.camera.camera import HFOV
from sim.camera.look import HELP as LOOK_HELP
from sim.camera.look import look_arg
from sim.physics.nao_model import FOOTPRINT_RADIUS


def parse_place(text: str) -> tuple[int, float, float, float]:
    parts = text.split(":")
    if len(parts) != 4:
        raise ValueError(f"--place {text!r}: expected ID:X:Y:HEADING_DEG")
    try:
        return int(parts[0]), float(parts[1]), float(parts[2]), math.radians(float(parts[3]))
    except ValueError:
        raise ValueError(f"--place {text!r}: ID must be an int, X Y HEADING numbers") from None


def plan_view(
    poses: dict[int, tuple[float, float, float]],
    sc: scenarios.Scenario | None,
    room: float,
    robot: int,
    yaw: float,
    out: Path,
    title: str,
) -> None:
    """Save a plan view: robots (discs of the contact radius) with ids and headings."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 7))
    ax.plot([-room, room, room, -room, -room], [-room, -room, room, room, -room], "k-", lw=2)
    if sc is not None:
        for ob in sc.obstacles:
            ax.add_patch(plt.Circle((ob.x, ob.y), ob.radius, color="0.5"))
        for cl in sc.clutter:
            ax.add_patch(
                plt.Rectangle(
                    (cl.x - cl.size / 2, cl.y - cl.size / 2), cl.size, cl.size, color="#ff3800"
                )
            )
    for rid in sorted(poses):
        x, y, th = poses[rid]
        ax.add_patch(plt.Circle((x, y), FOOTPRINT_RADIUS, fill=False, lw=1.5, color="tab:blue"))
        ax.arrow(x, y, 0.25 * math.cos(th), 0.25 * math.sin(th), width=0.02, color="tab:orange")
        ax.text(x + 0.12, y - 0.22, str(rid), fontsize=11, weight="bold")
        if rid == robot:
            psi = th + yaw
            for s in (-1, 1):
                a = psi + s * HFOV / 2
                ax.plot([x, x + 1.6 * math.cos(a)], [y, y + 1.6 * math.sin(a)], "g--", lw=1)
    ax.set_aspect("equal")
    ax.set_xlim(-room - 0.2, room + 0.2)
    ax.set_ylim(-room - 0.2, room + 0.2)
    ax.set_xlabel("x (m, east)")
    ax.set_ylabel("y (m, north)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)


def run_local(args: argparse.Namespace, out: Path) -> int:
    from sim.physics.world import World

    if args.scenario:
        sc = scenarios.load(args.scenario)
    else:
        sc = scenarios.generate(
            args.robots, args.seed, obstacles=args.obstacles, clutter=args.clutter
        )
    if args.look is not None:
        sc = replace(sc, look=args.look)
    with World(sc) as w:
        for rid, x, y, th in args.place:
            w.set_pose(rid, x, y, th)
        if args.robot not in w.robot_ids:
            print(f"snapshot: no robot {args.robot} (robots {list(w.robot_ids)})", file=sys.stderr)
            return 2
        yaw = math.radians(args.yaw)
        if args.top_down:
            plan_view(w.poses(), sc, sc.room, args.robot, yaw, out, f"seed {sc.seed}: plan view")
        else:
            img = w.render(args.robot, yaw)
            cv2.imwrite(str(out), img)
    return 0


def run_remote(args: argparse.Namespace, out: Path) -> int:
    """Ask a running world (``sim.server.client``'s link: sealed with credentials, or not)."""
    import zenoh

    from agent.wire import CameraReply, CameraRequest, key_camera, network_spec
    from sim.server.client import Link, WorldError, ask, save_picture, truth

    spec = network_spec(args, "observer" if args.top_down else f"robot-{args.robot}")
    cfg = zenoh.Config()
    for k, v in spec.json5_items():
        cfg.insert_json5(k, v)
    with zenoh.open(cfg) as s:
        link = Link(s, spec)
        try:
            if args.top_down:
                msg = truth(link, args.timeout)
                poses = {p[0]: (p[1], p[2], p[3]) for p in msg.poses}
                room = max(2.0, max(max(abs(x), abs(y)) for x, y, _ in poses.values()) + 1.0)
                plan_view(
                    poses, None, room, args.robot, math.radians(args.yaw), out,
                    f"t = {msg.t_sim:.1f} s",
                )  # fmt: skip
                return 0
            req = CameraRequest(yaw=math.radians(args.yaw))
            rep = ask(link, key_camera(args.robot), req, args.timeout)
        except WorldError as exc:
            print(f"snapshot: {exc}", file=sys.stderr)
            return 1
    if not isinstance(rep, CameraReply):
        print(f"snapshot: unexpected reply {type(rep).__name__}", file=sys.stderr)
        return 1
    try:
        save_picture(rep, out)
    except ValueError as exc:
        print(f"snapshot: {exc}", file=sys.stderr)
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tools.snapshot", description=__doc__.split("\n")[0])
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--scenario", help="scenario JSON file")
    p.add_argument("--obstacles", type=int, default=0)
    p.add_argument("--clutter", type=int, default=0)
    p.add_argument("--robot", type=int, default=1, help="whose camera")
    p.add_argument("--yaw", type=float, default=0.0, help="head yaw in degrees (+ left)")
    p.add_argument("--top-down", action="store_true", help="plan view instead of the camera")
    p.add_argument("--place", action="append", default=[], help="ID:X:Y:HEADING_DEG")
    p.add_argument("--look", type=look_arg, default=None, metavar="SPEC", help=LOOK_HELP)
    add_network_arguments(p, ("peer", "client"))
    p.add_argument("--timeout", type=float, default=20.0)
    p.add_argument("--out", default="view.png")
    args = p.parse_args(argv)
    try:
        args.place = [parse_place(t) for t in args.place]
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        code = run_remote(args, out) if args.connect else run_local(args, out)
    except (OSError, ValueError) as exc:
        print(f"snapshot: {exc}", file=sys.stderr)
        return 2
    if code == 0:
        print(f"wrote {out}")
    return code


if __name__ == "__main__":
    raise SystemExit(main())
