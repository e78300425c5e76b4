"""One way to start a fleet and judge it (docs/design.md §8 the fleet's network, §9 "Honest
results"): :class:`FleetSpec` says what a run is, :class:`Fleet` runs it as processes on
this machine, and :func:`run_fleet` is one whole run, judged.

    spec = FleetSpec(robots=3, seed=1, agent=AgentConfig(robot_id=0, timeout=90.0))
    with Fleet(spec, out) as fleet:      # router, world, render workers, agents, rogues
        fleet.wait()                     # observed until the agents have exited
    result = fleet.judge()               # tools.harness.judge.summarise, from ground truth

A :class:`Fleet` starts a TLS router for secure fleets (:func:`procs.fleet_network`), the
world (``python -m sim``, on the spec's scenario), optional render workers, one agent per
robot (``python -m agent``: its flags written by :meth:`AgentConfig.to_argv` alone, the
agent's defaults never repeated here) and optional rogues; it records the bus (MCAP) and
hands it to an :class:`~tools.harness.observe.Observer`, the judge's ground truth
(``fleet.obs.truth``). It stops every process when the ``with`` block ends, also on an
exception. Its levers (:meth:`Fleet.kill_agent`, :meth:`Fleet.start_agent`,
:meth:`Fleet.kill_router`, :meth:`Fleet.start_router`) are what ``tools.eval_faults``
pulls; :mod:`tools.harness.hosts` runs the same spec on test hosts.
"""

from __future__ import annotations

import contextlib
import math
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from agent.config import AgentConfig
from agent.core.formation.shape.spec import Shape
from agent.net.bus import Bus
from sim import scenarios
from sim.camera.look import Look
from sim.physics.locomotion import MAX_NOISE_SCALE
from tools.harness.judge import plan_meta, summarise
from tools.harness.observe import (
    AgentView,
    LiveView,
    Observer,
    Recorder,
    fetch_agreed_records,
    observe_still,
    observer_bus,
)
from tools.harness.procs import (
    FleetNet,
    Proc,
    agent_command,
    claimed_ids,
    fleet_network,
    robot_ids,
    start_agent,
    start_rogues,
    start_router,
    start_world,
    stop,
    wait_ready,
)
from tools.harness.render import served_by, start_render_workers
from tools.harness.view.live import live_sinks

#: The most robots a run has. Each robot is an agent process (~100 MB of its own memory
#: and a TLS session at the router): 128 robots need ~13 GB. The wire's records carry at
#: most ``agent.wire.MAX_NEIGHBOURS`` (128) neighbours, so even a robot that sees every
#: other one of 128 fits; the scenario generator places up to 200.
MAX_ROBOTS = 128
#: The most render workers a run has (``python -m sim.server.render_worker --shard i/K``).
MAX_RENDER_WORKERS = 8
#: The agents' wall limit when none is given: at least WALL_MIN_S, WALL_PER_ROBOT_S a robot.
#: On the two-core machine every agent of a simulated fleet computes the plan on the same
#: cores: 100 NAOs agreed after 456 s and were cut at 600 s while they planned (seed 62), where
#: each agent's own timeouts would have ended the run; the limit is the harness's last
#: resort, never the fleet's clock.
WALL_MIN_S = 600.0
WALL_PER_ROBOT_S = 20.0


def wall_limit(robots: int) -> float:
    """The default wall limit (s) of a fleet of ``robots`` agents (600 s up to 30, 2 000 s
    at 100)."""
    return max(WALL_MIN_S, WALL_PER_ROBOT_S * robots)


