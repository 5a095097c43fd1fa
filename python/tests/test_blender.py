"""The Blender add-on (python/blender/mr_fog), headless: render a small procedural scene with
Cycles and its Z pass, fog it through the add-on, compare with `mr fog` on the same passes.
Skipped where blender is not installed (scripts/setup does not install it)."""

import json
import os
import pathlib
import shutil
import subprocess

import numpy as np
import pytest

import libmr

BLENDER = shutil.which("blender")
MR = os.environ.get("MR_CLI")
SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "blender" / "tests" / "render_and_fog.py"


@pytest.mark.skipif(BLENDER is None, reason="blender is not installed (apt-get install blender): "
                                             "the add-on's headless test is skipped")
@pytest.mark.skipif(not MR or not os.path.exists(MR), reason="MR_CLI (the mr command) not given")
def test_addon_fog_equals_mr_fog_on_the_same_passes(tmp_path):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (os.environ.get("PYTHONPATH"), str(pathlib.Path(libmr.__file__).parents[1])) if p)
    run = subprocess.run([BLENDER, "-b", "--factory-startup", "--python", str(SCRIPT), "--", str(tmp_path)],
                         env=env, capture_output=True, text=True, timeout=600)
    assert "render_and_fog: done" in run.stdout, run.stdout[-3000:] + run.stderr[-3000:]
    checks = json.loads((tmp_path / "checks.json").read_text())
    # the camera and pose converted from Blender put the ground plane (Blender z = -1) at libmr
    # y = -1: each bottom-row pixel's depth along its libmr ray lands on it within 1 mm
    assert np.max(np.abs(np.array(checks["ground_heights_m"]) + 1.0)) < 1e-3
    assert checks["operator"] == "IMAGE_OT_mr_fog_render_result"
    # the Blender image the add-on wrote holds the composite
    assert checks["image_size"] == [96, 72]
    assert checks["image_mean"] == pytest.approx(checks["composite_mean"], rel=1e-6)
    # `mr fog` on the same passes (Z as planar depth) with the add-on's scene: equal, bit for bit
    subprocess.run([MR, "fog", str(tmp_path / "photo.exr"), "--depth", str(tmp_path / "photo_depth.exr"),
                    "--depth-kind", "z", "--scene", str(tmp_path / "scene.json"), "--out-dir",
                    str(tmp_path / "cli"), "--format", "exr", "--bit-depth", "float", "-q"], check=True)
    addon = libmr.read_image(tmp_path / "addon_composite.exr")
    cli = libmr.read_image(tmp_path / "cli" / "photo_fog.exr")
    photo = libmr.read_image(tmp_path / "photo.exr")
    assert addon.shape == cli.shape == (72, 96, 3)
    np.testing.assert_array_equal(addon, cli)
    assert not np.array_equal(addon, photo)  # fog changed the render
    scene = libmr.load_scene(tmp_path / "scene.json")
    assert scene.lighting.sun is not None and scene.camera.width == 96
