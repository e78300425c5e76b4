"""The NAO forehead camera of the simulated world (docs/design.md §4; NAO paper §3, Fig. 1).

What a camera sees and how its pictures are drawn: the pinhole model (:mod:`.camera`),
the look of the world (:mod:`.look`), the renderers (:mod:`.renderer`, TinyRenderer or
PyBullet's EGL plugin, which draws meshes from OBJ files: :mod:`.obj_mesh`) and the
development of a rendered picture in a look (:mod:`.picture`). It imports nothing else of
``sim``.
"""
