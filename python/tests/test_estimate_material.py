"""estimate() and transfer_material() through Python equal `mr estimate` and `mr material` on the
sample photos (same inputs, bit-identical outputs)."""

import json
import math
import os
import pathlib
import re
import subprocess

import numpy as np
import pytest

import libmr
from conftest import SAMPLES

MR = os.environ.get("MR_CLI")
needs_cli = pytest.mark.skipif(not MR or not pathlib.Path(MR).exists(), reason="MR_CLI not given")


@needs_cli
def test_estimate_equals_mr_estimate(tmp_path):
    photo_path, notes = SAMPLES / "leuven.jpg", SAMPLES / "leuven_annotations.json"
    subprocess.run([MR, "estimate", str(photo_path), "--annotations", str(notes), "-o",
                    str(tmp_path / "s.json"), "--depth-out", str(tmp_path / "d.exr"), "-q"], check=True)
    photo = libmr.read_image(photo_path)
    est = libmr.estimate(photo, annotations=notes)
    assert est.camera_source == "exif"
    assert est.scene == libmr.load_scene(tmp_path / "s.json")
    cli_depth = libmr.read_image(tmp_path / "d.exr", to_scene_linear=False, reject_non_finite=False)
    assert est.distance_m.shape == (563, 751, 1)
    np.testing.assert_array_equal(est.distance_m, cli_depth)
    # the annotations as a dict or as JSON text are the same document
    again = libmr.estimate(photo, annotations=json.loads(notes.read_text()))
    np.testing.assert_array_equal(again.distance_m, est.distance_m)
    assert est.horizon_source == "annotations" and 0 < est.confidence <= 1
    assert est.notes


def test_estimate_people_and_frame_border_switches():
    # gallery/tune canyon_couple: two people found by their faces, a scanned print's border
    photo = libmr.read_image(SAMPLES.parent / "gallery" / "tune" / "canyon_couple.jpg")
    on = libmr.estimate(photo)
    off = libmr.estimate(photo, people=False, frame_border=False)
    assert on.pixels["people"] > 0.2 * photo.shape[0] * photo.shape[1]
    assert on.pixels["frame_border"] > 0
    assert off.pixels["people"] == 0 and off.pixels["frame_border"] == 0
    face = (220, 368)  # her face: at her face's distance, not on the far billboard
    assert on.distance_m[face][0] < 3 < 40 < off.distance_m[face][0]


def test_estimate_backlit_land_switch():
    # gallery/tune after_the_rain: a storm's cumulus over a sunset, the land a black silhouette
    photo = libmr.read_image(SAMPLES.parent / "gallery" / "tune" / "after_the_rain.jpg")
    on = libmr.estimate(photo)
    off = libmr.estimate(photo, backlit_land=False)
    cumulus = (500, 640)  # row, column: sky above the land's skyline, not a structure
    assert math.isinf(on.distance_m[cumulus][0]) and math.isfinite(off.distance_m[cumulus][0])
    assert on.horizon[0][1] > 600 > 500 > off.horizon[0][1]


def test_estimate_water_mirror_lamps_and_wall_switches():
    # gallery/tune darkesthour: a lake at blue hour; free: a ceiling lit by its lamps; friends:
    # a window's white curtain, a little pale "sky"
    lake = libmr.read_image(SAMPLES.parent / "gallery" / "tune" / "darkesthour.jpg")
    on = libmr.estimate(lake)
    off = libmr.estimate(lake, water_mirror=False)
    water = (700, 640)  # row, column: the lake near the frame's bottom
    assert math.isfinite(on.distance_m[water][0]) and math.isinf(off.distance_m[water][0])
    ceiling = libmr.read_image(SAMPLES.parent / "gallery" / "tune" / "free.jpg")
    on = libmr.estimate(ceiling)
    off = libmr.estimate(ceiling, lamps_not_sky=False)
    assert on.pixels["sky"] == 0 and off.pixels["sky"] > 0.9 * 1280 * 960
    office = libmr.read_image(SAMPLES.parent / "gallery" / "tune" / "basketball.jpg")
    on = libmr.estimate(office)
    off = libmr.estimate(office, wall_not_sky=False)
    assert on.pixels["sky"] < 0.002 * 640 * 480 and off.pixels["sky"] > 0.2 * 640 * 480
    window = libmr.read_image(SAMPLES.parent / "gallery" / "tune" / "friends.jpg")
    on = libmr.estimate(window)
    off = libmr.estimate(window, little_sky_evidence=False)
    assert on.pixels["sky"] == 0 and off.pixels["sky"] > 0.01 * 852 * 1280
    # cold_water: a sea line 36 px above the level fall-back is the horizon
    sea = libmr.read_image(SAMPLES.parent / "gallery" / "tune" / "cold_water.jpg")
    camera = libmr.Camera(width=800, height=533, focal_px=692.82)  # 60 degrees across
    on = libmr.estimate(sea, camera=camera)
    off = libmr.estimate(sea, camera=camera, level_sky_line=False)
    row = lambda e: 0.5 * (e.horizon[0][1] + e.horizon[1][1])  # noqa: E731
    assert abs(row(on) - 229.5) < 1.5 and abs(row(off) - 266) < 1
    # and the girl wading at its left edge stands where her feet meet the water
    alone = libmr.estimate(sea, camera=camera, standing_people=False)
    head, knee = (238, 25), (305, 25)
    assert abs(on.distance_m[head][0] - on.distance_m[knee][0]) < 0.02 * on.distance_m[knee][0]
    assert alone.distance_m[head][0] > 3 * alone.distance_m[knee][0]
    assert on.pixels["people"] > alone.pixels["people"]


