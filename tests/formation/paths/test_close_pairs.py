"""Close-pair search by spatial hashing: exact against brute force."""

from __future__ import annotations

import numpy as np

from agent.core.formation.paths.close_pairs import candidate_segment_pairs
from agent.core.formation.paths.geometry import seg_seg_dist


def test_candidate_segment_pairs_is_exact_against_brute_force() -> None:
    # every segment pair of different owners within c is found, and no other: random,
    # point, vertical, horizontal and long segments, owners in any order
    rng = np.random.default_rng(1)
    for trial in range(120):
        m = int(rng.integers(1, 30))
        a = rng.uniform(-5, 5, (m, 2))
        b = a + rng.normal(0, float(rng.choice([0.01, 1.0, 4.0])), (m, 2))
        z = rng.random(m) < 0.2
        b[z] = a[z]
        v = rng.random(m) < 0.1
        b[v, 0] = a[v, 0]
        hz = rng.random(m) < 0.1
        b[hz, 1] = a[hz, 1]
        owner = rng.integers(0, m, m)
        c = float(rng.choice([0.1, 0.4, 2.0]))
        s, t = candidate_segment_pairs(a, b, owner, c)
        got = set(zip(s.tolist(), t.tolist(), strict=True))
        want = {
            (i, j)
            for i in range(m)
            for j in range(m)
            if owner[i] < owner[j] and seg_seg_dist(a[i], b[i], a[j], b[j]) <= c
        }
        assert got == want, trial
