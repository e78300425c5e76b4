"""The simulated world (docs/design.md §4): a PyBullet room with NAO-like robots.

``python -m sim`` serves it on the bus (:mod:`sim.server`); :class:`sim.world.World` is
the in-process API; ``python -m sim.client`` pokes a running world by hand.
"""
