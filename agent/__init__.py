"""nao-formation's agent: one identical process per NAO (docs/design.md §1, §2).

Importing the package fixes the numeric kernels every agent plans with, before numpy is
loaded (docs/design.md §2, *Determinism*). numpy picks its elementwise kernels and
OpenBLAS its matrix kernels by the CPU it runs on, and the last bits differ: on a host
with AVX-512, 5 of the 16 recorded pyramid plans of ``tests/formation/test_plan_shapes.py``
came out with another fingerprint than on a host without it, and two agents on such hosts
would agree on no digest (a safe stop, but no formation). Every x86-64 host with AVX2 and
FMA is therefore given the same kernels: numpy's AVX-512 dispatch off
(``NPY_DISABLE_CPU_FEATURES``) and OpenBLAS's Haswell kernels (``OPENBLAS_CORETYPE``); a
host without AVX2, or of another architecture, keeps its own, and its agents must share
hosts of their kind. A value already in the environment wins. ``python -m agent``,
``python -m tools.*`` and the test suite import this package before numpy.
"""

from __future__ import annotations

import os
import platform


def _cpu_flags() -> set[str]:
    """The CPU's feature flags (Linux: /proc/cpuinfo), empty where unknown."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


#: numpy's dispatch targets above x86-64-v3 (AVX2, FMA), turned off; naming one a CPU
#: lacks is allowed.
NUMPY_OFF = "X86_V4 AVX512_ICL AVX512_SPR"
#: OpenBLAS's kernels for every x86-64-v3 host.
OPENBLAS_KERNELS = "Haswell"

if platform.machine().lower() in ("x86_64", "amd64") and {"avx2", "fma"} <= _cpu_flags():
    os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", NUMPY_OFF)
    os.environ.setdefault("OPENBLAS_CORETYPE", OPENBLAS_KERNELS)
