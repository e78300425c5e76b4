"""Static obstacles, plan side (NAO paper 5.1.2): the ``near`` placement's translations.

The obstacle plans themselves are tested through the planner in ``test_plan.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from agent.core.formation.waves.obstacles import clear_shifts


def test_clear_shifts_known_answer() -> None:
    # one slot at 0, an obstacle 0.1 m east, step 0.2, clearance 0.6: ring 3 (0.6 m) is
    # clear where cos(angle) <= 1/12 (directions 90°..270°: 9 of 16), ring 4 everywhere
    shifts = clear_shifts(np.zeros((1, 2)), np.array([[0.1, 0.0]]), 0.2, 0.6)
    assert len(shifts) == 9 + 16
    np.testing.assert_allclose(shifts[0], [0.0, 0.6], atol=1e-12)
    np.testing.assert_allclose(shifts[8], [0.0, -0.6], atol=1e-12)
    np.testing.assert_allclose(shifts[9], [0.8, 0.0], atol=1e-12)
    far = clear_shifts(np.zeros((1, 2)), np.array([[5.0, 0.0]]), 0.2, 0.6)
    assert len(far) == 1 + 16 and not far[0].any()  # ring 0 (no move), then ring 1
    none = clear_shifts(np.zeros((1, 2)), np.zeros((0, 2)), 0.2, 0.6)
    assert len(none) == 1 and not none[0].any()
    with pytest.raises(ValueError, match="no obstacle-free place"):
        clear_shifts(np.zeros((1, 2)), np.zeros((1, 2)), 0.01, 100.0)