@dataclass(frozen=True)
class FleetSpec:
    """What one run of the fleet is; checked on construction (``ValueError``).

    ``agent``: every agent's settings (its ``robot_id`` and ``fleet_size`` are set per
    agent); ``agent_args``: (robot id, flag) pairs given to that robot's agent only, last
    (``3:--sensor-fault=rotate:40``: an odd agent; the judge reads them back);
    ``agent_log_level``: None for the agent's own; ``auto_ids``: agents claim their robots
    (``--id auto``); ``body``: ``zenoh`` or ``naoqi`` (the world's virtual NAOs over qi);
    ``journal``: every agent keeps its durable journal in ``OUT/state`` (crash recovery).
    The world: a ``scenario`` file (its robot ids ``scenario_ids``), else the seed's
    generated one (``isolated``: one robot 2-3 m from every other; ``headings``; with
    ``obstacles`` K > 0 the blocking scenario of :mod:`tools.lib.obstacle_scenario`),
    ``noise_scale``, its ``look`` (:mod:`sim.camera.look`) and ``free_looks`` (camera requests
    cost no sim time), more ``world_args``, its ``renderer`` and ``render_workers``. Every
    agent's recogniser: the ``calibration`` folder (``python -m agent --calibration DIR``,
    built by ``python -m tools.calibrate``), else the built-in one. The
    network: secure by default (a throwaway fleet in ``OUT/fleet`` unless ``credentials``),
    ``plain_links`` (tests), ``insecure``. Limits: ``timeout`` for the agents, wall s
    (None: :func:`wall_limit` of the fleet's size, :attr:`wall`); ``world_timeout`` for the
    world's start. ``rogue`` S > 0: attackers for S s
    (``rogue_replay``: also replaying a capture); ``live``: serve the run to Foxglove.
    """

    robots: int = 3
    seed: int = 1
    agent: AgentConfig = field(default_factory=lambda: AgentConfig(robot_id=0))
    agent_args: tuple[tuple[int, str], ...] = ()
    agent_log_level: str | None = None
    auto_ids: bool = False
    body: str = "zenoh"
    journal: bool = False
    scenario: Path | None = None
    scenario_ids: tuple[int, ...] | None = None
    isolated: bool = False
    headings: scenarios.Headings = field(default_factory=scenarios.Headings)
    obstacles: int = 0
    noise_scale: float = 1.0
    look: Look = field(default_factory=Look)
    free_looks: bool = False
    calibration: Path | None = None
    world_args: tuple[str, ...] = ()
    renderer: str | None = None
    render_workers: int = 0
    insecure: bool = False
    credentials: Path | None = None
    plain_links: bool = False
    timeout: float | None = None
    world_timeout: float = 120.0
    rogue: float = 0.0
    rogue_replay: Path | None = None
    live: str | None = None
    reshapes: tuple[Shape, ...] = ()

    @property
    def wall(self) -> float:
        """The agents' wall limit (s): ``timeout``, else :func:`wall_limit` of the fleet."""
        return wall_limit(self.robots) if self.timeout is None else self.timeout

    def __post_init__(self) -> None:
        if not 1 <= self.robots <= MAX_ROBOTS:
            raise ValueError(f"--robots must be in [1, {MAX_ROBOTS}], got {self.robots}")
        if self.isolated and self.robots < 2:
            raise ValueError("--isolated needs at least 2 robots")
        if self.body not in ("zenoh", "naoqi"):
            raise ValueError(f"--body must be zenoh or naoqi, got {self.body!r}")
        naoqi = self.body == "naoqi"
        if not 0 <= self.render_workers <= MAX_RENDER_WORKERS or (self.render_workers and naoqi):
            raise ValueError(
                f"--render-service must be in [0, {MAX_RENDER_WORKERS}], and needs --body zenoh"
            )
        if not (math.isfinite(self.noise_scale) and 0.0 <= self.noise_scale <= MAX_NOISE_SCALE):
            raise ValueError(f"--noise-scale must be in [0, {MAX_NOISE_SCALE:g}]")
        if naoqi and self.auto_ids:
            raise ValueError("--body naoqi drives the robot at a fixed URL: no --auto-ids")
        if not (self.wall > 0 and self.world_timeout > 0 and self.obstacles >= 0):
            raise ValueError("the timeouts must be > 0 and the obstacles >= 0")
        # a formation file with fewer slots than robots: refused before anything starts
        self.agent.shape.check_fleet(self.robots)
        for shape in self.reshapes:
            shape.check_fleet(self.robots)
            if not shape.source:
                raise ValueError(f"reshape to {shape.name!r}: a shape from no name or file")
        if self.reshapes and self.agent.reshape_wait <= 0.0:
            raise ValueError("reshapes need agents that wait for them (reshape_wait > 0)")

    def agent_config(self, rid: int) -> AgentConfig:
        """Robot ``rid``'s agent settings."""
        return replace(self.agent, robot_id=rid, fleet_size=self.robots)

    def agent_command(
        self, rid: int, net: list[str], extra: list[str] | None = None, nao: str | None = None
    ) -> list[str]:
        """The argv of robot ``rid``'s agent joining with ``net`` (``extra``: more flags
        before its own ``agent_args``; ``nao``: its NAO's qi URL with ``body`` naoqi)."""
        mine = [a for i, a in self.agent_args if i == rid]
        cal = [] if self.calibration is None else ["--calibration", str(self.calibration)]
        return agent_command(
            self.agent_config(rid),
            net,
            claim_id=self.auto_ids,
            log_level=self.agent_log_level,
            nao=nao if self.body == "naoqi" else None,
            extra=[*cal, *(extra or []), *mine],
        )

    def meta(self) -> dict[str, Any]:
        """What a run's ``result.json`` says of its settings (before the judge's numbers)."""
        cfg = self.agent
        out: dict[str, Any] = {
            "robots": self.robots,
            "seed": self.seed,
            "d_e": cfg.d_e,
            "phi_e_deg": cfg.phi_e_deg,
            "noise_scale": float(self.noise_scale),
            # the judge loads the shape again from its name or file (tools.harness.judge)
            **plan_meta(cfg),
        }
        if self.scenario is not None:
            out["scenario"] = str(self.scenario)
        if self.isolated:
            out["isolated"] = True
        out["headings"] = str(self.headings)
        if not self.look.is_default():
            out["look"] = str(self.look)
        if self.free_looks:
            out["free_looks"] = True
        if self.calibration is not None:
            out["calibration"] = str(self.calibration)
        if self.agent_args:
            out["agent_args"] = [f"{i}:{a}" for i, a in self.agent_args]
        if self.reshapes:  # the judge loads each again, and judges the last
            out["reshape_specs"] = [s.source for s in self.reshapes]
        if cfg.march is not None and cfg.march.distance is not None:
            out["route"] = {"distance": float(cfg.march.distance)}
        elif cfg.march is not None and cfg.march.to is not None:
            out["route"] = {"to": [float(v) for v in cfg.march.to]}
        return out


