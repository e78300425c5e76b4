"""``python -m tools.corpus build --out DIR``: a corpus of rendered neighbour records with
their truth, for judging the fleet's frame and fault check offline (docs/design.md §9).

Each *fleet* of the corpus is one start of the real world and the real agents: ``python
-m sim`` renders every forehead picture and ``python -m agent`` processes search, detect,
localise and publish their neighbour record (NAO paper 4.1.2) exactly as in a run; the
tool listens on the bus, keeps each robot's last record once every robot has published,
and stops the fleet before it plans. It writes one small JSON file per fleet (a few
kilobytes): the records, the true start poses (from the scenario) and each robot's true
pose when its record came (after its search), the fleet's size,
seed and start headings, and the commit it was made on. Nothing else of the run is kept.

Fleets are drawn from a fixed list (:func:`fleet_cases`): 4 to 50 NAOs, start headings
aligned, jittered (±20°) or random; wrong pairings arise on their own. Each fleet gives
several *runs* (:func:`runs_of`): the records as published (no fault), and the same
records with one robot's record corrupted by the agent's own sensor-fault test tool
(:class:`agent.core.perception.sensor_fault.SensorFault`, applied after localisation,
exactly where ``python -m agent --sensor-fault`` applies it): rotate 40°, scale 1.4,
shift 0.5 m, each on its own seeded victim.

A second family, the *bystander* fleets (:func:`bystander_cases`), has NAOs in the room
that run no agent (switched off, or another team's): ``bystanders`` more robots of the
scenario, either anywhere (``generate``) or one on a slot of the fleet's plan
(:func:`tools.jam_scenario.jam_scenario`, the dense-jam case). Their sightings are in the
members' records and pair with no member's: a fleet must neither leave a sound member
out for seeing them nor refuse every frame. Their ids follow the members' and are listed
in the file's ``bystanders``; the truth holds them too. They are kept apart
(``tests/data/bystanders``) and judged apart: another population than the fleets alone.

The corpus is split (:func:`held_out`): fleets whose seed is 3 modulo 4 are *held out*:
the estimator is never tuned on them, and ``tools.eval_frames --corpus`` reports both
parts apart.

Building is resumable (a fleet file already there is skipped) and shows progress. It
renders: ~5 CPU-s per robot with TinyRenderer, so run it on a quiet machine.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from agent.core.perception.sensor_fault import SensorFault
from agent.net.bus import Bus, BusConfig
from agent.wire import KEY_RECORD_ALL, KEY_WORLD_TRUTH_POSES, NeighborRecordMsg, TruthPosesMsg
from sim import scenarios
from tools.harness.procs import ROOT, free_port, start_world, stop, wait_ready

FORMAT = 1
#: Fleet sizes, in the order fleets are drawn: mostly the papers' sizes, some dense ones.
SIZES = (4, 6, 8, 5, 10, 7, 12, 6, 9, 15, 8, 20, 5, 10, 30, 6, 8, 11, 50, 7)
HEADINGS = ("random", "aligned", "jitter:20")
#: The faults of :func:`runs_of`: one run each per fleet, each on its own victim.
FAULTS = ("rotate:40", "scale:1.4", "shift:0.5")
FIRST_SEED = 1000
HELD_OUT_MOD = (4, 3)  #: seed % 4 == 3: held out


@dataclass(frozen=True)
class FleetCase:
    """One fleet to render: ``robots`` NAOs of ``scenarios.generate(robots, seed)``."""

    robots: int
    seed: int
    headings: str
    #: NAOs in the room that run no agent, ids ``robots + 1`` on
    bystanders: int = 0
    #: where they stand: "room" (anywhere, as ``generate`` places robots) or "slot" (one
    #: on a slot of the fleet's plan: :func:`tools.jam_scenario.jam_scenario`)
    place: str = "room"

    @property
    def name(self) -> str:
        tail = f"_b{self.bystanders}{self.place}" if self.bystanders else ""
        return f"n{self.robots:02d}_{self.headings.replace(':', '')}_s{self.seed}{tail}"

    def scenario(self) -> scenarios.Scenario:
        """The world's scenario: the members, then the bystanders."""
        heads = scenarios.Headings.parse(self.headings)
        if not self.bystanders:
            return scenarios.generate(self.robots, self.seed, headings=heads)
        if self.place == "slot":
            if self.bystanders != 1:
                raise ValueError(f"a slot takes one bystander, got {self.bystanders}")
            from tools.jam_scenario import jam_scenario

            return jam_scenario(self.robots, self.seed)[0]
        if self.place != "room":
            raise ValueError(f"bystanders stand in the 'room' or on a 'slot', got {self.place!r}")
        return scenarios.generate(self.robots + self.bystanders, self.seed, headings=heads)


