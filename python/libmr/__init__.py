"""libmr: physically based fog, haze and light in photographs (Python bindings).

    import libmr
    photo = libmr.read_image("street.jpg")            # float32 (H, W, 3), scene-linear
    depth = libmr.read_depth("street_depth.exr")      # DepthMap: .distance_m (H, W, 1), metres
    scene = libmr.Scene()
    scene.medium.sigma_t_per_m = (libmr.extinction_from_visibility(120.0),) * 3   # 1/m
    layers = libmr.fog(photo, depth.distance_m, scene)
    libmr.write_image("street_fog.jpg", layers.composite)   # atomic; EXIF carried over

Units: metres (positions, distances, heights), 1/m (extinction sigma_t), degrees (angles),
pixels (camera focal length and principal point), scene-linear radiance (images, sky radiance,
sun irradiance, lamp intensity per steradian).

Images are numpy float32 arrays of shape (H, W, C) (depth and mattes (H, W, 1); (H, W) is
accepted as one channel). Arrays libmr returns own libmr's image (no copy; their base is a
capsule) and carry its metadata; passing them back to libmr uses them in place. Any other array
(another dtype is an error, any strides are fine) is copied once into libmr's image layout on
the way in; so is an array passed with an explicit `metadata=`. ColorConfig.convert works in
place on any float32 array with packed pixels.

Errors: every failure raises a subclass of libmr.Error with .code (libmr.ErrorCode) and
.message (one line naming the file or parameter): InvalidArgumentError (also ValueError),
FileError (also OSError), CorruptInputError, SizeMismatchError (also ValueError), ColorError,
InternalError, CancelledError.

Threads: long calls (fog, estimate, transfer_material, image and depth I/O) release the GIL, so
Python threads and Dask workers render in parallel; a CancelToken stops a render from any thread.
The batch on a Dask cluster is libmr.dask (import it explicitly).
"""

from . import _libmr
from ._libmr import *  # noqa: F401,F403  (the C++ API; names listed in __all__)
from ._libmr import __version__  # noqa: F401

__all__ = [name for name in dir(_libmr) if not name.startswith("_")]
