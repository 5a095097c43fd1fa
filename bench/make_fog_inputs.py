#!/usr/bin/python3
"""Test inputs for bench/compare_fog.sh: a photo-like JPEG and a float depth EXR of any size.

    make_fog_inputs.py source.jpg out_stem width height

Writes <out_stem>.jpg (the source resized, with sensor-like noise so that the codecs see a
photo's entropy, quality 95, 4:2:0 like a camera) and <out_stem>_depth.exr (float, zip: a
street seen from 1.6 m: ground plane below the horizon, facades 20-200 m above it, sky on top).
"""
import math
import sys

import numpy as np
import OpenImageIO as oiio
from OpenImageIO import ImageBuf, ImageBufAlgo, ImageSpec, ROI

source, stem, width, height = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])

photo = ImageBufAlgo.resize(ImageBuf(source), roi=ROI(0, width, 0, height, 0, 1, 0, 3))
ImageBufAlgo.noise(photo, "gaussian", 0.0, 0.02, mono=False, seed=1)
photo.specmod().attribute("Compression", "jpeg:95")
if not photo.write(stem + ".jpg", "uint8"):
    sys.exit(photo.geterror())

focal = width / (2 * math.tan(math.radians(30)))
y = (np.arange(height, dtype=np.float64) + 0.5 - height / 2) / focal  # below horizon > 0
x = (np.arange(width, dtype=np.float64) + 0.5 - width / 2) / focal
ray_len = np.sqrt(1 + x[None, :] ** 2 + y[:, None] ** 2)
ground = np.where(y[:, None] > 1e-6, 1.6 / np.maximum(y[:, None], 1e-6) * ray_len, np.inf)
facade_z = 20 + 180 * (0.5 + 0.5 * np.sin(x * 7.0)) ** 2  # per column
facade = np.where(y[:, None] >= -(12.0 / facade_z[None, :]), facade_z[None, :] * ray_len, np.inf)
depth = np.minimum(ground, facade).astype(np.float32)
spec = ImageSpec(width, height, 1, "float")
spec.channelnames = ("Z",)
spec.attribute("compression", "zip")
out = oiio.ImageOutput.create(stem + "_depth.exr")
if not out.open(stem + "_depth.exr", spec) or not out.write_image(np.ascontiguousarray(depth[..., None])):
    sys.exit(oiio.geterror())
out.close()
