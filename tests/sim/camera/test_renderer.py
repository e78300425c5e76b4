"""The renderer choice (sim/camera/renderer.py): TinyRenderer always, PyBullet's EGL plugin where
it runs, ``auto``'s fallback, the ``--renderer`` flags, and EGL's pictures against
TinyRenderer's on the same scenes.

Under CI=1 the EGL tests must not skip where the EGL libraries are installed (.ci/run
installs them): a plugin that stopped working would otherwise pass unnoticed.
"""

from __future__ import annotations

import ctypes.util
import math
import os
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pybullet as pb
import pytest

from sim.camera import obj_mesh
from sim.camera import renderer as renderers
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario, generate


def _egl_state() -> str | None:
    """None when EGL works, else why not."""
    if renderers.plugin_path() is None:
        return "pybullet has no eglRenderer plugin"
    return renderers.self_test()


EGL_FAILS = _egl_state()
EGL_REQUIRED = bool(os.environ.get("CI")) and ctypes.util.find_library("EGL") is not None


def _need_egl() -> None:
    if EGL_FAILS is not None:
        if EGL_REQUIRED:
            pytest.fail(f"CI has the EGL libraries but EGL does not work: {EGL_FAILS}")
        pytest.skip(f"EGL unusable here: {EGL_FAILS}")


@pytest.fixture
def need_egl() -> None:
    _need_egl()


def orange(img: np.ndarray) -> np.ndarray:
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    return cv2.inRange(hsv, (2, 170, 50), (10, 255, 255)) > 0


# ------------------------------------------------------------------ choice and flags


def test_tiny_is_chosen_without_a_self_test() -> None:
    assert renderers.choose("tiny") == renderers.Choice("tiny", "asked for (--renderer tiny)")
    with pytest.raises(ValueError, match="not one of"):
        renderers.choose("vulkan")
    with pytest.raises(ValueError, match="renderer egl"):  # the GUI is TinyRenderer's
        World(Scenario(robots=(RobotSpec(1, 0.0, 0.0),), seed=3), gui=True, renderer="egl")