def route_length(cfg: AgentConfig) -> float:
    """An upper bound of the march's length (m): 0 without a march."""
    if cfg.march is None:
        return 0.0
    if cfg.march.distance is not None:
        return float(cfg.march.distance)
    assert cfg.march.to is not None
    return math.hypot(*cfg.march.to) + 2.0  # the leader's target is near the fleet's centre


def reshape_reach(spec: FleetSpec) -> float:
    """How far (m) a slot of the spec's reshapes may lie from the slots' mean, the most of
    any shape (0 without reshapes): each new shape stands on the held slots' mean, which
    lies within the room, so a room this much larger holds it (a line of 8 at d_e 0.8
    spans 5.6 m; the room generated for 8 robots is 6–7 m wide)."""
    return max((slot_reach(spec, shape) for shape in spec.reshapes), default=0.0)


def slot_reach(spec: FleetSpec, shape: Shape) -> float:
    """How far (m) a slot of ``shape`` lies from the mean of its slots, at most, for the
    spec's fleet size, d_e and φ_e."""
    cfg = spec.agent
    pos = shape.slots(spec.robots, cfg.d_e, cfg.phi_e).positions
    return float(np.max(np.hypot(*(pos - pos.mean(axis=0)).T)))


def shape_room(spec: FleetSpec, sc: scenarios.Scenario) -> float:
    """The smallest room half-size (m, on the 0.5 m grid of generated rooms) whose walls
    stand at least d_e (one formation spacing) beyond every slot of the run's first shape:
    the fleet does not see walls, so the world gives it the free floor a lab must
    (docs/formation.md "Shapes"). The slots stand round the starts' mean (o_p, eq. 13;
    :func:`agent.core.formation.shape.layout.centred`), whichever way the shape faces, so
    the room needs |o_p| plus the slots' reach from their mean plus d_e. A line of 10 at
    d_e 0.8 reaches 3.6 m, beyond the 3.5 m room the starts of 10 robots get; the pyramid
    fits the starts' room but for a few of the largest fleets."""
    starts = np.array([(r.x, r.y) for r in sc.robots], dtype=np.float64)
    reach = slot_reach(spec, spec.agent.shape)
    need = float(np.hypot(*starts.mean(axis=0))) + reach + spec.agent.d_e
    return math.ceil(2.0 * need) / 2.0


