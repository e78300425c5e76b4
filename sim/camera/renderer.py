"""Which renderer draws the forehead cameras: PyBullet's TinyRenderer or its EGL plugin
(docs/design.md §4; docs/world.md "Renderers").

- ``tiny``: PyBullet's CPU TinyRenderer, single-threaded (the reference pictures).
- ``egl``: PyBullet's EGL renderer plugin (``eglRenderer``), OpenGL through EGL; with no
  GPU, Mesa's llvmpipe rasterises on the CPU, several times cheaper per frame than
  TinyRenderer. The plugin draws only primitives and OBJ meshes (not meshes given as
  vertex lists), ignores texture changes and uses its own light model, so the world builds
  its room for it from OBJ files (:mod:`sim.camera.obj_mesh`) and matches TinyRenderer's light
  with colour factors (:func:`egl_shade`). It must be loaded before the scene is built.
- ``auto``: ``egl`` when the plugin loads and passes :func:`self_test` (a tiny scene drawn
  and checked not empty), else ``tiny``; :func:`choose` says which and why.

The plugin prints to the C-level stdout (GL version, vendor, "Destroy EGL OpenGL window")
on load, on its first pictures and on disconnect; :func:`quiet_stdout` sends those lines
to stderr, so a process whose stdout carries ready lines (``sim ready ...``) keeps it
clean.
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib.util
import math
import os
import struct
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as pb

RENDERERS = ("auto", "tiny", "egl")
DEFAULT = "auto"
RENDERER_HELP = (
    "camera renderer: tiny (PyBullet's TinyRenderer), egl (PyBullet's EGL plugin, "
    "llvmpipe without a GPU) or auto (egl when it loads and passes a self-test, else "
    "tiny; default)"
)
#: Environment variable naming another EGL plugin file (tests point it at a bad path to
#: check the fallback of ``auto``).
PLUGIN_ENV = "NAO_EGL_PLUGIN"

#: TinyRenderer's light (sim.camera.camera.render): ambient and diffuse shares of the intensity.
TINY_AMBIENT = 0.62
TINY_DIFFUSE = 0.38


@dataclass(frozen=True)
class Choice:
    """The renderer a world uses (``tiny`` or ``egl``) and why."""

    name: str
    why: str


def check(name: str) -> str:
    """``name`` if it is one of :data:`RENDERERS`, else ``ValueError``."""
    if name not in RENDERERS:
        raise ValueError(f"renderer {name!r} is not one of {', '.join(RENDERERS)}")
    return name


def plugin_path() -> str | None:
    """The EGL plugin's file: :data:`PLUGIN_ENV` if set, else pybullet's ``eglRenderer``."""
    env = os.environ.get(PLUGIN_ENV)
    if env:
        return env
    spec = importlib.util.find_spec("eglRenderer")
    return spec.origin if spec is not None else None


@contextlib.contextmanager
def quiet_stdout() -> Iterator[None]:
    """Send what C code prints to stdout (fd 1) to stderr while the block runs."""
    sys.stdout.flush()
    libc = ctypes.CDLL(None)
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        libc.fflush(None)
        os.dup2(saved, 1)
        os.close(saved)


def load_egl(client: int, path: str | None = None) -> None:
    """Load the EGL plugin into ``client`` (before anything is built) and switch its shadow
    map off (:func:`shadow_map_off`); ``RuntimeError`` if it does not load or the shadow
    map cannot be switched off."""
    path = path if path is not None else plugin_path()
    if not path or not Path(path).is_file():
        raise RuntimeError(f"no EGL plugin file ({path or 'eglRenderer not installed'})")
    with quiet_stdout():
        plugin = pb.loadPlugin(path, "_eglRendererPlugin", physicsClientId=client)
    if plugin < 0:
        raise RuntimeError(f"the EGL plugin {path} did not load (no EGL/OpenGL libraries?)")
    shadow_map_off(path)


def shadow_map_off(path: str) -> None:
    """Clear the plugin's ``useShadowMap`` flag (bullet3's GLInstancingRenderer: "todo:
    make this configurable"), which no API reaches: with it every picture first draws the
    scene into a 4096 x 4096 shadow map (half the cost of a picture on llvmpipe) and
    shades with specular highlights and cast shadows that TinyRenderer, without shadows,
    does not draw. Without it the plugin shades ``0.75 + 0.25 n.l`` (:func:`egl_shade`).

    The flag is a private one-byte variable of the loaded plugin: its address is the
    plugin's load address (``/proc/self/maps``) plus its offset in the file's symbol
    table. It is written only if it holds exactly 1 (true); else ``RuntimeError``."""
    real = os.path.realpath(path)
    found = elf_symbol(real, "useShadowMap")
    if found is None or found[1] != 1:
        raise RuntimeError(f"no one-byte useShadowMap symbol in {real}")
    base = None
    with open("/proc/self/maps") as maps:
        for line in maps:
            parts = line.split()
            if len(parts) >= 6 and int(parts[2], 16) == 0 and os.path.realpath(parts[5]) == real:
                base = int(parts[0].split("-")[0], 16)
                break
    if base is None:
        raise RuntimeError(f"the EGL plugin {real} is not mapped in this process")
    flag = ctypes.c_uint8.from_address(base + found[0])
    if flag.value not in (0, 1):
        raise RuntimeError(f"useShadowMap reads {flag.value}, not a flag: plugin layout unknown")
    flag.value = 0


def elf_symbol(path: str, name: str) -> tuple[int, int] | None:
    """(offset, size) of symbol ``name`` in the ``.symtab`` of the 64-bit little-endian ELF
    file ``path``, or None."""
    data = Path(path).read_bytes()
    if data[:4] != b"\x7fELF" or data[4] != 2 or data[5] != 1:
        return None
    (shoff,) = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum = struct.unpack_from("<HH", data, 0x3A)
    sections = [
        struct.unpack_from("<IIQQQQIIQQ", data, shoff + i * shentsize) for i in range(shnum)
    ]
    want = name.encode()
    for sec in sections:
        if sec[1] != 2 or sec[9] == 0:  # SHT_SYMTAB
            continue
        off, size, link, entsize = sec[4], sec[5], sec[6], sec[9]
        strings = sections[link][4]
        for k in range(size // entsize):
            st_name, _, _, _, value, sym_size = struct.unpack_from(
                "<IBBHQQ", data, off + k * entsize
            )
            start = strings + st_name
            if data[start : start + len(want) + 1] == want + b"\0":
                return int(value), int(sym_size)
    return None


def self_test(path: str | None = None) -> str | None:
    """Draw an orange box with the EGL plugin in a client of its own; None when the
    picture shows it, else why not."""
    from sim.camera import obj_mesh

    client = int(pb.connect(pb.DIRECT))
    if client < 0:
        return "cannot connect to PyBullet"
    try:
        load_egl(client, path)
        with tempfile.TemporaryDirectory(prefix="nao-egl-") as tmp:
            mesh = Path(tmp) / "box.obj"
            obj_mesh.write(mesh, *obj_mesh.box((0.2, 0.2, 0.2)))
            vis = pb.createVisualShape(
                pb.GEOM_MESH,
                fileName=str(mesh),
                rgbaColor=(1.0, 0.22, 0.0, 1.0),
                physicsClientId=client,
            )
            pb.createMultiBody(
                baseVisualShapeIndex=vis, basePosition=(1.5, 0.0, 0.0), physicsClientId=client
            )
        view = pb.computeViewMatrix((0, 0, 0), (1, 0, 0), (0, 0, 1))
        proj = pb.computeProjectionMatrixFOV(50.0, 4 / 3, 0.05, 10.0)
        with quiet_stdout():
            _, _, rgba, _, _ = pb.getCameraImage(
                64,
                48,
                viewMatrix=view,
                projectionMatrix=proj,
                renderer=pb.ER_BULLET_HARDWARE_OPENGL,
                flags=pb.ER_NO_SEGMENTATION_MASK,
                physicsClientId=client,
            )
        img = np.asarray(rgba, dtype=np.uint8).reshape(48, 64, 4).astype(int)
        orange = (img[:, :, 0] > 100) & (img[:, :, 1] < img[:, :, 0] // 2) & (img[:, :, 2] < 40)
        share = float(orange.mean())
        if not 0.05 < share < 0.6:
            return f"the self-test picture is not the test scene (orange share {share:.2f})"
        return None
    except Exception as exc:  # pybullet.error, RuntimeError: the plugin is unusable
        return f"{type(exc).__name__}: {exc}"
    finally:
        with quiet_stdout():
            pb.disconnect(physicsClientId=client)


def choose(requested: str, path: str | None = None) -> Choice:
    """The renderer for ``requested`` (:data:`RENDERERS`). ``egl`` is taken as asked (the
    world fails if the plugin does not load); ``auto`` runs :func:`self_test` first."""
    check(requested)
    if requested == "tiny":
        return Choice("tiny", "asked for (--renderer tiny)")
    if requested == "egl":
        return Choice("egl", "asked for (--renderer egl)")
    failed = self_test(path)
    if failed is None:
        return Choice("egl", "auto: the EGL plugin loaded and passed its self-test")
    return Choice("tiny", f"auto: EGL unusable, {failed}")


def egl_shade(normal: tuple[float, float, float], light: tuple[float, float, float]) -> float:
    """The EGL plugin's light factor, shadow map off (:func:`shadow_map_off`), for a
    surface of unit ``normal`` under the unit ``light`` direction: its shader (bullet3's
    instancingPS) gives ``i (1 - a) + a`` with ambient ``a`` = 0.5 and ``i`` = 0.5 + 0.5 n.l,
    so 0.75 + 0.25 n.l (``tests/sim/camera/test_renderer.py`` measures it)."""
    d = max(-1.0, min(1.0, sum(a * b for a, b in zip(normal, light, strict=True))))
    return 0.75 + 0.25 * d


def tiny_shade(
    normal: tuple[float, float, float], light: tuple[float, float, float], intensity: float
) -> float:
    """TinyRenderer's light factor (ambient + diffuse, :mod:`sim.camera.camera`) for the same."""
    d = sum(a * b for a, b in zip(normal, light, strict=True))
    return intensity * (TINY_AMBIENT + TINY_DIFFUSE * max(0.0, d))


def unit(v: tuple[float, float, float]) -> tuple[float, float, float]:
    n = math.sqrt(sum(c * c for c in v)) or 1.0
    return (v[0] / n, v[1] / n, v[2] / n)
