"""numpy <-> libmr images: dtype, shape, strides, zero copy where claimed, metadata, stubs."""

import ast
import pathlib

import numpy as np
import pytest

import libmr
from conftest import SAMPLES


def is_capsule_backed(a):
    """The array shows memory it does not own, whose owner is a libmr capsule (no numpy copy)."""
    return (not a.flags.owndata) and type(a.base).__name__ == "PyCapsule"


def test_read_image_returns_float32_hwc_without_copy():
    img = libmr.read_image(SAMPLES / "aerial.jpg")
    assert img.dtype == np.float32
    assert img.shape == (480, 640, 3)
    assert img.flags.c_contiguous and img.flags.writeable
    assert is_capsule_backed(img)
    assert libmr.is_libmr_image(img)
    # scene-linear: an sRGB-decoded photo has values in [0, 1], not codes
    assert 0.0 <= img.min() and img.max() <= 1.0 and img.mean() > 0.01


def test_exr_float_round_trip_is_exact(tmp_path, rng):
    pixels = rng.random((17, 23, 3), dtype=np.float32) * 4.0  # scene-linear, above 1 too
    path = tmp_path / "x.exr"
    libmr.write_image(path, pixels, pixel_type="float")
    back = libmr.read_image(path)
    assert back.dtype == np.float32 and back.shape == pixels.shape
    np.testing.assert_array_equal(back, pixels)
    # one channel and four channels
    for c in (1, 4):
        p = rng.random((5, 7, c), dtype=np.float32)
        libmr.write_image(tmp_path / f"c{c}.exr", p, pixel_type="float")
        np.testing.assert_array_equal(libmr.read_image(tmp_path / f"c{c}.exr", to_scene_linear=False), p)


def test_non_contiguous_and_2d_inputs_are_accepted(tmp_path, rng):
    base = rng.random((20, 30, 3), dtype=np.float32)
    strided = base[::2, ::3]  # neither rows nor pixels contiguous
    assert not strided.flags.c_contiguous
    transposed = np.ascontiguousarray(base.transpose(1, 0, 2)).transpose(1, 0, 2)  # Fortran-like
    assert not transposed.flags.c_contiguous
    for name, arr in (("strided", strided), ("transposed", transposed)):
        libmr.write_image(tmp_path / f"{name}.exr", arr, pixel_type="float")
        np.testing.assert_array_equal(libmr.read_image(tmp_path / f"{name}.exr"), arr)
    gray = rng.random((6, 9), dtype=np.float32)
    libmr.write_image(tmp_path / "gray.exr", gray, pixel_type="float")
    back = libmr.read_image(tmp_path / "gray.exr", to_scene_linear=False)
    assert back.shape == (6, 9, 1)
    np.testing.assert_array_equal(back[:, :, 0], gray)


@pytest.mark.parametrize(
    "bad, words",
    [
        (np.zeros((4, 4, 3), np.float64), ["float32", "float64"]),
        (np.zeros((4, 4, 3), np.uint8), ["float32", "uint8"]),
        (np.zeros((4,), np.float32), ["shape", "(4,)"]),
        (np.zeros((2, 4, 4, 3), np.float32), ["shape", "(2, 4, 4, 3)"]),
        (np.zeros((0, 4, 3), np.float32), ["empty"]),
        ([[0.0, 1.0]], ["numpy", "list"]),
    ],
)
def test_wrong_types_and_shapes_raise_clear_errors(tmp_path, bad, words):
    with pytest.raises(libmr.InvalidArgumentError) as e:
        libmr.write_image(tmp_path / "x.exr", bad)
    assert e.value.code == libmr.ErrorCode.invalid_argument
    assert str(e.value).startswith("image: ")
    for w in words:
        assert w in str(e.value)
    assert isinstance(e.value, ValueError)
    assert not (tmp_path / "x.exr").exists()


def test_views_of_libmr_arrays_are_not_taken_for_them():
    img = libmr.read_image(SAMPLES / "aerial.jpg")
    assert libmr.is_libmr_image(img)
    assert libmr.is_libmr_image(img[:, :, :])  # the same pixels, shape and strides
    assert not libmr.is_libmr_image(img[1:])  # other shape
    assert not libmr.is_libmr_image(img[:, ::-1])  # other strides
    assert not libmr.is_libmr_image(img.copy())
    assert not libmr.is_libmr_image(np.zeros((2, 2, 3), np.float32))


