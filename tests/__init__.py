"""The test suite; the agent package first, for the agents' numeric kernels (:mod:`agent`)."""

import agent  # noqa: F401
