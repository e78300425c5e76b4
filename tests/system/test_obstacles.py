"""One obstacle in the way, as real processes (NAO paper 5.1.2): world + 4
agents over loopback, secure by default, ``python -m tools.demo --obstacles 1``. The
obstacle stands on a straight path of the obstacle-free plan; the robots see it, report
it in their records, and the agreed plan routes around it. Bounded by the demo's own
limits."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from sim.physics.nao_model import FOOTPRINT_RADIUS
from tests.system.world import run_demo

pytestmark = [pytest.mark.system, pytest.mark.slow]


def _gap(path: np.ndarray, centre: np.ndarray) -> float:
    """Smallest distance from ``centre`` to the polyline ``path``."""
    best = np.inf
    for a, b in itertools.pairwise(path):
        ab = b - a
        t = np.clip(np.dot(centre - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0)
        best = min(best, float(np.linalg.norm(a + t * ab - centre)))
    return best


def test_four_robots_route_around_one_obstacle(tmp_path: Path) -> None:
    res, r = run_demo(tmp_path, "--robots", "4", "--seed", "1", "--obstacles", "1")
    assert "obstacles: 1 in the way" in res.stdout, (res.stdout[-2000:], res.stderr[-2000:])
    assert set(r["final_phase"].values()) == {"done"}, r.get("errors")
    assert r["identical_digests"] is True
    ((ox, oy, radius),) = r["obstacles"]
    centre = np.array([ox, oy])
    # it stood on a straight path from a start to the obstacle-free plan's target
    starts = np.array([r["starts"][i][:2] for i in sorted(r["starts"])])
    assert np.min(np.hypot(*(starts - centre).T)) >= 0.5
    # every robot saw it or was told: one merged obstacle, within 15 cm of the truth
    assert r["obstacles_seen"] == 1 and r["obstacle_position_error"][0] < 0.15
    # the agreed routes keep the clearance from the true obstacle (footprints apart)
    routes = [np.array(p) for p in r["planned_routes"].values()]
    assert min(_gap(p, centre) for p in routes) > radius + FOOTPRINT_RADIUS
    assert r["obstacle_contacts"] == 0 and r["contacts"] == 0
    assert r["min_obstacle_gap"] > 0.0
    assert r["success"] is True and res.returncode == 0
    assert (tmp_path / "demo" / "formation.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
