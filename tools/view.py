"""``python -m tools.view``: watch a fleet live, in Foxglove or in a browser page (docs/design.md
§10 "Seeing the fleet"; docs/view.md).

    python -m tools.view --connect tls/ROUTER:7447 --credentials observer/ [--web]
    python -m tools.view --connect tcp/127.0.0.1:7447 --insecure --web
    python -m tools.view --replay out/demo/run.mcap [--speed 2] [--loop] --web

``--connect``: joins a real fleet's bus as an observer (secure: a zenoh client of the TLS
router with the ``observer`` identity of ``--credentials``, which the ACL lets only
subscribe; every message shown has passed the signature check) and serves what it sees
as Foxglove's well-known schemas over the Foxglove WebSocket protocol (``--live``,
default 127.0.0.1:8765): the same scene builder as the recorder
(:class:`tools.harness.view.scene.Scene`). ``--record FILE`` also writes the MCAP recording.

``--replay FILE``: the wire channels of a recording (``tools.demo``'s run.mcap) fed
through the same scene builder at their recorded pace (``--speed K`` times faster),
once or in a loop.

The plan's targets are drawn when the scene's planning parameters are the fleet's (the
plan is recomputed from the signed records and drawn when its digest is one an agent
reported): ``--shape NAME|FILE``, ``--d-e``, ``--phi-e-deg``, ``--orientation`` and
``--strategy``, as the agents were given them. A replay takes them from the run's
``result.json`` beside the recording, where there is one; a flag given overrides it; the
rest are the agents' defaults (the pyramid).

``--web [HOST:PORT]`` (default 127.0.0.1:8080) serves the page in the browser
(:mod:`tools.harness.view.webpage`): top-down map, each robot's phase, camera views, log.
Runs until Ctrl-C, or ``--for S`` seconds.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from pathlib import Path
from typing import Any

from agent.config import load_shape
from agent.core.formation.params import D_E, ORIENTATIONS, PHI_E_DEG, PLAN_STRATEGIES, PlanParams
from agent.core.formation.shape.spec import PYRAMID
from agent.wire import TruthPosesMsg, decode, reason
from tools.harness.view.live import DEFAULT_LIVE, Fanout, LiveServer, check_live_argument, serve
from tools.harness.view.scene import Scene
from tools.harness.view.webpage import DEFAULT_WEB, PageServer, serve_page


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m tools.view", description=__doc__.split("\n\n")[0])
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--connect", action="append", metavar="ENDPOINT", help="the fleet's router")
    src.add_argument("--replay", type=Path, metavar="FILE", help="a recording (run.mcap)")
    p.add_argument("--credentials", default="", metavar="DIR", help="the observer's credentials")
    p.add_argument("--insecure", action="store_true", help="no TLS or signatures (dev fleets)")
    p.add_argument("--live", default=DEFAULT_LIVE, metavar="HOST:PORT", help="WebSocket server")
    p.add_argument(
        "--web", nargs="?", const=DEFAULT_WEB, default=None, metavar="HOST:PORT",
        help=f"serve the page in the browser (default {DEFAULT_WEB})",
    )  # fmt: skip
    p.add_argument("--record", type=Path, default=None, metavar="FILE", help="also write MCAP")
    p.add_argument("--speed", type=float, default=1.0, help="replay K times faster")
    p.add_argument("--loop", action="store_true", help="replay again and again")
    p.add_argument("--for", dest="seconds", type=float, default=0.0, help="stop after S s")
    p.add_argument(
        "--screenshot", type=Path, default=None, metavar="PNG",
        help="with --web: once every robot is on the page, save its screenshot and stop "
        "(Playwright and the system's chromium: pip install '.[view]')",
    )  # fmt: skip
    p.add_argument(
        "--screenshot-after", type=float, default=1.0, metavar="S",
        help="take the screenshot no sooner than S s after the page showed every robot",
    )  # fmt: skip
    plan = p.add_argument_group("the fleet's planning parameters (default: a replay's result.json)")
    plan.add_argument("--shape", default=None, metavar="NAME|FILE", help="the formation")
    plan.add_argument("--d-e", type=float, default=None, help="the edge length d_e (m)")
    plan.add_argument("--phi-e-deg", type=float, default=None, help="φ_e (deg)")
    plan.add_argument("--orientation", choices=ORIENTATIONS, default=None)
    plan.add_argument("--strategy", choices=PLAN_STRATEGIES, default=None)
    a = p.parse_args(argv)
    try:
        a.params = plan_params(a)
    except ValueError as exc:
        p.error(f"planning parameters: {exc}")
    if a.screenshot is not None and a.web is None:
        a.web = "127.0.0.1:0"
    check_live_argument(p, a.live)
    if a.connect and not a.credentials and not a.insecure:
        p.error("--connect needs --credentials DIR (the observer identity) or --insecure")
    if not a.speed > 0:
        p.error("--speed must be > 0")
    return a


#: the planning flags and the keys of a run's result.json that give them
PLAN_KEYS = {
    "shape": "shape_spec",
    "d_e": "d_e",
    "phi_e_deg": "phi_e_deg",
    "orientation": "orientation",
    "strategy": "strategy",
}


def plan_params(a: argparse.Namespace) -> PlanParams:
    """The fleet's planning parameters: the flags given, else a replay's ``result.json``
    (``tools.demo`` and the harness write it beside ``run.mcap``), else the defaults.
    ``ValueError`` for a ``result.json`` that is no JSON object, a value of the wrong type,
    a shape that does not load, parameters the planner refuses."""
    known: dict[str, object] = {}
    meta = a.replay.parent / "result.json" if a.replay is not None else None
    if meta is not None and meta.is_file():
        try:
            result = json.loads(meta.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{meta}: {reason(exc)}") from exc
        if not isinstance(result, dict):
            raise ValueError(f"{meta}: not a JSON object")
        known = {flag: result[key] for flag, key in PLAN_KEYS.items() if key in result}
    known.update({f: getattr(a, f) for f in PLAN_KEYS if getattr(a, f) is not None})
    try:
        shape = load_shape(_text(known, "shape", PYRAMID.name))
    except ValueError as exc:
        raise ValueError(f"{exc} (--shape NAME|FILE gives the fleet's)") from exc
    return PlanParams(
        d_e=_number(known, "d_e", D_E),
        phi_e=math.radians(_number(known, "phi_e_deg", PHI_E_DEG)),
        orientation=_text(known, "orientation", "pca"),
        strategy=_text(known, "strategy", "default"),
        shape=shape,
    )


def _number(known: dict[str, object], name: str, default: float) -> float:
    v = known.get(name, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"{name}: {v!r} is not a number")
    return float(v)


def _text(known: dict[str, object], name: str, default: str) -> str:
    v = known.get(name, default)
    if not isinstance(v, str):
        raise ValueError(f"{name}: {v!r} is not a string")
    return v


class Feed:
    """The scene builder fed message by message, its channels to ``live`` (and to the
    recording of ``record``), world time from the ground truth as the recorder keeps it."""

    def __init__(
        self, live: LiveServer, record: Path | None, scenario: Path | None, params: PlanParams
    ) -> None:
        from tools.harness.observe import Recorder

        self.rec = Recorder(record, params=params, sinks=[live]) if record is not None else None
        self.scene = (
            self.rec.scene
            if self.rec is not None
            else Scene(Fanout(live.emit, []), params=params, scenario=scenario, since_ns=0)
        )
        self.world_ns = 0
        self.rejected = 0

    def take(self, key: str, msg: Any) -> None:
        if self.rec is not None:
            self.rec.record(key, msg)
            return
        if isinstance(msg, TruthPosesMsg):
            self.world_ns = max(self.world_ns, round(msg.t_sim * 1e9))
        try:
            self.scene.take(key, msg, self.world_ns)
        except Exception as exc:  # as the recorder: a bad message never stops the view
            self.rejected += 1
            print(f"view: message on {key}: {reason(exc)}", file=sys.stderr)

    def finish(self) -> None:
        if self.rec is not None:
            self.rec.close()
        else:
            self.scene.finish()


def wire_messages(path: Path) -> list[tuple[int, str, bytes]]:
    """The wire channels of a recording: (publish time ns, key, payload), in order."""
    from mcap.reader import make_reader

    out = []
    with path.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if channel.message_encoding == "msgpack":
                out.append((message.publish_time, channel.topic, message.data))
    out.sort(key=lambda m: m[0])
    return out


class Stop:
    """When a view stops: after ``--for`` seconds, or when :meth:`set` (the screenshot)."""

    def __init__(self, seconds: float) -> None:
        self.end = time.monotonic() + seconds if seconds > 0 else float("inf")
        self.event = threading.Event()

    def set(self) -> None:
        self.event.set()

    def __bool__(self) -> bool:
        return self.event.is_set() or time.monotonic() > self.end


def replay(args: argparse.Namespace, live: LiveServer, stop: Stop) -> None:
    msgs = wire_messages(args.replay)
    if not msgs:
        raise SystemExit(f"view: no wire messages in {args.replay}")
    rounds = 0
    while True:
        rounds += 1
        feed = Feed(live, None, args.replay.parent / "scenario.json", args.params)
        t0_rec, t0 = msgs[0][0], time.monotonic()
        print(f"view: replaying {args.replay} ({len(msgs)} messages), round {rounds}", flush=True)
        for t_ns, key, data in msgs:
            due = t0 + (t_ns - t0_rec) / 1e9 / args.speed
            while (wait := due - time.monotonic()) > 0:
                if stop:
                    return
                time.sleep(min(wait, 0.1))
            try:
                feed.take(key, decode(data))
            except Exception as exc:  # ProtocolError: counted as the replay tool does
                feed.rejected += 1
                print(f"view: message on {key}: {reason(exc)}", file=sys.stderr)
        feed.finish()
        print(f"view: replay round {rounds} over", flush=True)
        if not args.loop:
            while not stop:
                time.sleep(0.2)
            return
        time.sleep(2.0)
        if stop:
            return


def watch_fleet(args: argparse.Namespace, live: LiveServer, stop: Stop) -> None:
    from agent.net.bus import Bus, BusConfig
    from tools.harness.observe import watch

    secure = bool(args.credentials) and not args.insecure
    bus = Bus(
        BusConfig(
            connect=tuple(args.connect),
            multicast_scouting=False,
            mode="client" if secure else "peer",
            credentials=args.credentials if secure else "",
            identity="observer" if secure else "",
        )
    )
    feed = Feed(live, args.record, None, args.params)
    try:
        watch(bus)
        print("view: watching the fleet", flush=True)
        while not stop:
            for ev in bus.drain(0.1):
                if ev.kind == "msg":
                    feed.take(ev.key, ev.msg)
    finally:
        bus.close()
        feed.finish()


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    live = serve(args.live)
    page: PageServer | None = serve_page(args.web, live.url) if args.web is not None else None
    stop = Stop(args.seconds)
    source = replay if args.replay is not None else watch_fleet
    code = 0
    try:
        if args.screenshot is not None and page is not None:
            worker = threading.Thread(target=source, args=(args, live, stop), daemon=True)
            worker.start()
            try:
                code = screenshot(page.url, args.screenshot, stop, args.screenshot_after)
            finally:
                stop.set()
                worker.join(30)
        else:
            source(args, live, stop)
    except KeyboardInterrupt:
        pass
    finally:
        if page is not None:
            page.close()
        live.close()
    return code


def screenshot(url: str, path: Path, stop: Stop, after: float = 1.0) -> int:
    """Open the page in the system's headless chromium (Playwright), wait until every
    robot of the scene has a card with a phase and a place on the map, save ``path``."""
    import shutil

    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        print("view: --screenshot needs Playwright: pip install '.[view]'", file=sys.stderr)
        return 2
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        print("view: --screenshot needs chromium (apt-get install chromium)", file=sys.stderr)
        return 2
    with sync_playwright() as pw:
        browser = pw.chromium.launch(
            executable_path=exe, args=["--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu"]
        )
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(url)
            while not stop:
                ready = page.evaluate(READY)
                if ready:
                    time.sleep(max(0.0, after))
                    path.parent.mkdir(parents=True, exist_ok=True)
                    page.screenshot(path=str(path))
                    print(f"view: screenshot {path}", flush=True)
                    return 0
                time.sleep(0.5)
        finally:
            browser.close()
    print("view: no screenshot: the robots never all showed", file=sys.stderr)
    return 1


#: the page shows the fleet: every robot with a card with a phase and a place on the map
READY = """() => {
    const v = window.naoView;
    if (!v || !v.connected) return false;
    const rs = Object.values(v.robots);
    return rs.length > 0 && rs.every(r => r.x !== undefined && r.phase !== '-')
        && v.draws.length > 0;
}"""


if __name__ == "__main__":
    raise SystemExit(main())