def fleet_cases(count: int, first: int = 0) -> list[FleetCase]:
    """Fleets ``first`` .. ``first + count - 1`` of the fixed list: fleet k has size
    ``SIZES[k % len(SIZES)]``, headings ``HEADINGS[k % 3]`` and seed ``FIRST_SEED + k``."""
    if count < 0 or first < 0:
        raise ValueError(f"count and first must be >= 0, got {count}, {first}")
    return [
        FleetCase(SIZES[k % len(SIZES)], FIRST_SEED + k, HEADINGS[k % len(HEADINGS)])
        for k in range(first, first + count)
    ]


#: Bystander fleets: (members, bystanders, where) in the order they are drawn.
#: Nine (prime to the held-out modulus 4): every kind has fleets held out.
BYSTANDER_SIZES = ((4, 1, "slot"), (6, 1, "room"), (5, 2, "room"), (8, 1, "slot"),
                   (10, 2, "room"), (4, 1, "room"), (6, 1, "slot"), (12, 3, "room"),
                   (20, 2, "room"))  # fmt: skip
FIRST_BYSTANDER_SEED = 3000


def bystander_cases(count: int, first: int = 0) -> list[FleetCase]:
    """Bystander fleets ``first`` .. ``first + count - 1``: fleet k is
    ``BYSTANDER_SIZES[k % 9]`` with headings ``HEADINGS[k % 3]`` (a slot's scenario keeps
    ``jam_scenario``'s own) and seed ``FIRST_BYSTANDER_SEED + k``."""
    if count < 0 or first < 0:
        raise ValueError(f"count and first must be >= 0, got {count}, {first}")
    out = []
    for k in range(first, first + count):
        n, b, place = BYSTANDER_SIZES[k % len(BYSTANDER_SIZES)]
        heads = "aligned" if place == "slot" else HEADINGS[k % len(HEADINGS)]
        out.append(FleetCase(n, FIRST_BYSTANDER_SEED + k, heads, b, place))
    return out


def held_out(seed: int) -> bool:
    """A fleet the estimator is never tuned on (module docstring)."""
    return seed % HELD_OUT_MOD[0] == HELD_OUT_MOD[1]


@dataclass(frozen=True)
class Run:
    """One evaluation run: a fleet's records, with ``fault`` on ``victim`` (-1: none)."""

    fleet: str
    robots: int
    seed: int
    headings: str
    truth: dict[int, tuple[float, float, float]]
    records: tuple[NeighborRecordMsg, ...]
    victim: int = -1
    fault: str = ""
    #: NAOs of the truth that run no agent (bystander fleets)
    bystanders: tuple[int, ...] = ()

    @property
    def name(self) -> str:
        return self.fleet + (f"+{self.fault}@{self.victim}" if self.fault else "")


def _record(d: dict[str, Any]) -> NeighborRecordMsg:
    return NeighborRecordMsg(
        sender=int(d["sender"]),
        round=int(d["round"]),
        neighbours=tuple((float(x), float(y)) for x, y in d["neighbours"]),
        orientations=tuple(float(o) for o in d.get("orientations", ())),
        confidences=tuple(float(c) for c in d.get("confidences", ())),
        seen_at=tuple(float(t) for t in d.get("seen_at", ())),
        stances=tuple((float(a), float(b), float(h)) for a, b, h in d.get("stances", ())),
        clock_error=float(d.get("clock_error", 0.0)),
    )


def _as_dict(m: NeighborRecordMsg) -> dict[str, Any]:
    return {
        "sender": m.sender,
        "round": m.round,
        "neighbours": [list(p) for p in m.neighbours],
        "orientations": list(m.orientations),
        "confidences": list(m.confidences),
        "seen_at": list(m.seen_at),
        "stances": [list(st) for st in m.stances],
        "clock_error": m.clock_error,
    }


