"""Agreed planning parameters (docs/design.md §1 "Agree"; the papers assume one program).

Equal records are not enough: every agent must also plan with the same d_e, φ_e,
radius, orientation and strategy, and march the same route. Each agent hashes its own
settings (:func:`params_digest`) and sends that digest with every digest message; a
member whose parameters digest differs is named by :func:`odd_params`, alike on every
agent (see :mod:`agent.core.agreement`).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping

ParamValue = float | int | str | None | tuple[float | str, ...]


def params_digest(params: Mapping[str, ParamValue]) -> str:
    """SHA-256 of the agreed planning parameters in a canonical text form.

    Keys sorted; floats by ``repr`` (shortest round-trip form, so 0.8 and 0.8000000001
    differ and equal floats always hash alike); tuples as lists; ``None`` as null.
    Raises ``ValueError`` for a non-finite float or a type outside :data:`ParamValue`.
    """

    def canon(v: object) -> object:
        if isinstance(v, bool) or v is None or isinstance(v, int | str):
            return v
        if isinstance(v, float):
            if not math.isfinite(v):
                raise ValueError(f"parameter value {v} is not finite")
            return repr(v)
        if isinstance(v, tuple):
            return [canon(x) for x in v]
        raise ValueError(f"parameter value of type {type(v).__name__} cannot be agreed")

    text = json.dumps({str(k): canon(v) for k, v in params.items()}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def odd_params(params_of: Mapping[int, str]) -> tuple[list[int], list[int]]:
    """(odd robots, reference robots) by their parameters digests, ids sorted.

    The reference is the largest group of robots with equal digests; between groups of
    the same size, the one holding the smallest id. Every other robot is odd. A pure
    function of the digests, so agents holding the same digests name the same robots.
    """
    groups: dict[str, list[int]] = {}
    for rid in sorted(params_of):
        groups.setdefault(params_of[rid], []).append(rid)
    ref = min(groups.values(), key=lambda g: (-len(g), g[0]))
    return sorted(i for i in params_of if i not in ref), ref
