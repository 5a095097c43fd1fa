"""fog through Python equals `mr fog` pixel for pixel on a sample photo (same scene, same camera
from the photo's EXIF, float EXR outputs compared bit for bit)."""

import os
import pathlib
import shutil
import subprocess

import numpy as np
import pytest

import libmr
from conftest import SAMPLES

MR = os.environ.get("MR_CLI")


def mr_fog(tmp_path, photo, extra):
    out = tmp_path / "cli"
    scene_file = tmp_path / "scene.json"
    cmd = [MR, "fog", str(photo), "--out-dir", str(out), "--format", "exr", "--bit-depth", "float",
           "--save-scene", str(scene_file), "-q"] + extra
    subprocess.run(cmd, check=True)
    return libmr.read_image(out / (photo.stem + "_fog.exr")), libmr.load_scene(scene_file)


def python_fog(photo_path, depth_path, scene):
    photo = libmr.read_image(photo_path)  # carries its EXIF: the camera comes from it as in mr fog
    camera = libmr.default_camera(photo.shape[1], photo.shape[0], scene, libmr.image_metadata(photo))
    depth = libmr.read_depth(depth_path, camera).distance_m
    return libmr.fog(photo, depth, scene)


@pytest.mark.skipif(not MR or not pathlib.Path(MR).exists(), reason="MR_CLI (the mr command) not given")
@pytest.mark.parametrize(
    "extra",
    [
        ["--visibility", "300m"],  # sky light only (the streamed closed form in mr fog)
        ["--visibility", "200m", "--layer", "0,60", "--sun-azimuth", "30", "--sun-elevation", "25",
         "--quality", "draft"],  # the scattering core: shafts from the photo's geometry
    ],
    ids=["sky-only", "sun"],
)
def test_python_fog_equals_mr_fog(tmp_path, extra):
    photo = tmp_path / "leuven.jpg"  # EXIF focal length: the camera must come from it
    shutil.copy(SAMPLES / "leuven.jpg", photo)
    shutil.copy(SAMPLES / "leuven_depth.exr", tmp_path / "leuven_depth.exr")
    cli_out, scene = mr_fog(tmp_path, photo, extra)
    layers = python_fog(photo, tmp_path / "leuven_depth.exr", scene)
    assert cli_out.shape == layers.composite.shape
    np.testing.assert_array_equal(cli_out, layers.composite)
    # and written by Python the same way, the files' pixels are identical too
    libmr.write_image(tmp_path / "py.exr", layers.composite, pixel_type="float")
    np.testing.assert_array_equal(libmr.read_image(tmp_path / "py.exr"), cli_out)
    # fog_file: file to file as mr fog does it (the default JPEG output: roll-off, 8 bits)
    subprocess.run([MR, "fog", str(photo), "--out-dir", str(tmp_path / "jpg"), "--scene",
                    str(tmp_path / "scene.json"), "-q"], check=True)
    result = libmr.fog_file(photo, tmp_path / "leuven_depth.exr", tmp_path / "ff.jpg", scene)
    assert result.streamed == (scene.lighting.sun is None)
    np.testing.assert_array_equal(libmr.read_image(tmp_path / "ff.jpg", to_scene_linear=False),
                                  libmr.read_image(tmp_path / "jpg" / "leuven_fog.jpg", to_scene_linear=False))
    with pytest.raises(libmr.FileError, match="exists"):
        libmr.fog_file(photo, tmp_path / "leuven_depth.exr", tmp_path / "ff.jpg", scene, overwrite=False)
