"""Progress of a long evaluation: ``[k/n] 37 % elapsed 4:10, about 7:05 left - label``.

One line per finished item on standard error, with the estimate from the mean time per
item so far (a matrix of runs of similar length). No dependency beyond the standard
library, so that every tool can show it.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO


def _clock(seconds: float) -> str:
    s = max(0, round(seconds))
    return (
        f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"
    )


class Progress:
    """Counts finished items of ``total`` and prints the estimate after each."""

    def __init__(
        self,
        total: int,
        name: str,
        stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if total < 1:
            raise ValueError(f"total must be >= 1, got {total}")
        self.total, self.name, self.done = total, name, 0
        self._stream = stream
        self._clock = clock
        self._t0 = clock()

    def line(self) -> str:
        elapsed = self._clock() - self._t0
        left = elapsed / self.done * (self.total - self.done) if self.done else float("nan")
        width = 20
        bar = "#" * (width * self.done // self.total)
        eta = _clock(left) if self.done else "?"
        return (
            f"[{self.name}] [{bar:<{width}}] {self.done}/{self.total} "
            f"{self.done / self.total:4.0%} elapsed {_clock(elapsed)}, about {eta} left"
        )

    def step(self, label: str = "") -> None:
        """One more item finished; print the bar, the estimate and ``label``."""
        self.done = min(self.total, self.done + 1)
        text = self.line() + (f" - {label}" if label else "")
        print(text, file=self._stream or sys.stderr, flush=True)
