"""Per-frame overhead of the Python call against the C++ call it wraps (issue 15), on a 2 MP frame.

    PYTHONPATH=build/python /usr/bin/python3 python/bench/overhead.py [--runs 5]

For each scene (sky only: the closed form; a sun: the scattering core at the normal preset) and
each kind of input (arrays libmr returned: used in place; plain numpy arrays: copied once),
prints the median wall time of libmr.fog() in Python, the median time inside the C++ mr::fog
call (FogLayers.call_s, measured by the binding around the call), and the median of each run's
overhead (its wall - its call) and its share of the call. The target is an overhead under 5 %
of the render time.
"""

import argparse
import statistics
import time

import numpy as np

import libmr


def scenes():
    sky = libmr.Scene()
    sky.lighting.sky_radiance = (0.8, 0.85, 0.9)
    sun = libmr.Scene()
    sun.medium.layer_top_m = 60.0
    sun.lighting.sun = libmr.Sun(direction_to_sun=libmr.direction_from_azimuth_elevation(30, 25),
                                 irradiance=(4, 4, 4))
    sun.lighting.sky_radiance = (0.5, 0.55, 0.6)
    sun.render.backend = libmr.Backend.cpu
    return {"sky only": sky, "sun (normal)": sun}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    a = ap.parse_args()
    h, w = a.height, a.width
    rng = np.random.default_rng(1)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    numpy_photo = np.stack([xs / w, ys / h, np.full_like(xs, 0.4)], -1) + rng.normal(0, 0.01, (h, w, 3)).astype(np.float32)
    rows = np.maximum(ys - h * 0.3, 0.0)
    numpy_depth = np.where(ys < h * 0.3, np.inf, 2.0 + 400.0 / (1.0 + rows)).astype(np.float32)
    numpy_depth[(xs.astype(int) // 160) % 4 == 1] *= 0.3  # pillars nearer than the ground behind
    libmr_photo = libmr.new_image(h, w, 3)
    libmr_photo[...] = numpy_photo
    libmr_depth = libmr.new_image(h, w, 1)
    libmr_depth[..., 0] = numpy_depth
    print(f"{w}x{h} ({w * h / 1e6:.1f} MP), median of {a.runs}, libmr {libmr.version()}")
    print(f"{'scene':<14} {'inputs':<16} {'python s':>9} {'C++ s':>8} {'overhead s':>11} {'share':>7}")
    for name, scene in scenes().items():
        for kind, photo, depth in (("libmr arrays", libmr_photo, libmr_depth),
                                   ("numpy (copied)", numpy_photo, numpy_depth)):
            walls, calls, extra = [], [], []
            for _ in range(a.runs):
                t0 = time.perf_counter()
                layers = libmr.fog(photo, depth, scene)
                walls.append(time.perf_counter() - t0)
                calls.append(layers.call_s)
                extra.append(walls[-1] - layers.call_s)  # paired: the same run's two clocks
                del layers
            wall, call, over = statistics.median(walls), statistics.median(calls), statistics.median(extra)
            print(f"{name:<14} {kind:<16} {wall:9.3f} {call:8.3f} {over:11.4f} {100 * over / call:6.2f}%")


if __name__ == "__main__":
    main()
