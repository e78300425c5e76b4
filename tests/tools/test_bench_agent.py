"""tools/bench/agent.py: the agreement cost model runs and agrees."""

from __future__ import annotations

import numpy as np

from tools.bench.agent import main, simulate


def test_simulate_agrees_with_and_without_loss() -> None:
    rng = np.random.default_rng(1)
    clean = simulate(4, 0.0, rng)
    lossy = simulate(4, 0.3, rng)
    assert clean["agreed"] == 1.0 and lossy["agreed"] == 1.0
    assert 0 < clean["bytes_mean"] <= clean["bytes_max"]
    assert lossy["bytes_mean"] >= clean["bytes_mean"]  # loss costs re-sends, never less


def test_cli_rejects_bad_loss() -> None:
    import pytest

    with pytest.raises(SystemExit):
        main(["--losses", "1.5"])