def march_room(spec: FleetSpec, out: Path) -> list[str]:
    """World flags for the run's scenario, written to ``out/scenario.json``: the file of
    ``scenario``, or the seed's generated one (``isolated``, ``headings``), a generated
    room enlarged to hold the first shape (:func:`shape_room`); with a march, its room's
    half-size enlarged by the route's length, with reshapes by the reach of their shapes
    (:func:`reshape_reach`; sim/scenarios is not changed).
    [] when the world generates the default scenario itself, or when the caller chose a
    scenario with ``world_args``."""
    if any("--scenario" in a for a in spec.world_args):
        return []
    extra = route_length(spec.agent) + reshape_reach(spec)
    turned = spec.headings.kind != "aligned"
    if spec.scenario is not None:
        sc = scenarios.load(spec.scenario)
    else:
        sc = scenarios.generate(
            spec.robots, spec.seed, isolated=spec.isolated, headings=spec.headings
        )
        held = shape_room(spec, sc)
        if held > sc.room:
            sc = replace(sc, room=min(100.0, held))
        elif extra <= 0.0 and not spec.isolated and not turned:
            return []  # the world's own scenario of the seed is this one
    if extra > 0.0:
        sc = replace(sc, room=min(100.0, math.ceil(2.0 * (sc.room + extra)) / 2.0))
    path = out / "scenario.json"
    scenarios.dump(sc, path)
    return ["--scenario", str(path)]