@pytest.mark.parametrize("bad", ["/nonexistent/eglRenderer.so", "text"])
def test_auto_falls_back_to_tiny_when_the_plugin_fails(
    bad: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    if bad == "text":  # a file that is no shared library: dlopen refuses it
        (tmp_path / "fake.so").write_text("not a plugin\n")
        bad = str(tmp_path / "fake.so")
    monkeypatch.setenv(renderers.PLUGIN_ENV, bad)
    choice = renderers.choose("auto")
    assert choice.name == "tiny"
    assert choice.why.startswith("auto: EGL unusable")
    sc = Scenario(robots=(RobotSpec(1, 0.0, 0.0),), seed=3)
    with World(sc, renderer="auto") as w:
        assert w.renderer == "tiny"
        assert "EGL unusable" in w.renderer_why
        assert w.render(1, 0.0).shape == (480, 640, 3)
    with pytest.raises(RuntimeError, match="EGL plugin"):
        World(sc, renderer="egl")


def test_the_renderer_flag_on_every_command() -> None:
    from sim.__main__ import build_parser as sim_parser
    from sim.server.render_worker import build_parser as worker_parser
    from tools.bench.render import main as bench_main
    from tools.demo import parse_args as demo_args
    from tools.harness.render import render_command

    for parser in (sim_parser(), worker_parser()):
        assert parser.parse_args([]).renderer == "auto"
        for kind in renderers.RENDERERS:
            assert parser.parse_args(["--renderer", kind]).renderer == kind
        with pytest.raises(SystemExit):
            parser.parse_args(["--renderer", "vulkan"])
    assert demo_args([]).renderer is None  # the world's and workers' own default
    assert demo_args(["--renderer", "tiny"]).renderer == "tiny"
    with pytest.raises(SystemExit):
        demo_args(["--renderer", "vulkan"])
    assert render_command([], (1, 2), "egl")[-2:] == ["--renderer", "egl"]
    assert "--renderer" not in render_command([], (1, 2))
    with pytest.raises(SystemExit):
        bench_main(["--renderer", "vulkan"])


def test_the_camera_encoding_flag_on_the_world_its_workers_and_the_bench() -> None:
    from sim.__main__ import build_parser as sim_parser
    from sim.server.render_worker import build_parser as worker_parser
    from tools.bench.render import main as bench_main
    from tools.harness.render import render_command

    for parser in (sim_parser(), worker_parser()):
        assert parser.parse_args([]).camera_encoding == "bgr8"
        assert parser.parse_args(["--camera-encoding", "png"]).camera_encoding == "png"
        with pytest.raises(SystemExit):
            parser.parse_args(["--camera-encoding", "jpeg"])
    assert render_command([], (1, 2), None, "png")[-2:] == ["--camera-encoding", "png"]
    assert "--camera-encoding" not in render_command([], (1, 2), "egl")
    with pytest.raises(SystemExit):
        bench_main(["--camera-encoding", "jpeg"])


# ------------------------------------------------------------------ TinyRenderer


def test_tiny_pictures_are_the_default_worlds() -> None:
    """``--renderer tiny`` draws exactly what ``World`` draws by default."""
    sc = generate(3, 5, obstacles=1, clutter=2)
    with World(sc, noise=False) as a, World(sc, noise=False, renderer="tiny") as b:
        assert (a.renderer, b.renderer) == ("tiny", "tiny")
        for rid in a.robot_ids:
            assert np.array_equal(a.render(rid, 0.4), b.render(rid, 0.4))


# ------------------------------------------------------------------ EGL


def test_box_mesh_faces_point_outward() -> None:
    verts, normals, idx = obj_mesh.box((0.1, 0.2, 0.3))
    for k in range(0, len(idx), 3):
        a, b, c = (np.array(verts[i]) for i in idx[k : k + 3])
        assert np.dot(np.cross(b - a, c - a), normals[idx[k]]) > 0


@pytest.mark.usefixtures("need_egl")
def test_egl_shade_is_the_plugins_light() -> None:
    """A flat grey wall facing the camera, lit from several directions, has the
    brightness :func:`sim.camera.renderer.egl_shade` says (shadow map off)."""
    client = int(pb.connect(pb.DIRECT))
    try:
        renderers.load_egl(client)
        mesh = obj_mesh.write(
            Path(os.environ.get("TMPDIR", "/tmp")) / f"nao-wall-{os.getpid()}.obj",
            *obj_mesh.box((0.05, 2.0, 2.0)),
        )
        vis = pb.createVisualShape(
            pb.GEOM_MESH, fileName=str(mesh), rgbaColor=(0.5, 0.5, 0.5, 1), physicsClientId=client
        )
        pb.createMultiBody(baseVisualShapeIndex=vis, basePosition=(3, 0, 0), physicsClientId=client)
        mesh.unlink()
        view = pb.computeViewMatrix((0, 0, 0), (1, 0, 0), (0, 0, 1))
        proj = pb.computeProjectionMatrixFOV(40.0, 4 / 3, 0.05, 10.0)
        for deg in (0, 45, 90, 135, 180):
            a = math.radians(deg)
            light = (-math.cos(a), 0.0, math.sin(a))
            with renderers.quiet_stdout():
                _, _, rgba, _, _ = pb.getCameraImage(
                    64, 48, view, proj, lightDirection=light, physicsClientId=client
                )
            got = float(np.asarray(rgba, dtype=np.uint8).reshape(48, 64, 4)[24, 32, 0])
            want = 255 * 0.5 * renderers.egl_shade((-1.0, 0.0, 0.0), light)
            assert abs(got - want) <= 2.0, (deg, got, want)
    finally:
        with renderers.quiet_stdout():
            pb.disconnect(physicsClientId=client)


@pytest.fixture(scope="module")
def pair() -> Iterator[tuple[World, World]]:
    _need_egl()
    sc = generate(4, 9, obstacles=1, clutter=3)
    with World(sc, noise=False) as tiny, World(sc, noise=False, renderer="egl") as egl:
        yield tiny, egl


def test_egl_pictures_match_tinyrenderers(pair: tuple[World, World]) -> None:
    """Same scenes, both renderers: small pixel differences (texture filtering, edges) and
    the same orange robots (mask IoU of each robot's own orange)."""
    tiny, egl = pair
    assert egl.renderer == "egl"
    ious = []
    for rid in tiny.robot_ids:
        for yaw in (-1.2, 0.0, 1.2):
            a, b = tiny.render(rid, yaw), egl.render(rid, yaw)
            assert b.shape == a.shape and b.dtype == a.dtype
            diff = np.abs(a.astype(int) - b.astype(int))
            assert diff.mean() < 6.0, (rid, yaw, diff.mean())
            # registered to a fraction of a pixel (sim.camera.camera.PROJECTION_EGL)
            ga, gb = (cv2.cvtColor(x, cv2.COLOR_BGR2GRAY).astype(np.float32) for x in (a, b))
            (du, dv), _ = cv2.phaseCorrelate(ga, gb)
            assert abs(du) < 0.15 and abs(dv) < 0.15, (rid, yaw, du, dv)
            ma, mb = orange(a), orange(b)
            if ma.sum() > 200:
                ious.append((ma & mb).sum() / (ma | mb).sum())
    assert ious, "no orange in any view"
    assert min(ious) > 0.85, ious


@pytest.mark.usefixtures("need_egl")
def test_egl_world_leaves_stdout_clean(capfd: pytest.CaptureFixture[str]) -> None:
    """The plugin's own prints (GL version, ...) go to stderr, not to the ready lines."""
    with World(Scenario(robots=(RobotSpec(1, 0.0, 0.0),), seed=2), renderer="egl") as w:
        w.render(1, 0.0)
    out = capfd.readouterr().out
    assert "GL" not in out and "EGL" not in out, out
