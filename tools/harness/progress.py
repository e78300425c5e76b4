"""Progress of a long evaluation (docs/design.md §10): a bar with the estimate of the time
left, ``[name] [#####...] k/n 37 % elapsed 4:10, about 7:05 left - label``.

On a terminal the bar is ``rich``'s (redrawn in place, the label of each finished item
printed above it); elsewhere (CI logs, files) one plain line per finished item, so that a
log reads top to bottom. The estimate is the mean time per item so far (a matrix of runs
of similar length).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.progress import Progress as RichProgress


def _clock(seconds: float) -> str:
    s = max(0, round(seconds))
    return (
        f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"
    )


class Progress:
    """Counts finished items of ``total`` and shows the estimate after each: ``rich``'s bar
    on a terminal (``stream`` a TTY, default standard error), else a plain line."""

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
        out = stream or sys.stderr
        self._bar: RichProgress | None = None
        if out.isatty():
            self._bar = RichProgress(
                TextColumn(f"[bold]{name}[/]"),
                BarColumn(),
                MofNCompleteColumn(),
                TaskProgressColumn(),
                TextColumn("elapsed"),
                TimeElapsedColumn(),
                TextColumn("left"),
                TimeRemainingColumn(),
                console=Console(file=out),
                transient=False,
            )
            self._task = self._bar.add_task(name, total=total)
            self._bar.start()

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
        """One more item finished; show the bar, the estimate and ``label``."""
        self.done = min(self.total, self.done + 1)
        if self._bar is not None:
            if label:
                self._bar.console.print(f"[{self.name}] {label}", markup=False, highlight=False)
            self._bar.update(self._task, completed=self.done)
            if self.done >= self.total:
                self.close()
            return
        text = self.line() + (f" - {label}" if label else "")
        print(text, file=self._stream or sys.stderr, flush=True)

    def close(self) -> None:
        """Leave the terminal's bar as it is (also when the matrix stops early)."""
        if self._bar is not None:
            self._bar.stop()
            self._bar = None
