"""``python -m tools.bench scale``: the fleet at 10, 30 and 50 NAOs, the wall time per
phase printed and drawn as a stacked bar chart (where the time goes in large fleets).

The same tool as ``python -m tools.eval_scale`` (its arguments; default ``--robots 10
--robots 30 --robots 50 --seeds 1``): each run judged from the ground truth, the table,
the phase chart ``scale_phases.png`` under ``--out`` (default ``out/eval_scale``).
"""

from __future__ import annotations

from tools import eval_scale


def main(argv: list[str]) -> int:
    return eval_scale.main(argv)
