"""Tools around the fleet: the demo, evaluations, benchmarks, the viewer (docs/design.md §2).

The agent package is imported first, so that every tool that plans (and compares its
digest with the agents') uses the agents' numeric kernels (:mod:`agent`).
"""

import agent  # noqa: F401  (before numpy: the agents' numeric kernels)
