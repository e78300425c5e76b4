"""The numeric kernels every agent plans with (agent/__init__.py; docs/design.md §2,
*Determinism*): set before numpy loads, on every x86-64 host with AVX2 and FMA; a value
already in the environment wins."""

from __future__ import annotations

import os
import subprocess
import sys

import agent

SHOW = "import agent, os; print(os.environ.get('NPY_DISABLE_CPU_FEATURES'), os.environ.get('OPENBLAS_CORETYPE'))"


def _run(env: dict[str, str]) -> list[str]:
    out = subprocess.run([sys.executable, "-c", SHOW], env=env, capture_output=True, text=True,
                         check=True, timeout=60)  # fmt: skip
    return out.stdout.split()


def _clean() -> dict[str, str]:
    return {k: v for k, v in os.environ.items()
            if k not in ("NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE")}  # fmt: skip


def test_the_kernels_are_fixed_on_an_avx2_host() -> None:
    want = {"avx2", "fma"} <= agent._cpu_flags()
    got = _run(_clean())
    if want:
        assert got == ["X86_V4", "AVX512_ICL", "AVX512_SPR", "Haswell"]
    else:
        assert got == ["None", "None"]


def test_a_value_in_the_environment_wins() -> None:
    env = _clean() | {"NPY_DISABLE_CPU_FEATURES": "AVX512_SPR", "OPENBLAS_CORETYPE": "Zen"}
    assert _run(env) == ["AVX512_SPR", "Zen"]


def test_numpy_runs_without_its_avx512_kernels_here() -> None:
    """In this suite numpy was loaded after the package: its AVX-512 targets are off."""
    from numpy._core._multiarray_umath import __cpu_features__ as features

    if {"avx2", "fma"} <= agent._cpu_flags():
        assert not features["X86_V4"] and not features["AVX512_ICL"]
