"""The house rules of docs/design.md ("Layers"), checked on the source with ``ast``.

- the pure core (``agent/core``) imports no I/O module and nothing of the project but
  itself;
- ``agent/wire`` (the contract every process shares) imports only itself and the NAO's
  numbers of the core; it never imports zenoh;
- ``agent/net`` is the only agent layer that imports zenoh; only modules named
  ``*naoqi*`` import ``qi``;
- ``agent/body`` never reaches up into the phases; nothing of ``agent/`` imports
  ``sim/`` or ``tools/``;
- crash recovery (``agent/recovery``) builds on the phases, never the reverse: the phase
  machine knows it only through the ``Recovery`` and ``Recorder`` protocols;
- ``sim/`` imports only ``agent.wire`` of ``agent/``;
- tools reach agents as processes or through the seams, never the phase machine nor its
  crash recovery;
- no import cycles among the modules of ``agent/``, ``sim/`` and ``tools/`` (imports
  under ``if TYPE_CHECKING:`` included: a cycle of types is still a knot);
- no source file (agent, sim, tools and the tests; Python, JavaScript, HTML) over 600
  lines; no folder of ``agent/``, ``sim/`` or ``tools/`` with more than 15 modules
  (``OVER_MODULES`` lists the folders still over, which may shrink, never grow);
- the formation core's rooms are layered (``FORMATION_TIERS``): a module imports only
  its own room and the rooms of lower tiers; so are the world's (``SIM_TIERS``: camera,
  scenarios, physics, server, then the qi gateway and ``python -m sim``).
"""

from __future__ import annotations

import ast
import functools
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("agent", "sim", "tools")
MAX_LINES = 600
IO_MODULES = frozenset({"zenoh", "msgpack", "pybullet", "qi", "socket", "sim", "tools"})


def _modules() -> dict[str, Path]:
    out: dict[str, Path] = {}
    for pkg in PACKAGES:
        for p in sorted((ROOT / pkg).rglob("*.py")):
            parts = p.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts).removesuffix(".__init__")
            out[name] = p
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> Iterator[str]:
    """Every module named by an import statement of ``path`` (any depth, any block)."""
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                base = ".".join([*up, base] if base else up)
            for a in node.names:
                # ``from agent.wire import trust`` imports the module agent.wire.trust
                sub = f"{base}.{a.name}"
                yield sub if sub in MODULES else base


def _own(target: str) -> str | None:
    """The project module an import names (a name inside a module counts as the module)."""
    while target and target not in MODULES:
        target = target.rpartition(".")[0]
    return target or None


@functools.cache
def _raw() -> dict[str, set[str]]:
    """Every module's imports, parsed once, when a test first asks (not at collection)."""
    return {m: set(_imports(m, p)) for m, p in MODULES.items()}


@functools.cache
def _graph() -> dict[str, set[str]]:
    """The project's import graph: each module to the project modules it imports."""
    return {
        m: {t for t in map(_own, imps) if t and t != m and not m.startswith(t + ".")}
        for m, imps in _raw().items()
    }


def _in(module: str, layer: str) -> bool:
    return module == layer or module.startswith(layer + ".")


def _violations(layer: str, allowed: tuple[str, ...], banned: frozenset[str]) -> list[str]:
    out = []
    for m in sorted(x for x in MODULES if _in(x, layer)):
        for imp in sorted(_raw()[m]):
            top = imp.split(".")[0]
            if top in banned or (
                top == "agent" and imp != "agent" and not any(_in(imp, a) for a in allowed)
            ):
                out.append(f"{m} imports {imp}")
    return out


def test_the_tree_has_the_layers() -> None:
    for layer in ("core", "wire", "net", "body", "phases", "recovery"):
        assert (ROOT / "agent" / layer / "__init__.py").is_file(), layer


def test_core_is_pure() -> None:
    assert _violations("agent.core", ("agent.core",), IO_MODULES) == []


def test_wire_imports_only_itself_and_the_nao_facts() -> None:
    banned = frozenset({"zenoh", "pybullet", "qi", "socket", "sim", "tools"})
    assert _violations("agent.wire", ("agent.wire", "agent.core.nao"), banned) == []


def test_net_sits_on_the_wire() -> None:
    banned = frozenset({"pybullet", "qi", "sim", "tools"})
    assert _violations("agent.net", ("agent.net", "agent.wire"), banned) == []


def test_bodies_never_reach_up_into_the_phases() -> None:
    banned = frozenset({"pybullet", "sim", "tools"})
    allowed = ("agent.body", "agent.net", "agent.wire", "agent.core")
    assert _violations("agent.body", allowed, banned) == []


