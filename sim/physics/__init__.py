"""The simulated room and its robots' bodies (docs/design.md §4; NAO paper §3.1, §4.2).

The PyBullet room and its in-process API (:mod:`.world`), the NAO-like body built from
primitives (:mod:`.nao_model`) and walking and turning on the sim clock with seeded
noise and contacts (:mod:`.locomotion`). It builds on :mod:`sim.camera` and
:mod:`sim.scenarios`, never on :mod:`sim.server`.
"""