def test_estimate_errors_and_cancel(tmp_path):
    photo = libmr.read_image(SAMPLES / "aerial.jpg")
    bad = {"format": "libmr-annotations", "version": 1, "horizon": [[0, 10], "x"]}
    with pytest.raises(libmr.InvalidArgumentError, match="/horizon/1"):
        libmr.estimate(photo, annotations=bad)
    with pytest.raises(libmr.FileError):
        libmr.estimate(photo, annotations=tmp_path / "missing.json")
    token = libmr.CancelToken()
    token.request()
    with pytest.raises(libmr.CancelledError):
        libmr.estimate(photo, cancel=token)


def reduced(stem, folder):
    """Every third pixel of a sample photo and its depth map, as files (as the C++ CLI test)."""
    photo = libmr.read_image(SAMPLES / f"{stem}.jpg")[::3, ::3]
    depth = libmr.read_image(SAMPLES / f"{stem}_depth.exr", to_scene_linear=False,
                             reject_non_finite=False)[::3, ::3]
    libmr.write_image(folder / f"{stem}.png", photo)
    libmr.write_image(folder / f"{stem}_depth.exr", depth, pixel_type="float")
    return folder / f"{stem}.png", folder / f"{stem}_depth.exr"


@needs_cli
def test_transfer_material_equals_mr_material(tmp_path):
    sample_png, sample_depth = reduced("building", tmp_path)
    target_png, target_depth = reduced("leuven", tmp_path)
    scene = libmr.Scene()
    scene.lighting.sun = libmr.Sun(direction_to_sun=libmr.direction_from_azimuth_elevation(-135, 45),
                                   irradiance=(2.5, 2.5, 2.5))
    scene.lighting.sky_radiance = (0.4, 0.4, 0.4)
    libmr.save_scene(tmp_path / "scene.json", scene)
    w, h = libmr.probe_image(target_png).width, libmr.probe_image(target_png).height
    mask = np.zeros((h, w, 1), np.float32)
    mask[140:180, 40:200] = 1 / 255  # the street
    mask[30:120, 2:35] = 2 / 255  # the left house's wall
    libmr.write_image(tmp_path / "mask.png", mask, pixel_type="8", colorspace="raw")
    cli = [MR, "material", "--sample", str(sample_png), "--sample-depth", str(sample_depth),
           "--sample-scene", str(tmp_path / "scene.json"), "--sample-fov", "50",
           "--target", str(target_png), "--target-depth", str(target_depth),
           "--target-scene", str(tmp_path / "scene.json"), "--fov", "60",
           "--regions", str(tmp_path / "mask.png"), "-q"]
    subprocess.run(cli + ["-o", str(tmp_path / "cli.exr"), "--materials-json", str(tmp_path / "m.json")],
                   check=True)
    subprocess.run(cli + ["-o", str(tmp_path / "physical.exr"), "--physical-exposure"], check=True)

    sample = libmr.read_image(sample_png)
    target = libmr.read_image(target_png)
    s_cam = libmr.Camera.from_horizontal_fov(sample.shape[1], sample.shape[0], 50.0)
    t_cam = libmr.Camera.from_horizontal_fov(w, h, 60.0)
    labels = libmr.load_region_labels(tmp_path / "mask.png", w, h)
    assert labels.shape == (h, w, 1) and set(np.unique(labels)) == {0, 1, 2}
    result = libmr.transfer_material(
        sample, libmr.read_depth(sample_depth, s_cam).distance_m,
        target, libmr.read_depth(target_depth, t_cam).distance_m, labels,
        sample_scene=scene, target_scene=scene, sample_camera=s_cam, target_camera=t_cam)
    assert result.image.shape == (h, w, 3)
    assert len(result.assignment) == 2 and result.candidates
    np.testing.assert_array_equal(result.image, libmr.read_image(tmp_path / "cli.exr"))
    py_doc, cli_doc = json.loads(result.to_json()), json.loads((tmp_path / "m.json").read_text())
    # the notes also say how long steps took (seconds); everything else is identical
    timing = re.compile(r"[0-9.]+ s\b")
    assert [timing.sub("T", n) for n in py_doc.pop("notes")] == [timing.sub("T", n) for n in cli_doc.pop("notes")]
    assert py_doc == cli_doc
    # fit_photo_range=False is `mr material --physical-exposure`; it differs from the default
    # exactly where a region was exposed down to the photo's white.
    physical = libmr.transfer_material(
        sample, libmr.read_depth(sample_depth, s_cam).distance_m,
        target, libmr.read_depth(target_depth, t_cam).distance_m, labels,
        sample_scene=scene, target_scene=scene, sample_camera=s_cam, target_camera=t_cam,
        fit_photo_range=False)
    np.testing.assert_array_equal(physical.image, libmr.read_image(tmp_path / "physical.exr"))
    exposed = any("exposed down" in n for n in result.notes)
    assert exposed == (not np.array_equal(physical.image, result.image))
    assert len(result.exposures) == 2 and exposed == (min(result.exposures) < 1)
    assert physical.exposures == [1.0, 1.0]
    with pytest.raises(libmr.SizeMismatchError):
        libmr.transfer_material(sample, libmr.read_depth(sample_depth, s_cam).distance_m, target,
                                libmr.read_depth(target_depth, t_cam).distance_m, labels[:-1],
                                sample_scene=scene, target_scene=scene, sample_camera=s_cam,
                                target_camera=t_cam)