def test_libmr_arrays_are_used_in_place_with_their_metadata(tmp_path):
    # leuven.jpg has EXIF (Make, 35 mm focal length). Writing the array libmr returned writes
    # libmr's own image (its metadata proves it is not a copy of the numpy data); a numpy copy
    # of the same pixels has none.
    img, md = libmr.read_image(SAMPLES / "leuven.jpg", with_metadata=True)
    assert md["Make"] == "Apple"
    assert libmr.image_metadata(img)["Make"] == "Apple"
    libmr.write_image(tmp_path / "same.jpg", img)
    _, md_same = libmr.read_image(tmp_path / "same.jpg", with_metadata=True)
    assert md_same.get("Make") == "Apple"
    libmr.write_image(tmp_path / "copy.jpg", img.copy())
    _, md_copy = libmr.read_image(tmp_path / "copy.jpg", with_metadata=True)
    assert "Make" not in md_copy
    # an explicit metadata= replaces it (a copy of the pixels with that metadata)
    other = libmr.Metadata({"Make": "Test", "Exif:FocalLengthIn35mmFilm": 50.0})
    libmr.write_image(tmp_path / "other.jpg", img, metadata=other)
    _, md_other = libmr.read_image(tmp_path / "other.jpg", with_metadata=True)
    assert md_other["Make"] == "Test"
    assert libmr.image_metadata(img)["Make"] == "Apple"  # the array's own is unchanged
    assert libmr.image_metadata(img.copy()) is None


def test_in_place_edits_of_a_libmr_array_reach_libmr(tmp_path):
    img = libmr.new_image(4, 5, 3)
    assert img.shape == (4, 5, 3) and not img.any() and is_capsule_backed(img)
    img[1, 2] = (0.25, 0.5, 0.75)
    libmr.write_image(tmp_path / "x.exr", img, pixel_type="float")
    np.testing.assert_array_equal(libmr.read_image(tmp_path / "x.exr")[1, 2], [0.25, 0.5, 0.75])


def test_color_convert_works_in_place_on_numpy_memory():
    config = libmr.ColorConfig.builtin()
    srgb = np.array([[[0.5, 0.0, 1.0], [0.04045, 0.2, 0.8]]], np.float32)
    buffer = np.zeros((3, 4, 3), np.float32)
    view = buffer[1:2, 1:3]  # padded rows: a view into a bigger array
    view[...] = srgb
    address = view.__array_interface__["data"][0]
    config.convert(view, "srgb_texture", "scene_linear")
    assert view.__array_interface__["data"][0] == address
    expected = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(buffer[1:2, 1:3], expected, rtol=2e-3, atol=1e-5)
    assert not buffer[0].any() and not buffer[2].any()  # nothing outside the view touched
    with pytest.raises(libmr.InvalidArgumentError, match="read-only"):
        ro = np.zeros((2, 2, 3), np.float32)
        ro.flags.writeable = False
        config.convert(ro, "srgb_texture", "scene_linear")
    with pytest.raises(libmr.InvalidArgumentError, match="packed"):
        config.convert(np.zeros((2, 6, 3), np.float32)[:, ::2], "srgb_texture", "scene_linear")


def test_read_depth_and_z_conversion():
    depth = libmr.read_depth(SAMPLES / "aerial_depth.exr")
    d = depth.distance_m
    assert d.dtype == np.float32 and d.shape == (480, 640, 1) and is_capsule_backed(d)
    assert depth.no_surface_pixels == np.count_nonzero(np.isinf(d))
    # planar z -> distance along the ray: d = z * |(u, v, 1)|, u = (x + 0.5 - cx) / f
    cam = libmr.Camera.from_horizontal_fov(8, 6, 90.0)
    z = np.full((6, 8), 10.0, np.float32)
    z[0, 0] = 1e10  # Blender's background: sky
    out = libmr.depth_to_distance(z, cam, kind="z").distance_m[:, :, 0]
    ys, xs = np.mgrid[0:6, 0:8]
    norm = np.sqrt(((xs + 0.5 - cam.cx) / cam.focal_px) ** 2 + ((ys + 0.5 - cam.cy) / cam.focal_px) ** 2 + 1)
    expected = 10.0 * norm
    expected[0, 0] = np.inf
    np.testing.assert_allclose(out, expected, rtol=1e-6)
    with pytest.raises(libmr.InvalidArgumentError, match="camera"):
        libmr.depth_to_distance(z, None, kind="z")


def test_type_stubs_cover_the_module():
    stub = pathlib.Path(libmr.__file__).with_name("__init__.pyi")
    tree = ast.parse(stub.read_text())
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
    names = {n for n in names if not n.startswith("_")}
    public = set(libmr.__all__)
    assert public - names == set(), "missing from __init__.pyi"
    assert names - public == set(), "in __init__.pyi but not in libmr"
