#!/usr/bin/python3
"""Koschmieder fog the way a data-set builder writes it (issue 12's peer): numpy float32.

    numpy_fog.py photo.jpg depth.exr out.jpg [visibility_m] [airlight]
    numpy_fog.py --folder in_dir out_dir [visibility_m] [airlight]

The folder form fogs every in_dir/NAME.jpg with in_dir/NAME_depth.exr into out_dir/NAME.jpg in
one process, one photo after another (how such a script runs over a data set).

Reads an 8-bit sRGB photo and a float depth map (metres along the ray; inf = sky) with
OpenImageIO's Python bindings, decodes sRGB to linear, applies C = I t + A (1 - t) with
t = exp(-3.912 / V * d), encodes back to sRGB and writes a quality-95 4:4:4 JPEG (what `mr fog`
writes), all in float32 full-frame arrays.
"""
import os
import sys

import numpy as np
import OpenImageIO as oiio


def read(path):
    inp = oiio.ImageInput.open(path)
    if inp is None:
        sys.exit(f"ERROR: {path}: {oiio.geterror()}")
    pixels = inp.read_image(oiio.FLOAT)
    inp.close()
    return pixels




def fog_one(photo_path, depth_path, out_path, visibility_m, airlight):
    photo = read(photo_path)[..., :3]
    depth = read(depth_path)[..., 0]
    linear = np.where(photo <= 0.04045, photo / 12.92, ((photo + 0.055) / 1.055) ** 2.4).astype(np.float32)
    t = np.exp(np.float32(-3.912 / visibility_m) * depth)[..., None]
    fogged = linear * t + airlight * (np.float32(1) - t)
    srgb = np.where(fogged <= 0.0031308, fogged * 12.92, 1.055 * np.power(fogged, np.float32(1 / 2.4)) - 0.055)
    codes = np.clip(srgb * 255 + 0.5, 0, 255).astype(np.uint8)

    spec = oiio.ImageSpec(codes.shape[1], codes.shape[0], 3, "uint8")
    spec.attribute("Compression", "jpeg:95")
    spec.attribute("jpeg:subsampling", "4:4:4")
    out = oiio.ImageOutput.create(out_path)
    if out is None or not out.open(out_path, spec) or not out.write_image(codes):
        sys.exit(f"ERROR: {out_path}: {oiio.geterror()}")
    out.close()


if sys.argv[1] == "--folder":
    in_dir, out_dir = sys.argv[2], sys.argv[3]
    visibility_m = float(sys.argv[4]) if len(sys.argv) > 4 else 150.0
    airlight = np.float32(sys.argv[5] if len(sys.argv) > 5 else 0.8)
    for name in sorted(os.listdir(in_dir)):
        if name.endswith(".jpg"):
            stem = name[:-4]
            fog_one(os.path.join(in_dir, name), os.path.join(in_dir, stem + "_depth.exr"),
                    os.path.join(out_dir, name), visibility_m, airlight)
else:
    visibility_m = float(sys.argv[4]) if len(sys.argv) > 4 else 150.0
    airlight = np.float32(sys.argv[5] if len(sys.argv) > 5 else 0.8)
    fog_one(sys.argv[1], sys.argv[2], sys.argv[3], visibility_m, airlight)