def corrupt(rec: NeighborRecordMsg, fault: SensorFault) -> NeighborRecordMsg:
    """``rec`` as the agent publishes it with ``--sensor-fault`` (its localise step)."""
    pts = np.array(rec.neighbours, dtype=np.float64).reshape(-1, 2)
    ori = np.array(rec.orientations, dtype=np.float64)
    pts, ori = fault.apply(pts, ori)
    return NeighborRecordMsg(
        sender=rec.sender,
        round=rec.round,
        neighbours=tuple((float(x), float(y)) for x, y in pts),
        orientations=tuple(float(o) for o in ori),
        confidences=rec.confidences,
        seen_at=rec.seen_at,
        stances=rec.stances,
        clock_error=rec.clock_error,
    )


def runs_of(path: Path) -> list[Run]:
    """The runs of one fleet file: no fault, then one per :data:`FAULTS` (victims drawn
    from ``numpy.random.default_rng([seed, k])``)."""
    d = json.loads(path.read_text())
    if d.get("format") != FORMAT:
        raise ValueError(f"{path}: corpus format {d.get('format')!r}, expected {FORMAT}")
    truth = {int(k): (float(v[0]), float(v[1]), float(v[2])) for k, v in d["truth"].items()}
    recs = tuple(sorted((_record(r) for r in d["records"]), key=lambda r: r.sender))
    by = tuple(int(i) for i in d.get("bystanders", ()))
    base = Run(path.stem, int(d["robots"]), int(d["seed"]), str(d["headings"]), truth, recs,
               bystanders=by)  # fmt: skip
    out = [base]
    ids = [r.sender for r in recs]
    for k, text in enumerate(FAULTS):
        victim = ids[int(np.random.default_rng([base.seed, k]).integers(len(ids)))]
        fault = SensorFault.parse(text)
        bad = tuple(corrupt(r, fault) if r.sender == victim else r for r in recs)
        out.append(replace(base, records=bad, victim=victim, fault=text))
    return out


def load_corpus(root: Path) -> list[Run]:
    """Every run of every fleet file under ``root`` (sorted by file name)."""
    files = sorted(root.glob("*.json"))
    if not files:
        raise ValueError(f"no corpus fleet files (*.json) in {root}")
    return [run for f in files for run in runs_of(f)]


def _commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                             text=True, timeout=10, check=False)  # fmt: skip
    except OSError:
        return ""
    return out.stdout.strip()


def _agent_argv(rid: int, n: int, endpoint: str) -> list[str]:
    """The agent as a fleet runs it (defaults), insecure: the corpus is about what robots
    see, not how they talk."""
    from agent.config import AgentConfig
    from tools.harness.procs import agent_command

    net = ["--connect", endpoint, "--no-multicast-scouting", "--insecure"]
    return agent_command(AgentConfig(robot_id=rid, fleet_size=n), net, log_level="WARNING")


