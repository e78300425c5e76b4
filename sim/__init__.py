"""The simulated world (docs/design.md §4): a PyBullet room with NAO-like robots.

``python -m sim`` serves it on the bus (:mod:`sim.server.server`);
:class:`sim.physics.world.World` is the in-process API; ``python -m sim.server.client``
pokes a running world by hand. Its rooms, lowest first: :mod:`sim.camera` (the forehead
camera and how its pictures are drawn), :mod:`sim.scenarios`, :mod:`sim.physics` (the
room, the NAO bodies, walking), :mod:`sim.server` (the world on the bus), then
:mod:`sim.naoqi_gateway` (virtual NAOs over qi) and ``__main__``.
"""
