#!/usr/bin/python3
"""Tests of the gallery's artifact measures (gallery/measures.py) on images whose answer is known.

    gallery_measures_test.py [path/to/mr]

Without the mr binary only the numpy cases run; with it, two end-to-end cases fog a synthetic
photo with `mr fog` (sky light only, so the result is Koschmieder's closed form) through a smooth
depth map (must give no created edges, no depth seams, a neutral fog colour for a neutral
airlight) and through a depth map with a step where the photo has no edge (must be flagged).
Exit 0 when every check passes; each failed check prints one line.
"""

import os
import subprocess
import sys
import tempfile

import numpy as np
import OpenImageIO as oiio

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "gallery"))
import measures as M  # noqa: E402

W, H = 256, 192
failures = []


def check(cond, what):
    print(("ok    " if cond else "FAIL  ") + what)
    if not cond:
        failures.append(what)


def srgb_encode(lin):
    lin = np.clip(lin, 0, 1)
    return np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * np.power(lin, 1 / 2.4) - 0.055)


def srgb_decode(v):
    return np.where(v <= 0.04045, v / 12.92, np.power((v + 0.055) / 1.055, 2.4))


def quantize8(v):
    return np.round(np.clip(v, 0, 1) * 255) / 255


def synthetic_photo():
    """sRGB-encoded photo: a smooth vertical gradient (no edges, gradient 0.0016/px) with
    textured boxes on the left half only (x < 120); the right half is flat."""
    y = np.linspace(0, 1, H)[:, None, None]
    img = np.broadcast_to(0.75 - 0.3 * y + np.array([0.0, 0.02, 0.05]), (H, W, 3)).copy()
    yy, xx = np.mgrid[0:H, 0:W]
    for (x0, y0, x1, y1, c) in [(10, 20, 60, 80, (0.2, 0.3, 0.2)), (70, 100, 110, 170, (0.9, 0.6, 0.4)),
                                (20, 120, 50, 180, (0.1, 0.1, 0.15))]:
        box = (xx >= x0) & (xx < x1) & (yy >= y0) & (yy < y1)
        checker = ((xx // 6 + yy // 6) % 2)[..., None] * 0.15
        img[box] = (np.array(c) + checker)[box]
    return quantize8(img)


def koschmieder(photo, depth_m, visibility_m, airlight):
    t = np.exp(-3.912 / visibility_m * depth_m)[..., None]
    lin = srgb_decode(photo) * t + np.asarray(airlight) * (1 - t)
    return quantize8(srgb_encode(lin)), np.broadcast_to(t, photo.shape), np.asarray(airlight) * (1 - t)


def smooth_depth():
    y = np.linspace(0, 1, H)[:, None]
    x = np.linspace(0, 1, W)[None, :]
    return 200.0 - 170.0 * y + 10.0 * x  # 40-210 m, smooth


def numpy_cases():
    photo = synthetic_photo()
    depth = smooth_depth()

    # A clean Koschmieder fog through a smooth depth map softens every edge: nothing created.
    fog, t, ins = koschmieder(photo, depth, 150.0, [0.8, 0.8, 0.8])
    _, edges = M.created_edges(photo, fog)
    check(edges <= 1e-5, f"clean Koschmieder fog: created edges {100 * edges:.4f} % <= 0.001 %")
    off, total, _ = M.depth_seams(depth, photo)
    check(total == 0 and off == 0, f"smooth depth: {total} depth jumps, {off} seams (expect 0, 0)")
    a, level = M.airlight_colour(ins, t)
    check(a is not None and np.allclose(a, 0.8, atol=1e-9) and level == M.AIRLIGHT_MIN_OPACITY,
          f"airlight from inscatter/(1-T) recovers 0.8 grey: {a}")
    check(M.chroma_ab(a) < 1e-6, f"neutral fog colour has C* ~ 0: {M.chroma_ab(a)}")

    # A fake seam: the depth jumps from 30 m to 300 m at x = 180, where the photo is flat.
    seam_depth = np.where(np.arange(W)[None, :] < 180, 30.0, 300.0) * np.ones((H, 1))
    fog, _, _ = koschmieder(photo, seam_depth, 150.0, [0.8, 0.8, 0.8])
    mask, edges = M.created_edges(photo, fog)
    cols = np.nonzero(mask.any(axis=0))[0]
    where = f"columns {cols.min()}-{cols.max()}" if cols.size else "nowhere"
    check(edges >= 2 * H / (W * H) and cols.size and cols.min() >= 176 and cols.max() <= 183,
          f"fake seam flagged: created edges {100 * edges:.3f} % in {where} (expect 176-183)")
    check(edges > M.TARGET_CREATED_EDGES, "fake seam fails the 0.02 % target")
    off, total, seam_map = M.depth_seams(seam_depth, photo)
    check(total == H and off == H and seam_map[:, 179].all(),
          f"fake seam: {off} of {total} depth jumps off image edges (expect {H} of {H})")

    # The same jump along a photo edge is not a seam: a box edge at x = 60 (box 10..60, rows 20..80).
    edge_depth = np.full((H, W), 100.0)
    edge_depth[20:80, 10:60] = 20.0
    off, total, _ = M.depth_seams(edge_depth, photo)
    check(total > 0 and off == 0, f"depth jump on the photo's box edges: {off} of {total} off edges")

    # Sky (+inf) against a surface where the photo has no edge is a seam (a sky cut-out).
    sky_depth = np.full((H, W), 50.0)
    sky_depth[:40, 150:] = np.inf
    off, total, _ = M.depth_seams(sky_depth, photo)
    check(off == total and total == (W - 150) + 40, f"sky cut-out in a flat area: {off} of {total}")

    # An unfogged rectangular window in a flat area: its border is created, its inside is not.
    win_depth = np.full((H, W), 400.0)
    win_depth[60:140, 150:230] = 5.0
    fog, _, _ = koschmieder(photo, win_depth, 150.0, [0.8, 0.8, 0.8])
    mask, edges = M.created_edges(photo, fog)
    check(edges > 0.01 and not mask[80:120, 170:210].any(),
          f"unfogged window: border flagged ({100 * edges:.2f} %), inside clean")

    # New pure white: a clipped blob of known area on a photo with a white patch already.
    photo_w = photo.copy()
    photo_w[0:10, 0:10] = 1.0
    fog = photo_w.copy()
    fog[0:10, 0:10] = 1.0  # was white already: not new
    fog[100:150, 130:170] = 1.0  # 50 x 40 new
    fog[150:160, 130:170] = [1.0, 1.0, 0.9]  # not white in all channels
    _, white = M.new_white(photo_w, fog)
    check(abs(white - 2000 / (W * H)) < 1e-12, f"new white {100 * white:.3f} % == 2000 px")

    # Chroma and its bound.
    check(M.chroma_ab([1, 1, 0.2]) > M.AIRLIGHT_CHROMA_BOUND, "lemon-yellow fog exceeds the chroma bound")
    check(abs(M.daylight_chroma(6504) ) < 0.5, f"D65 daylight has C* ~ 0: {M.daylight_chroma(6504):.2f}")
    check(30 < M.AIRLIGHT_CHROMA_BOUND < 40, f"chroma bound (4000 K daylight) = {M.AIRLIGHT_CHROMA_BOUND:.1f}")
    check(abs(M.chroma_ab([0.2, 0.2, 0.2]) - M.chroma_ab([0.9, 0.9, 0.9])) < 1e-9,
          "chroma does not depend on exposure")


def write(path, px, fmt):
    buf = oiio.ImageBuf(oiio.ImageSpec(px.shape[1], px.shape[0], px.shape[2] if px.ndim == 3 else 1, oiio.FLOAT))
    buf.set_pixels(buf.roi, np.ascontiguousarray(px, dtype=np.float32))
    if not buf.write(path, fmt):
        raise RuntimeError(buf.geterror())


def read(path):
    buf = oiio.ImageBuf(path)
    names = list(buf.spec().channelnames)
    return buf.get_pixels(oiio.FLOAT), names


def mr_cases(mr):
    photo = synthetic_photo()
    with tempfile.TemporaryDirectory(prefix="gallery_measures_") as tmp:
        photo_path = os.path.join(tmp, "synthetic.png")
        write(photo_path, photo, "uint8")
        for case, depth in [("smooth", smooth_depth()),
                            ("seam", np.where(np.arange(W)[None, :] < 180, 30.0, 300.0) * np.ones((H, 1)))]:
            depth_path = os.path.join(tmp, f"depth_{case}.exr")
            write(depth_path, depth[..., None], "float")
            out_dir = os.path.join(tmp, case)
            cmd = [mr, "fog", photo_path, "--depth", depth_path, "--visibility", "150m", "--airlight",
                   "0.8", "--no-shadows", "--aovs", "--out-dir", out_dir, "--format", "png", "-q"]
            p = subprocess.run(cmd, capture_output=True, text=True)
            check(p.returncode == 0, f"mr fog ({case}) ran: {p.stderr.strip()[:200]}")
            if p.returncode != 0:
                continue
            fog, _ = read(os.path.join(out_dir, "synthetic_fog.png"))
            aov, names = read(os.path.join(out_dir, "synthetic_fog_aovs.exr"))
            idx = lambda *c: [names.index(n) for n in c]  # noqa: E731
            t = aov[..., idx("transmittance.R", "transmittance.G", "transmittance.B")]
            ins = aov[..., idx("inscatter.R", "inscatter.G", "inscatter.B")]
            z = aov[..., names.index("depth.Z")]
            check(np.std(fog) > 0.02 and fog.min() >= 0 and fog.max() > 0.3,
                  f"mr output ({case}) is an image, not black/flat: mean {fog.mean():.3f} std {np.std(fog):.3f}")
            _, edges = M.created_edges(photo, fog[..., :3])
            off, total, _ = M.depth_seams(z, photo)
            a, _ = M.airlight_colour(ins, t)
            if case == "smooth":
                check(edges <= M.TARGET_CREATED_EDGES,
                      f"mr Koschmieder through smooth depth: created edges {100 * edges:.4f} % <= 0.02 %")
                check(off == 0, f"mr smooth depth: {off} depth seams")
                check(a is not None and np.allclose(a, 0.8, rtol=0.02),
                      f"mr fog colour = the given neutral airlight 0.8: {a}")
                check(a is not None and M.chroma_ab(a) < 1.0, f"mr fog colour chroma ~ 0: {M.chroma_ab(a)}")
            else:
                check(edges > M.TARGET_CREATED_EDGES,
                      f"mr fog through a depth step off the photo's edges is flagged: {100 * edges:.3f} %")
                check(off == H, f"mr depth step: {off} of {total} jumps off edges (expect {H})")


def main():
    numpy_cases()
    if len(sys.argv) > 1:
        mr_cases(sys.argv[1])
    if failures:
        print(f"{len(failures)} check(s) failed")
        return 1
    print("all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