def render_fleet(case: FleetCase, log_dir: Path, timeout: float) -> dict[str, Any]:
    """Start the world and ``case.robots`` agents, collect every robot's record, stop them."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    sc = case.scenario()
    if case.bystanders:
        path = log_dir / "scenario.json"
        scenarios.dump(sc, path)
        extra = ["--scenario", str(path)]
    else:
        extra = ["--headings", case.headings]
    world = start_world(len(sc.robots), case.seed, endpoint, log_dir, extra)
    agents: list[subprocess.Popen[bytes]] = []
    last: dict[int, NeighborRecordMsg] = {}
    at_record: dict[int, list[float]] = {}  # each robot's true pose when its record came
    now: dict[int, list[float]] = {}
    try:
        wait_ready(world, 60.0)
        with Bus(BusConfig(connect=(endpoint,), multicast_scouting=False)) as bus:
            bus.subscribe(KEY_RECORD_ALL)
            bus.subscribe(KEY_WORLD_TRUTH_POSES)
            for rid in range(1, case.robots + 1):
                log = (log_dir / f"agent-{rid}.log").open("wb")
                agents.append(subprocess.Popen(_agent_argv(rid, case.robots, endpoint), cwd=ROOT,
                                               stdout=log, stderr=subprocess.STDOUT))  # fmt: skip
            deadline = time.monotonic() + timeout
            while len(last) < case.robots:
                if time.monotonic() > deadline:
                    raise RuntimeError(
                        f"{case.name}: records of {sorted(last)} only after {timeout:g} s"
                    )
                for ev in bus.drain(timeout=0.5):
                    if ev.kind == "msg" and isinstance(ev.msg, TruthPosesMsg):
                        now = {int(p[0]): [round(float(v), 4) for v in p[1:]] for p in ev.msg.poses}
                    if ev.kind == "msg" and isinstance(ev.msg, NeighborRecordMsg):
                        last[ev.msg.sender] = ev.msg
                        if ev.msg.sender in now:
                            at_record[ev.msg.sender] = now[ev.msg.sender]
    finally:
        for p in agents:
            p.kill()
        for p in agents:
            p.wait(10.0)
        stop(world)
    return {
        "format": FORMAT,
        "robots": case.robots,
        "seed": case.seed,
        "headings": case.headings,
        "commit": _commit(),
        "truth": {str(r.id): [r.x, r.y, r.heading] for r in sc.robots},
        "bystanders": [r.id for r in sc.robots if r.id > case.robots],
        # the true pose of each robot when its record arrived (the search over: a robot
        # has turned through its search, and its body may face another way than at start)
        "at_record": {str(k): v for k, v in sorted(at_record.items())},
        "records": [_as_dict(last[k]) for k in sorted(last)],
    }


def build(out: Path, cases: list[FleetCase], log_dir: Path) -> Iterator[tuple[FleetCase, str]]:
    """Render every case not yet in ``out``; yields (case, what happened)."""
    out.mkdir(parents=True, exist_ok=True)
    for case in cases:
        path = out / f"{case.name}.json"
        if path.exists():
            yield case, "kept"
            continue
        logs = log_dir / case.name
        logs.mkdir(parents=True, exist_ok=True)
        t0 = time.monotonic()
        try:
            data = render_fleet(case, logs, timeout=120.0 + 20.0 * case.robots)
        except RuntimeError as exc:
            yield case, f"failed: {exc}"
            continue
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(data, separators=(",", ":")))
        tmp.replace(path)
        yield case, f"{path.stat().st_size / 1024:.1f} kB in {time.monotonic() - t0:.0f} s"


def main(argv: list[str] | None = None) -> int:
    from tools.harness.progress import Progress

    ap = argparse.ArgumentParser(
        prog="python -m tools.corpus", description=(__doc__ or "").split("\n\n")[0]
    )
    sub = ap.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("build", help="render fleets into DIR (resumable)")
    b.add_argument("--out", type=Path, default=None,
                   help="default: tests/data/frames, or tests/data/bystanders for that family")  # fmt: skip
    b.add_argument("--fleets", type=int, default=200, help="fleets of the fixed list to render")
    b.add_argument("--family", choices=("fleets", "bystanders"), default="fleets",
                   help="the fixed list to draw from: fleets, or fleets with bystanders")  # fmt: skip
    b.add_argument("--first", type=int, default=0, help="index of the first fleet")
    b.add_argument("--every", type=int, default=1, help="render every K-th fleet (with --offset)")
    b.add_argument("--offset", type=int, default=0)
    b.add_argument("--max-robots", type=int, default=50)
    b.add_argument("--logs", type=Path, default=Path("out/corpus-logs"))
    a = ap.parse_args(argv)
    family = bystander_cases if a.family == "bystanders" else fleet_cases
    if a.out is None:
        a.out = Path("tests/data/bystanders" if a.family == "bystanders" else "tests/data/frames")
    cases = [c for k, c in enumerate(family(a.fleets, a.first))
             if k % a.every == a.offset and c.robots <= a.max_robots]  # fmt: skip
    bar = Progress(len(cases), "corpus")
    failed = 0
    for case, what in build(a.out, cases, a.logs):
        failed += what.startswith("failed")
        bar.step(f"{case.name}: {what}")
    bar.close()
    print(f"{len(cases)} fleets, {failed} failed; corpus in {a.out}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
