"""The three bodies of :class:`agent.seams.Body` on one simulated world each (one contract suite for
every body).

- ``world``: :class:`agent.body.in_process.WorldBody`, the world in this process;
- ``zenoh``: :class:`agent.body.zenoh_world.ZenohBody` over a real zenoh session (loopback) to a
  :class:`sim.server.server.WorldServer` whose loop runs in a thread of this process;
- ``naoqi``: :class:`agent.body.naoqi.NaoqiBody` over the real qi protocol (loopback) to
  the virtual NAOs of :class:`sim.naoqi_gateway.NaoqiGateway` on that same world loop.

Every image is a real render; nothing is mocked.
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import pytest

from agent.adapters import FormationAdapter, PerceptionAdapter
from agent.body.base import Body
from agent.config import AgentConfig
from agent.net.bus import Bus, BusConfig
from agent.phases.context import Context
from agent.phases.hold import Hold
from agent.phases.membership import Membership
from agent.phases.motion import Motion
from agent.phases.research import Research
from agent.phases.safe_steps import SafeSteps
from agent.phases.search import Search
from agent.phases.waves import Itinerary
from agent.seams import Perception
from sim import scenarios
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario
from tools.harness.procs import free_port

KINDS = ("world", "zenoh", "naoqi")


@dataclass
class Rig:
    """A world and a way to get a body for one of its robots (or a missing one)."""

    kind: str
    world: World
    make: Callable[[int], Body]
    server: Any = None  # the WorldServer (zenoh and naoqi)
    urls: dict[int, str] = field(default_factory=dict)  # the virtual NAOs (naoqi)
    gateway: Any = None


@contextlib.contextmanager
def rig(kind: str, scenario: Scenario, noise: bool = False) -> Iterator[Rig]:
    world = World(scenario, noise=noise)
    bodies: list[Body] = []
    with contextlib.ExitStack() as stack:
        stack.callback(world.close)

        def keep(b: Body) -> Body:
            bodies.append(b)
            return b

        stack.callback(lambda: [b.close() for b in bodies])
        if kind == "world":
            from agent.body.in_process import WorldBody

            yield Rig(kind, world, lambda rid: keep(WorldBody(world, rid)))
            return
        from agent.net.bus import Bus, BusConfig
        from sim.server.server import NetConfig, WorldServer

        ep = f"tcp/127.0.0.1:{free_port()}"
        server = WorldServer(world, NetConfig(listen=(ep,), multicast_scouting=False))
        server.open()
        stack.callback(server.close)
        thread = threading.Thread(target=server.serve, daemon=True)
        thread.start()
        stack.callback(thread.join, 10.0)
        stack.callback(server.stop)
        if kind == "zenoh":
            from agent.body.zenoh_world import ZenohBody

            bus = Bus(BusConfig(connect=(ep,), multicast_scouting=False))
            stack.callback(bus.close)
            yield Rig(
                kind, world, lambda rid: keep(ZenohBody(bus, rid, camera_timeout=5.0)), server
            )
            return
        from agent.body.naoqi import NaoqiBody
        from sim.naoqi_gateway import NaoqiGateway

        gateway = NaoqiGateway(server)
        urls = gateway.open()
        stack.callback(gateway.close)

        def naoqi(rid: int) -> Body:
            # a robot the world lacks has no NAO: a port where nothing listens
            url = urls.get(rid, f"tcp://127.0.0.1:{free_port()}")
            return keep(NaoqiBody(url, rid, timeout=3.0))

        yield Rig(kind, world, naoqi, server, urls, gateway)


#: robot 1 at the origin facing north, robot 2 0.9 m ahead facing it
FACING = Scenario(
    robots=(
        RobotSpec(1, 0.0, 0.0, math.pi / 2),
        RobotSpec(2, 0.0, 0.9, -math.pi / 2),
    ),
    seed=11,
    room=3.0,
)


@pytest.fixture(scope="module", params=KINDS)
def facing(request: pytest.FixtureRequest) -> Iterator[Rig]:
    with rig(str(request.param), FACING) as r:
        yield r


# --------------------------------------------------------------- runner-phase rigs
#: The scenario seed of the in-process runner tests (test_runner_phases, test_march).
RUNNER_SEED = 4


@pytest.fixture(scope="module")
def perception() -> PerceptionAdapter:
    return PerceptionAdapter()


@dataclass
class Robot:
    """One robot's collaborators on a body, composed without the runner (each test uses
    one of them): the fleet as heard on a bus (a real membership), motion, the plan it
    follows, safe steps, search, re-search and hold."""

    ctx: Context
    membership: Membership
    motion: Motion
    course: Itinerary
    safe_steps: SafeSteps
    search: Search
    research: Research
    hold: Hold


def parts(body: Body, cfg: AgentConfig, perception: Perception, bus: Bus) -> Robot:
    """The collaborators of robot ``cfg.robot_id`` on ``body`` (see :class:`Robot`)."""
    ctx = Context.of(bus, body, cfg, perception, FormationAdapter())
    fleet, course = Membership(ctx), Itinerary()
    motion = Motion(ctx, fleet)
    steps, search = SafeSteps(ctx, fleet, motion, course), Search(ctx, motion)
    research = Research(ctx, fleet, motion, search)
    hold = Hold(ctx, fleet, motion, steps, course)
    return Robot(ctx, fleet, motion, course, steps, search, research, hold)


@pytest.fixture()
def world() -> Iterator[World]:
    with World(scenarios.generate(3, RUNNER_SEED)) as w:
        yield w


@pytest.fixture()
def bus() -> Iterator[Bus]:
    with Bus(BusConfig(multicast_scouting=False)) as b:
        yield b