def test_crash_recovery_builds_on_the_phases_never_the_reverse() -> None:
    """agent/recovery imports the phases (their context, roles, reporter, record sets) and
    what lies below them; the phases never import agent/recovery (the runner is handed a
    ``Recovery`` built on its crew, by ``agent/__main__.py``)."""
    banned = frozenset({"zenoh", "pybullet", "qi", "sim", "tools"})
    allowed = ("agent.recovery", "agent.phases", "agent.body", "agent.net", "agent.wire",
               "agent.core", "agent.config", "agent.seams")  # fmt: skip
    assert _violations("agent.recovery", allowed, banned) == []
    assert _imports_of("agent.phases", lambda i: _in(i, "agent.recovery")) == []


def test_only_the_transport_imports_zenoh_and_only_naoqi_modules_import_qi() -> None:
    zenoh = sorted(
        m for m in MODULES if _in(m, "agent") and "zenoh" in {i.split(".")[0] for i in _raw()[m]}
    )
    assert zenoh and all(_in(m, "agent.net") for m in zenoh), zenoh
    qi = sorted(m for m in MODULES if "qi" in {i.split(".")[0] for i in _raw()[m]})
    assert all("naoqi" in m.rpartition(".")[2] for m in qi), qi


def _imports_of(layer: str, wrong: Callable[[str], bool]) -> list[str]:
    """``module imports name`` for every import of ``layer`` that ``wrong`` refuses."""
    return sorted(
        f"{m} imports {i}" for m in MODULES if _in(m, layer) for i in _raw()[m] if wrong(i)
    )


def test_agent_never_imports_sim_or_tools() -> None:
    assert _imports_of("agent", lambda i: i.split(".")[0] in ("sim", "tools")) == []


def test_sim_imports_only_the_wire_format() -> None:
    wrong = _imports_of("sim", lambda i: i.split(".")[0] == "agent" and not _in(i, "agent.wire"))
    assert wrong == []


def test_tools_never_import_the_phase_machine() -> None:
    wrong = _imports_of("tools", lambda i: _in(i, "agent.phases") or _in(i, "agent.recovery"))
    assert wrong == []


def test_the_rules_catch_what_they_forbid() -> None:
    """The checks can fail: a forbidden import written into a module is found."""
    _raw()["sim.physics.world"].add("agent.phases.runner")
    try:
        assert _imports_of("sim", lambda i: not _in(i, "agent.wire") and i.startswith("agent"))
    finally:
        _raw()["sim.physics.world"].discard("agent.phases.runner")
    _raw()["agent.phases.runner"].add("agent.recovery.resume")
    try:
        assert _imports_of("agent.phases", lambda i: _in(i, "agent.recovery")) == [
            "agent.phases.runner imports agent.recovery.resume"
        ]
    finally:
        _raw()["agent.phases.runner"].discard("agent.recovery.resume")


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_cycle_finder_finds_a_known_cycle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(graph) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles() -> None:
    assert _cycles(_graph()) == []


# The formation core (agent/core/formation), lowest tier first: its rooms (folders) and its
# root modules. A module may import its own room and any room of a lower tier, never
# one of its own tier or above:
# - joined (robots joined by pairs: disjoint sets) stands below everything;
# - frame (the common frame from the records), shape (the pyramid) and obstacle_map (the
#   perceived obstacles in the common frame) stand alone;
# - paths (assignment, straight and bent paths, their geometry) build on the shape;
# - params names the choices of the rooms below it;
# - waves (the safety rule, the schedule, the choice of plan, execution in time) build
#   on the paths and the parameters;
# - plan turns records into a plan through all of them;
# - view (one robot's view of a finished plan: own frame, route, passers-by) reads it;
#   so does reshape (the plan from a held plan's slots to another shape).
FORMATION = "agent.core.formation"
FORMATION_TIERS: tuple[tuple[str, ...], ...] = (
    ("joined",),
    ("frame", "shape", "obstacle_map"),
    ("paths",),
    ("params",),
    ("waves",),
    ("plan",),
    ("view", "reshape"),
)


def _room(module: str, package: str = FORMATION) -> str:
    """The room (folder or root module) of a module of ``package``: ``frame`` for
    ``agent.core.formation.frame.poses``."""
    return module.removeprefix(package + ".").split(".")[0]


def _tier(room: str, tiers: tuple[tuple[str, ...], ...] = FORMATION_TIERS) -> int:
    return next(k for k, rooms in enumerate(tiers) if room in rooms)


def _layer_violations(
    graph: dict[str, set[str]], package: str, tiers: tuple[tuple[str, ...], ...]
) -> list[str]:
    """``m imports t`` for every import from a room of ``package`` into another room of its
    own tier or above."""
    out = []
    for m in sorted(x for x in graph if x.startswith(package + ".")):
        for t in sorted(graph[m]):
            if not t.startswith(package + "."):
                continue
            a, b = _room(m, package), _room(t, package)
            if a != b and _tier(b, tiers) >= _tier(a, tiers):
                out.append(f"{m} imports {t}")
    return out