class Fleet:
    """One run of ``spec`` as processes on this machine, its logs and recording in ``out``
    (module docstring). ``quiet``: no live status lines and no printed table."""

    def __init__(self, spec: FleetSpec, out: Path, quiet: bool = True) -> None:
        self.spec, self.out, self.quiet = spec, out, quiet
        self.t0 = time.monotonic()
        self.obs = Observer(self.t0)
        #: the run's result as it grows: the spec's settings, then what the run measured;
        #: a caller may add to it before :meth:`judge` (``tools.eval_faults``: the fault)
        self.result: dict[str, Any] = spec.meta()
        self.ids: list[int] = []
        self.agents: dict[int, Proc] = {}
        self.router: Proc | None = None
        self.net: FleetNet | None = None
        self._procs: list[Proc] = []  # world, render workers (the router and agents apart)
        self._rogues: list[Proc] = []
        self._nao_urls: dict[int, str] = {}
        self._rec: Recorder | None = None
        self._live: LiveView | None = None
        self._bus: Bus | None = None
        self._op_bus: Bus | None = None
        self._closed = False

    # ------------------------------------------------------------------ start and stop

    def __enter__(self) -> Fleet:
        try:
            self._start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def endpoint(self) -> str:
        """Where the fleet's processes meet on the bus."""
        assert self.net is not None, "the fleet has not started"
        return self.net.endpoint

    @property
    def truth(self) -> list[tuple[float, dict[int, tuple[float, float, float]]]]:
        """The ground truth so far: (sim time, pose of every robot) samples, as the world
        published them (``world/truth/**``; the judge's, never the agents')."""
        return self.obs.truth

    def elapsed(self) -> float:
        """Seconds since the run began."""
        return time.monotonic() - self.t0

    def recorder(self) -> Recorder:
        """The run's recording ``out/run.mcap`` and its live view (``spec.live``), whose
        scene plans with the agents' planning parameters: the plan it draws is the one
        whose digest the agents report, for every shape, orientation and strategy."""
        params = self.spec.agent.plan_params()
        return Recorder(self.out / "run.mcap", params=params, sinks=live_sinks(self.spec.live))

    def _start(self) -> None:
        spec, out, result = self.spec, self.out, self.result
        out.mkdir(parents=True, exist_ok=True)
        net = self.net = fleet_network(
            out,
            spec.robots,
            spec.scenario_ids,
            insecure=spec.insecure,
            credentials=spec.credentials,
            plain_links=spec.plain_links,
        )
        self._rec = self.recorder()
        result["secure"] = bool(net.credentials)
        result["tls"] = net.router
        if net.router:
            self.router = start_router(net.endpoint, out, net.flags)
        self._bus = observer_bus(net)
        joins = ["--connect" if net.router else "--listen", net.endpoint, *net.flags]
        world = start_world(spec.robots, spec.seed, net.endpoint, out, self._world_flags(), joins)
        self._procs.append(world)
        # Agents of known ids on the zenoh body start with the world, not after it: each
        # loads its libraries while the world builds its scene, then waits for the world's
        # services as it would on hosts of its own (agent/body/zenoh_world.py, retries
        # while no world answers). A virtual NAO's address, a claimed id and the render
        # workers' cameras come only with the world's ready line.
        early = spec.body == "zenoh" and not spec.auto_ids and spec.render_workers == 0
        if early:
            for i in spec.scenario_ids or range(1, spec.robots + 1):
                self.start_agent(i)
        wait_ready(world, spec.world_timeout, self._take)
        result["wall_world_ready"] = self.elapsed()
        if spec.render_workers > 0:  # cameras drawn by render workers, not the world
            workers = ["--connect", net.endpoint, *net.flags]
            self._procs.extend(
                start_render_workers(spec.render_workers, workers, out, renderer=spec.renderer)
            )
            result["render_workers"] = spec.render_workers
            result["wall_render_ready"] = self.elapsed()
        self.ids = robot_ids(world.lines, spec.robots)
        result["ids"] = self.ids
        # with body naoqi: each robot's virtual NAO, "sim naoqi robot=ID url=URL"
        self._nao_urls = {
            int(ln.split("robot=")[1].split()[0]): ln.split("url=")[1].strip()
            for ln in world.lines
            if ln.startswith("sim naoqi ")
        }
        if not early:
            for i in self.ids:
                self.start_agent(i)
        elif sorted(self.agents) != self.ids:
            raise RuntimeError(f"the world serves robots {self.ids}, agents {sorted(self.agents)}")
        if spec.rogue > 0:
            self._rogues = start_rogues(net, out, self.ids, spec.rogue, spec.rogue_replay)
        result["rogues_started"] = [r.name.removeprefix("rogue ") for r in self._rogues]
        self._live = LiveView(sys.stderr, self.ids) if not self.quiet else None

    def _world_flags(self) -> list[str]:
        spec = self.spec
        room = march_room(spec, self.out)
        if spec.obstacles > 0:  # 5.1.2: obstacles on the straight paths
            from tools.lib.obstacle_scenario import obstacle_world_args

            cfg = spec.agent
            room = obstacle_world_args(
                spec.robots, spec.seed, spec.obstacles, cfg.d_e, cfg.phi_e, self.out, self.result
            )
        naoqi = ["--naoqi"] if spec.body == "naoqi" else []
        noise = [f"--noise-scale={spec.noise_scale:g}"]
        drawn = ["--renderer", spec.renderer] if spec.renderer else []
        look = [] if spec.look.is_default() else ["--look", str(spec.look)]
        free = ["--free-looks"] if spec.free_looks else []
        return [*room, *spec.world_args, *naoqi, *noise, *drawn, *look, *free]

    def close(self) -> None:
        """Stop every process (agents first, the router last), the bus and the recording;
        again: nothing."""
        if self._closed:
            return
        self._closed = True
        for p in reversed([*self._procs, *self.agents.values(), *self._rogues]):
            stop(p)
        if self.router is not None:
            stop(self.router)
        if self._bus is not None:
            self._bus.close()
        if self._op_bus is not None:
            self._op_bus.close()
        if self._rec is not None:
            self._rec.close()

    # ------------------------------------------------------------------ observe

    def _take(self) -> None:
        assert self._bus is not None, "the fleet has not started"
        for ev in self._bus.drain(0.1):
            self.obs.take_event(ev, self._rec)

    def step(self) -> None:
        """Hand what the bus brings within 0.1 s to the observer (and the agreed records it
        missed, :func:`fetch_agreed_records`); repaint the status lines."""
        self._take()
        if self._bus is not None:
            fetch_agreed_records(self._bus, self.obs)
        if self._live is not None:
            self._live.update(self.obs, self.elapsed())

    def wait(self, busy: Callable[[float], bool] | None = None) -> None:
        """Observe until every agent has exited and ``busy`` (called after every look with
        the seconds since the start: a caller's injector) has nothing pending, or the
        spec's ``timeout`` (``result["timeout"]``); then until the world stands still
        (at most 1.5 s: the last truth after the motions, :func:`observe_still`), and the
        rogues' end."""
        assert self._bus is not None, "the fleet has not started"
        deadline = time.monotonic() + self.spec.wall
        while True:
            self.step()
            pending = busy(self.elapsed()) if busy is not None else False
            if not pending and self.all_exited():
                break
            if time.monotonic() > deadline:
                self.result["timeout"] = f"agents still running after {self.spec.wall:g} s"
                break
        observe_still(self._bus, self.obs, self._rec, 1.5)  # the last truth after the motions
        if self._live is not None:
            self._live.update(self.obs, self.elapsed(), force=True)
        self.result["wall_total"] = self.elapsed()
        stats = self._bus.stats
        self.result["rejected"] = {
            "bus": stats.rejected, "untrusted": stats.untrusted, "observer": self.obs.rejected,
        }  # fmt: skip
        self.result["dropped"] = stats.dropped
        for r in self._rogues:  # they stop by themselves after the rogue's seconds
            with contextlib.suppress(subprocess.TimeoutExpired):
                r.popen.wait(max(1.0, self.spec.rogue + 30.0 - self.elapsed()))
            stop(r)

    # ------------------------------------------------------------------ levers

    def start_agent(self, rid: int, append: bool = False) -> None:
        """Start robot ``rid``'s agent (again, with ``append``: the same id, log and
        journal folder, so that it resumes)."""
        assert self.net is not None
        net = ["--connect", self.net.endpoint, *self.net.flags]
        extra = ["--state-dir", str(self.out / "state")] if self.spec.journal else []
        cmd = self.spec.agent_command(rid, net, extra, self._nao_urls.get(rid))
        name = f"agent-slot{rid}.log" if self.spec.auto_ids else f"agent-{rid}.log"
        self.agents[rid] = start_agent(cmd, self.out / name, append)

    def operator(self) -> Callable[[float], bool] | None:
        """With the spec's reshapes, the operator (docs/formation.md "Reshaping"): a
        :meth:`wait` caller that commands each shape in turn once the fleet holds
        (:class:`tools.lib.reshape.Reshaper`, signed with the operator's key), pending
        until the last is held or refused; its transitions go to ``result["reshapes"]``.
        None without reshapes."""
        if not self.spec.reshapes:
            return None
        assert self.net is not None, "the fleet has not started"
        from agent.wire import KEY_RESHAPE
        from tools.lib.reshape import Reshaper, Seen

        bus = self._op_bus = Bus(self.net.operator())
        op = Reshaper(self.spec.reshapes, self.ids, lambda m: bus.publish(KEY_RESHAPE, m))
        self.result["reshapes"] = []

        def step(elapsed: float) -> bool:
            views = self.obs.agents
            seen = {
                i: Seen(v.phase, v.plan_digest, v.t_sim, v.detail, v.error)
                for i, v in views.items()
                if i in self.ids
            }
            pending = op.step(elapsed, seen)
            self.result["reshapes"] = [t.as_dict() for t in op.done]
            return pending

        return step

    def running(self, rid: int) -> bool:
        p = self.agents.get(rid)
        return p is not None and p.popen.poll() is None

    def all_exited(self) -> bool:
        return all(p.popen.poll() is not None for p in self.agents.values())

    def kill_agent(self, rid: int) -> None:
        """SIGKILL robot ``rid``'s agent, no goodbye."""
        _kill(self.agents[rid])

    def kill_router(self) -> None:
        if self.router is not None:
            _kill(self.router)

    def start_router(self) -> None:
        """Start the router again on the same endpoint; waits for its ready line."""
        assert self.net is not None
        self.router = start_router(self.net.endpoint, self.out, self.net.flags)

    # ------------------------------------------------------------------ verdict

    def judge(self) -> dict[str, Any]:
        """Stop the run (:meth:`close`) and judge it from the ground truth
        (:func:`tools.harness.judge.summarise`: ``OUT/result.json``, the figure; the table
        unless quiet); each agent's exit code is its process's."""
        self.close()
        spec, result = self.spec, self.result
        if result.get("render_workers"):
            result["render_served"] = served_by(self.out, result["render_workers"])
        agents = self.agents
        if spec.auto_ids:
            agents = claimed_ids(agents, self.out)
            result["claimed_ids"] = sorted(agents)
        for i, p in agents.items():
            self.obs.agents.setdefault(i, AgentView()).exit_code = p.popen.returncode
        cfg = spec.agent
        return summarise(self.obs, result, self.out, sorted(agents), cfg.d_e, cfg.phi_e, self.quiet)


def _kill(proc: Proc) -> None:
    """SIGKILL a process of the run, reap it and close its log."""
    proc.popen.send_signal(signal.SIGKILL)
    proc.popen.wait()
    proc.log.close()


def run_fleet(spec: FleetSpec, out: Path, quiet: bool = True) -> dict[str, Any]:
    """One whole run of ``spec`` in ``out``, judged (``RuntimeError`` when it could not
    start: a world or router that did not come up)."""
    fleet = Fleet(spec, out, quiet)
    with fleet:
        fleet.wait(fleet.operator())
    return fleet.judge()
