"""The progress bar of long tools (tools/harness/progress.py): rich's
bar with the estimate on a terminal, one plain line per item elsewhere (CI logs)."""

from __future__ import annotations

import io

from tools.harness.progress import Progress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_terminal_gets_the_bar_with_the_estimate_and_the_labels() -> None:
    out = Terminal()
    bar = Progress(4, "matrix", stream=out)
    for k in range(4):
        bar.step(f"run {k} ok")
    text = out.getvalue()
    assert "run 3 ok" in text and "4/4" in text and "matrix" in text
    assert "\x1b[" in text  # drawn in place


def test_a_log_gets_one_plain_line_per_item() -> None:
    out = io.StringIO()
    now = [0.0]
    bar = Progress(2, "matrix", stream=out, clock=lambda: now[0])
    now[0] = 30.0
    bar.step("first")
    lines = out.getvalue().splitlines()
    assert lines == [
        "[matrix] [##########          ] 1/2  50% elapsed 0:30, about 0:30 left - first"
    ]