def _formation_violations(graph: dict[str, set[str]]) -> list[str]:
    return _layer_violations(graph, FORMATION, FORMATION_TIERS)


def test_every_formation_room_has_a_tier() -> None:
    """A new room (or root module) of the formation core must be placed in the order."""
    rooms = {_room(m) for m in MODULES if m.startswith(FORMATION + ".")}
    assert rooms == {r for tier in FORMATION_TIERS for r in tier}
    for room in rooms - {"plan", "params", "reshape", "joined", "obstacle_map"}:
        assert (ROOT / "agent/core/formation" / room / "__init__.py").is_file(), room


def test_formation_rooms_are_layered() -> None:
    assert _formation_violations(_graph()) == []


def test_the_formation_order_catches_an_upward_import() -> None:
    graph = {m: set(ts) for m, ts in _graph().items()}
    graph[f"{FORMATION}.frame.poses"].add(f"{FORMATION}.paths.geometry")
    graph[f"{FORMATION}.shape.pyramid"].add(f"{FORMATION}.frame.records")
    assert _formation_violations(graph) == [
        f"{FORMATION}.frame.poses imports {FORMATION}.paths.geometry",
        f"{FORMATION}.shape.pyramid imports {FORMATION}.frame.records",
    ]


# The world (sim/), lowest tier first: its rooms (folders) and its root modules.
# - camera (the pinhole model, looks, renderers, OBJ meshes, developed pictures) stands
#   alone;
# - scenarios (robots, obstacles, clutter, the look) name what a world starts with;
# - physics (the room, the NAO bodies, walking and turning) builds them;
# - server (the world on the bus, its camera service and render processes, the hand
#   client) serves the physics;
# - naoqi_gateway (virtual NAOs over qi) fronts the server; __main__ starts them all.
SIM_TIERS: tuple[tuple[str, ...], ...] = (
    ("camera",),
    ("scenarios",),
    ("physics",),
    ("server",),
    ("naoqi_gateway",),
    ("__main__",),
)


def test_every_sim_room_has_a_tier() -> None:
    """A new room (or root module) of the world must be placed in the order."""
    rooms = {_room(m, "sim") for m in MODULES if m.startswith("sim.")}
    assert rooms == {r for tier in SIM_TIERS for r in tier}


def test_sim_rooms_are_layered() -> None:
    """No import cycle between the world's rooms: each imports only lower tiers."""
    assert _layer_violations(_graph(), "sim", SIM_TIERS) == []


def test_the_sim_order_catches_an_upward_import() -> None:
    graph = {m: set(ts) for m, ts in _graph().items()}
    graph["sim.camera.picture"].add("sim.physics.world")
    graph["sim.physics.world"].add("sim.server.server")
    assert _layer_violations(graph, "sim", SIM_TIERS) == [
        "sim.camera.picture imports sim.physics.world",
        "sim.physics.world imports sim.server.server",
    ]


MAX_MODULES = 15
# folders over the limit today, with their count: they may shrink, never grow (tools/: one
# module per command, ``python -m tools.NAME``, whose names users type)
OVER_MODULES: dict[str, int] = {"tools": 28}


def _module_counts() -> dict[str, int]:
    """Modules (``.py`` files but ``__init__.py``) of every folder of agent/, sim/, tools/."""
    folders = {p.parent for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    return {
        d.relative_to(ROOT).as_posix(): sum(1 for f in d.glob("*.py") if f.name != "__init__.py")
        for d in sorted(folders)
    }


def test_no_folder_over_15_modules() -> None:
    counts = _module_counts()
    assert {"agent", "sim", "sim/server", "tools"} <= set(counts)
    over = {d: n for d, n in counts.items() if n > OVER_MODULES.get(d, MAX_MODULES)}
    assert over == {}
    # an entry of OVER_MODULES goes once its folder is split
    assert all(counts.get(d, 0) > MAX_MODULES for d in OVER_MODULES), counts


# the tests count as source too: a 600-line test file hides as many concepts as a module
SOURCES = sorted(
    p.relative_to(ROOT).as_posix()
    for pkg in (*PACKAGES, "tests")
    for pattern in ("*.py", "*.js", "*.html")
    for p in (ROOT / pkg).rglob(pattern)
)


@pytest.mark.parametrize("name", SOURCES)
def test_no_source_file_over_600_lines(name: str) -> None:
    n = len((ROOT / name).read_text().splitlines())
    assert n <= MAX_LINES, f"{name}: {n} lines"
