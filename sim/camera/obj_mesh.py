"""Meshes as Wavefront OBJ files, the form PyBullet's EGL renderer plugin can draw
(docs/design.md §4; :mod:`sim.camera.renderer`).

The plugin draws a ``GEOM_MESH`` visual shape only from a file (OBJ, STL, COLLADA), not
from the vertex lists :mod:`sim.physics.nao_model` and :mod:`sim.physics.world` hand to
TinyRenderer, and it ignores a texture set later with ``changeVisualShape``: a textured quad's picture must
come with its OBJ, through a material file (``map_Kd``). :func:`write` writes the same
vertices, normals (kept by the loader: smooth parts stay smooth) and texture coordinates.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

Vec = Sequence[float]


def write(
    path: Path,
    verts: Sequence[Vec],
    normals: Sequence[Vec],
    idx: Sequence[int],
    uvs: Sequence[tuple[float, float]] | None = None,
    texture: Path | None = None,
) -> Path:
    """Write one mesh (triangles ``idx`` into ``verts``, one normal and optionally one
    texture coordinate per vertex) to ``path``; with ``texture`` (an image file beside it)
    also ``path.mtl`` naming it. Returns ``path``."""
    if len(idx) % 3 or len(normals) != len(verts) or (uvs is not None and len(uvs) != len(verts)):
        raise ValueError("a mesh needs whole triangles and one normal (and uv) per vertex")
    lines: list[str] = []
    if texture is not None:
        mtl = path.with_suffix(".mtl")
        mtl.write_text(f"newmtl m\nKa 1 1 1\nKd 1 1 1\nmap_Kd {texture.name}\n")
        lines += [f"mtllib {mtl.name}", "usemtl m"]
    lines += [f"v {v[0]:.7g} {v[1]:.7g} {v[2]:.7g}" for v in verts]
    lines += [f"vn {n[0]:.7g} {n[1]:.7g} {n[2]:.7g}" for n in normals]
    if uvs is not None:
        # OBJ's v runs up the image; TinyRenderer's (the uvs the world gives) runs down.
        lines += [f"vt {u:.7g} {v:.7g}" for u, v in uvs]
    for k in range(0, len(idx), 3):
        a, b, c = (i + 1 for i in idx[k : k + 3])
        if uvs is not None:
            lines.append(f"f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}")
        else:
            lines.append(f"f {a}//{a} {b}//{b} {c}//{c}")
    path.write_text("\n".join(lines) + "\n")
    return path


def box(half: Vec) -> tuple[list[list[float]], list[list[float]], list[int]]:
    """A box of half extents ``half`` about its centre: 6 flat faces (24 vertices, face
    normals, counter-clockwise outward), as TinyRenderer shades a ``GEOM_BOX``."""
    verts: list[list[float]] = []
    normals: list[list[float]] = []
    idx: list[int] = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            u, w = (axis + 1) % 3, (axis + 2) % 3
            n = [0.0, 0.0, 0.0]
            n[axis] = sign
            base = len(verts)
            for su, sw in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [0.0, 0.0, 0.0]
                p[axis] = sign * half[axis]
                p[u] = su * half[u]
                p[w] = sw * half[w]
                verts.append(p)
                normals.append(list(n))
            # (u, w, axis) is right-handed: u x w = axis, so u-then-w runs CCW about +axis.
            quad = (0, 1, 2, 0, 2, 3) if sign > 0 else (0, 2, 1, 0, 3, 2)
            idx += [base + q for q in quad]
    return verts, normals, idx
