"""mr::Error -> Python exceptions carrying the code and the one-line message."""

import numpy as np
import pytest

import libmr
from conftest import SAMPLES, sky_only_scene

CLASSES = {
    libmr.ErrorCode.invalid_argument: libmr.InvalidArgumentError,
    libmr.ErrorCode.io: libmr.FileError,
    libmr.ErrorCode.corrupt_input: libmr.CorruptInputError,
    libmr.ErrorCode.size_mismatch: libmr.SizeMismatchError,
    libmr.ErrorCode.color: libmr.ColorError,
    libmr.ErrorCode.internal: libmr.InternalError,
    libmr.ErrorCode.cancelled: libmr.CancelledError,
}


def test_one_class_per_code_all_libmr_errors():
    assert len(CLASSES) == len(libmr.ErrorCode.__members__)
    for cls in CLASSES.values():
        assert issubclass(cls, libmr.Error) and issubclass(cls, Exception)
    assert issubclass(libmr.InvalidArgumentError, ValueError)
    assert issubclass(libmr.SizeMismatchError, ValueError)
    assert issubclass(libmr.FileError, OSError)


def test_size_mismatch_names_both_sizes():
    photo = np.zeros((10, 12, 3), np.float32)
    with pytest.raises(libmr.SizeMismatchError) as e:
        libmr.fog(photo, np.ones((10, 11), np.float32), sky_only_scene(libmr))
    assert e.value.code == libmr.ErrorCode.size_mismatch
    assert "12x10" in e.value.message and "11x10" in e.value.message


def test_nan_depth_and_bad_scene_are_invalid_arguments():
    photo = np.zeros((4, 4, 3), np.float32)
    depth = np.ones((4, 4), np.float32)
    depth[1, 1] = np.nan
    with pytest.raises(libmr.InvalidArgumentError) as e:
        libmr.fog(photo, depth, sky_only_scene(libmr))
    assert e.value.code == libmr.ErrorCode.invalid_argument
    scene = sky_only_scene(libmr)
    scene.medium.albedo = (2.0, 1.0, 1.0)
    with pytest.raises(libmr.InvalidArgumentError, match="medium.albedo"):
        libmr.fog(photo, np.ones((4, 4), np.float32), scene)
    with pytest.raises(libmr.InvalidArgumentError, match="visibility"):
        libmr.extinction_from_visibility(-1.0)


def test_files_missing_corrupt_and_unwritable(tmp_path):
    with pytest.raises(libmr.FileError) as e:
        libmr.read_image(tmp_path / "missing.jpg")
    assert e.value.code == libmr.ErrorCode.io and "missing.jpg" in e.value.message
    garbage = tmp_path / "garbage.jpg"
    garbage.write_bytes(b"this is not a jpeg" * 10)
    with pytest.raises(libmr.Error) as e:
        libmr.read_image(garbage)
    assert e.value.code in (libmr.ErrorCode.io, libmr.ErrorCode.corrupt_input)
    assert "garbage.jpg" in e.value.message
    truncated = tmp_path / "truncated.png"
    libmr.write_image(tmp_path / "good.png", np.full((64, 64, 3), 0.5, np.float32))
    data = (tmp_path / "good.png").read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(libmr.Error) as e:
        libmr.read_image(truncated)
    assert e.value.code in (libmr.ErrorCode.io, libmr.ErrorCode.corrupt_input)
    with pytest.raises(libmr.FileError) as e:
        libmr.write_image(tmp_path / "no" / "such" / "dir.png", np.zeros((2, 2, 3), np.float32))
    assert "dir.png" in e.value.message
    # nothing partial left behind by the failed atomic write
    assert sorted(p.name for p in tmp_path.iterdir()) == ["garbage.jpg", "good.png", "truncated.png"]


def test_depth_size_against_camera():
    cam = libmr.Camera.from_horizontal_fov(100, 50, 60.0)
    with pytest.raises(libmr.SizeMismatchError):
        libmr.read_depth(SAMPLES / "aerial_depth.exr", cam)


def test_errors_pickle_for_dask():
    # Dask sends a worker's exception back to the client by pickling it.
    import pickle

    try:
        libmr.extinction_from_visibility(0.0)
    except libmr.Error as e:
        back = pickle.loads(pickle.dumps(e))
        assert type(back) is libmr.InvalidArgumentError and str(back) == str(e)
