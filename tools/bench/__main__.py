"""``python -m tools.bench {plan,makespan,world,perception,agent,render,pictures,scale,idle}``: benchmarks that print numbers.

Each sub-benchmark lives in its own module ``tools/bench/<name>.py`` with a
``main(argv) -> int``.
"""

from __future__ import annotations

import importlib
import sys

TARGETS = (
    "plan",
    "makespan",
    "world",
    "perception",
    "agent",
    "render",
    "pictures",
    "scale",
    "idle",
)


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] not in TARGETS:
        print(f"usage: python -m tools.bench {{{','.join(TARGETS)}}} [options]", file=sys.stderr)
        return 2
    try:
        mod = importlib.import_module(f"tools.bench.{args[0]}")
    except ModuleNotFoundError as exc:
        print(f"benchmark {args[0]!r} is not available: {exc}", file=sys.stderr)
        return 2
    return int(mod.main(args[1:]))


if __name__ == "__main__":
    raise SystemExit(main())
