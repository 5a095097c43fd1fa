#!/usr/bin/python3
"""Regenerates the depth maps (<stem>_depth.exr) of the bundled sample photos.

Run with Debian's python (it needs python3-numpy and python3-openimageio):

    /usr/bin/python3 sample_photos/make_depth.py            # rewrite every *_depth.exr
    /usr/bin/python3 sample_photos/make_depth.py --check    # read them back, print statistics
    /usr/bin/python3 sample_photos/make_depth.py --check --viz /tmp/depthviz
                                                            # ... and write colour-mapped PNGs

Output format (what libmr's read_depth() with DepthKind::distance expects):
single-channel float32 OpenEXR, channel "Z", same size as the photo, holding the Euclidean
distance in metres from the camera centre along the ray through each pixel centre; 0 means
"no surface" (sky, or unknown disparity in the ground-truth map).

Camera model for every photo: pinhole, principal point at the image centre (cx = W/2,
cy = H/2), focal length f = 0.5 * W / tan(hfov / 2) (for aloe: Middlebury's 3740 px).
Pixel (x, y) covers [x, x+1) x [y, y+1) and its ray passes through its centre, so a planar
depth z becomes the distance d = z * sqrt(((x+0.5-cx)/f)^2 + ((y+0.5-cy)/f)^2 + 1).

aloe: ground truth. aloe_disparity.png is Middlebury 2006 "Aloe" disp1.png (full size,
1282x1110, left view; value = disparity in pixels, 0 = unknown), copied from opencv-doc's
aloeGT.png. z = f * B / (d + doffs) with f = 3740 px, B = 0.160 m, doffs = DOFFS_ALOE.

The other photos have no ground truth: their depth is a hand-built, approximate scene model
(see README.md): a ground plane from a horizon row y_h and a camera height h_c,
z = f * h_c / (y + 0.5 - y_h) for pixel rows below the horizon (the same formula as
DESIGN.md section 4), with vertical planes ("billboards") for facades, walls, trees and
hedges in hand-marked polygons, and sky = 0 from the region no polygon covers above the
horizon plus a colour-based flood fill that carves the sky out of the polygons' edges.
Everything is deterministic: no randomness, no dependence on time or machine.
"""

import argparse
import hashlib
import math
import os
import sys

import numpy as np
import OpenImageIO as oiio

HERE = os.path.dirname(os.path.abspath(__file__))

# --- Middlebury 2006 calibration (stated on vision.middlebury.edu/stereo/data/scenes2006/) ---
FOCAL_FULL_PX = 3740.0      # focal length at full size (1240-1396 px wide)
BASELINE_M = 0.160          # 160 mm between views 1 and 5
# Middlebury 2005/2006 disparities are stored with an offset: depth = f*B / (d + dmin), where
# dmin comes from each scene's dmin.txt (not shipped in opencv-doc). 270 px is the value used
# here for Aloe at full size; see README.md for how it was chosen and why it is uncertain.
DOFFS_ALOE = 270.0


# ----------------------------------------------------------------------------- image I/O

def read_rgb(path):
    """Returns the image as float32 HxWx3 in [0, 1] (the file's encoded, i.e. sRGB, values)."""
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        sys.exit(f"ERROR: {path}: {buf.geterror()}")
    px = buf.get_pixels(oiio.FLOAT)
    if px is None or px.ndim != 3 or px.shape[2] < 3:
        sys.exit(f"ERROR: {path}: expected an RGB image")
    return np.ascontiguousarray(px[:, :, :3], dtype=np.float32)


def read_gray_u8(path):
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        sys.exit(f"ERROR: {path}: {buf.geterror()}")
    px = buf.get_pixels(oiio.UINT8)
    if px is None or px.ndim != 3 or px.shape[2] != 1:
        sys.exit(f"ERROR: {path}: expected a single-channel 8-bit image")
    return px[:, :, 0].astype(np.float64)


def round_mantissa(values, drop_bits=10):
    """Rounds positive float32 values to 23 - drop_bits stored mantissa bits (to nearest).

    With drop_bits = 10 the relative change is at most 2**-14 = 6.1e-5 (1 cm at 160 m), far
    below the accuracy of an approximate scene model, and ZIP compresses the result ~4x better.
    """
    u = np.ascontiguousarray(values, dtype=np.float32).view(np.uint32)
    half = np.uint32(1 << (drop_bits - 1))
    mask = np.uint32((0xFFFFFFFF << drop_bits) & 0xFFFFFFFF)
    return ((u + half) & mask).view(np.float32)


def write_depth(path, dist, attrs, compression):
    """Writes a float32 single-channel EXR with channel "Z", atomically (temp file + rename)."""
    h, w = dist.shape
    spec = oiio.ImageSpec(w, h, 1, oiio.FLOAT)
    spec.channelnames = ("Z",)
    spec.attribute("compression", compression)
    # OIIO stamps the current time into DateTime unless it is set; an empty value keeps the
    # files byte-for-byte reproducible.
    spec.attribute("DateTime", "")
    for key, value in attrs.items():
        spec.attribute(key, value)
    tmp = path + ".tmp.exr"
    out = oiio.ImageOutput.create(tmp)
    if out is None:
        sys.exit(f"ERROR: {path}: cannot create an EXR writer: {oiio.geterror()}")
    if not out.open(tmp, spec):
        sys.exit(f"ERROR: {path}: cannot open for writing: {out.geterror()}")
    if not out.write_image(np.ascontiguousarray(dist[:, :, None], dtype=np.float32)):
        sys.exit(f"ERROR: {path}: write failed: {out.geterror()}")
    out.close()
    os.replace(tmp, path)


def write_png(path, rgb):
    h, w = rgb.shape[:2]
    out = oiio.ImageOutput.create(path)
    out.open(path, oiio.ImageSpec(w, h, 3, oiio.UINT8))
    out.write_image(np.ascontiguousarray(np.clip(rgb, 0, 1), dtype=np.float32))
    out.close()


# ----------------------------------------------------------------------------- camera

class Camera:
    """Pinhole camera, principal point at the image centre, y down, looking down +z."""

    def __init__(self, width, height, focal_px):
        self.w, self.h, self.f = width, height, float(focal_px)
        self.cx, self.cy = width / 2.0, height / 2.0
        xs = (np.arange(width) + 0.5 - self.cx) / self.f
        ys = (np.arange(height) + 0.5 - self.cy) / self.f
        self.ux, self.uy = np.meshgrid(xs, ys)          # ray through pixel centre: (ux, uy, 1)
        self.ray_len = np.sqrt(self.ux ** 2 + self.uy ** 2 + 1.0)

    @staticmethod
    def from_hfov(width, height, hfov_deg):
        return Camera(width, height, 0.5 * width / math.tan(math.radians(hfov_deg) / 2))

    def hfov_deg(self):
        return math.degrees(2 * math.atan(0.5 * self.w / self.f))

    def point(self, x, y, z):
        """3D point at planar depth z seen through continuous pixel position (x, y)."""
        return np.array([(x - self.cx) / self.f * z, (y - self.cy) / self.f * z, z])


class Ground:
    """The ground plane of DESIGN.md section 4: z = f * h_c / (y - y_h), y = row + 0.5.

    In camera coordinates that is the plane n . P = h_c with n = (0, 1, (cy - y_h) / f):
    a level camera at height h_c whose horizon is row y_h (equivalently, a camera pitched by
    atan((cy - y_h) / f)). 'Up' is -n / |n|; vertical structures are planes containing it.
    """

    def __init__(self, cam, y_h, h_c):
        self.cam, self.y_h, self.h_c = cam, float(y_h), float(h_c)
        self.n = np.array([0.0, 1.0, (cam.cy - self.y_h) / cam.f])

    def z_at_row(self, y):
        """Planar depth of the ground at continuous row y (must be below the horizon)."""
        if y <= self.y_h:
            raise ValueError(f"row {y} is not below the horizon {self.y_h}")
        return self.cam.f * self.h_c / (y - self.y_h)

    def z_map(self):
        ys = self.cam.uy * self.cam.f + self.cam.cy        # continuous row of each pixel centre
        with np.errstate(divide="ignore", invalid="ignore"):
            z = self.cam.f * self.h_c / (ys - self.y_h)
        z[ys <= self.y_h] = np.nan
        return z

    def point(self, x, y):
        return self.cam.point(x, y, self.z_at_row(y))


def plane_z(cam, normal, p0):
    """Planar depth where each pixel's ray meets the plane normal . P = normal . p0."""
    denom = normal[0] * cam.ux + normal[1] * cam.uy + normal[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = float(np.dot(normal, p0)) / denom
    z[~np.isfinite(z) | (z <= 0)] = np.nan
    return z


def vertical_plane_through(ground, p_a, p_b):
    """Vertical plane (containing 'up') through two 3D points."""
    normal = np.cross(p_b - p_a, ground.n)
    return normal / np.linalg.norm(normal), p_a


# ----------------------------------------------------------------------------- polygons

def polygon_mask(w, h, verts):
    """Even-odd rule rasterisation of a polygon (pixel-centre sampling)."""
    xs = np.arange(w) + 0.5
    ys = np.arange(h) + 0.5
    px, py = np.meshgrid(xs, ys)
    inside = np.zeros((h, w), dtype=bool)
    n = len(verts)
    for i in range(n):
        x1, y1 = verts[i]
        x2, y2 = verts[(i + 1) % n]
        if y1 == y2:
            continue
        crosses = (py >= min(y1, y2)) & (py < max(y1, y2))
        xint = x1 + (py - y1) * (x2 - x1) / (y2 - y1)
        inside ^= crosses & (px < xint)
    return inside


def flood(seed, passable):
    """4-connected flood fill of `passable` pixels starting from `seed` (numpy only)."""
    region = seed & passable
    while True:
        before = region
        for _ in range(16):                      # several dilation steps per convergence test
            grown = region.copy()
            grown[1:, :] |= region[:-1, :]
            grown[:-1, :] |= region[1:, :]
            grown[:, 1:] |= region[:, :-1]
            grown[:, :-1] |= region[:, 1:]
            region = grown & passable
        if np.array_equal(region, before):
            return region


def fill_nearest(depth, holes):
    """Gives each hole pixel the value of a nearby non-hole pixel (iterative dilation)."""
    depth = depth.copy()
    holes = holes.copy()
    h, w = depth.shape
    for _ in range(max(h, w)):
        if not holes.any():
            break
        for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            src = np.roll(np.roll(depth, dy, axis=0), dx, axis=1)
            src_ok = ~np.roll(np.roll(holes, dy, axis=0), dx, axis=1)
            # np.roll wraps around: forbid taking values across the image border
            if dy == 1:
                src_ok[0, :] = False
            if dy == -1:
                src_ok[-1, :] = False
            if dx == 1:
                src_ok[:, 0] = False
            if dx == -1:
                src_ok[:, -1] = False
            take = holes & src_ok
            depth[take] = src[take]
            holes &= ~take
    return depth


# ----------------------------------------------------------------------------- scene models

def sky_overcast(rgb):
    """Bright, nearly grey pixels (overcast sky)."""
    mx = rgb.max(axis=2)
    mn = rgb.min(axis=2)
    sat = (mx - mn) / np.maximum(mx, 1e-6)
    return (mx > 0.55) & (sat < 0.16)


def sky_blue(rgb):
    """Bright pixels clearly bluer than red (clear or hazy blue sky)."""
    r, g, b = rgb[:, :, 0], rgb[:, :, 1], rgb[:, :, 2]
    return (b > 0.55) & (b > r + 0.07) & (b >= g)


# Layer kinds (painted in list order, so list far things first and near things last):
#   ("base", (x1, y1), (x2, y2))   vertical plane standing on the ground along the image line
#                                  from (x1, y1) to (x2, y2) (both below the horizon)
#   ("vp", x_vp, (xa, ya))         vertical plane whose horizontal lines vanish at (x_vp, y_h)
#                                  and that meets the ground at pixel (xa, ya)
#   ("z", z)                       fronto-parallel billboard at planar depth z metres
#   ("row", y)                     fronto-parallel billboard standing on the ground at row y
# Every layer has a polygon (image coordinates, pixel corners at integers) and `carve`:
# True: sky-coloured pixels of the polygon connected to the open sky become sky;
# "all": every sky-coloured pixel of the polygon becomes sky (foliage against the sky);
# False: the polygon is solid.

SCENES = {
    # Grand Beguinage, Leuven: cobbled street, brick houses, gate pillars. 751x563.
    # hfov 60 deg matches OpenCV's own calibration of this photo (fx = 651.4 px in
    # samples/data/essential_mat_data.txt). Horizon: the street's vanishing point and the base
    # of the far houses (~65 m away at row 378); camera at eye height.
    "leuven": dict(
        source="leuvenA.jpg", hfov=60.0, horizon=362.0, cam_height=1.6, ground_max=70.0,
        sky=sky_overcast,
        layers=[
            # far end of the street (houses ~65 m away)
            dict(name="street end", kind=("row", 378.0), carve=True,
                 poly=[(211, 190), (272, 190), (272, 380), (211, 380)]),
            # fachwerk house, white house and the wall in front of them (~31 m)
            dict(name="centre houses", kind=("row", 395.0), carve=True,
                 poly=[(256, 245), (300, 200), (364, 150), (412, 160), (412, 196),
                       (492, 196), (492, 397), (256, 397)]),
            # big brick house on the right, behind the garden (~32 m)
            dict(name="right house", kind=("z", 32.0), carve=True,
                 poly=[(484, 50), (751, 50), (751, 374), (484, 374)]),
            # garden wall bordering the lawn (~27 m)
            dict(name="garden wall", kind=("row", 401.0), carve=False,
                 poly=[(456, 360), (751, 360), (751, 401), (456, 401)]),
            # tree at the right edge
            dict(name="tree", kind=("z", 22.0), carve=True,
                 poly=[(726, 15), (751, 15), (751, 250), (726, 250)]),
            # houses along the left side of the street, one plane along their base line
            dict(name="left houses", kind=("base", (0.0, 452.0), (213.0, 403.0)), carve=True,
                 poly=[(0, 0), (142, 0), (230, 160), (230, 402), (213, 404), (0, 454)]),
            # low wall beside the left pillar (~15 m)
            dict(name="low wall", kind=("row", 432.0), carve=False,
                 poly=[(420, 376), (478, 376), (478, 437), (420, 437)]),
            # gate pillar, left (~12 m)
            dict(name="pillar 1", kind=("row", 446.0), carve=False,
                 poly=[(492, 287), (505, 287), (512, 299), (512, 324), (523, 327),
                       (523, 448), (476, 448), (476, 327), (487, 324), (487, 299)]),
            # gate pillar, right, on the end of the front wall (~8 m)
            dict(name="pillar 2", kind=("row", 496.0), carve=False,
                 poly=[(557, 261), (574, 261), (588, 279), (588, 311), (602, 313),
                       (606, 330), (606, 498), (539, 498), (539, 330), (541, 313),
                       (549, 311), (549, 279)]),
            # curved wall in the right foreground, approximated by one plane (6-8 m)
            dict(name="front wall", kind=("base", (545.0, 496.0), (751.0, 540.0)), carve=False,
                 poly=[(542, 396), (600, 398), (751, 410), (751, 548), (542, 499)]),
        ]),

    # Modernist hotel facade behind a lawn, trees and a blue sky on the left. 868x600.
    # The facade's floor lines vanish at x ~ -335 (fit to the slab shadows); the floor spacing
    # (66 px at x=250 .. 131 px at x=820) and the building's base at row 532 agree with 3 m
    # storeys when the camera is low (0.3 m above the lawn, the blurred grass at the bottom is
    # a few metres away). hfov 50 deg is assumed (no EXIF).
    "building": dict(
        source="building.jpg", hfov=50.0, horizon=520.0, cam_height=0.3, ground_max=40.0,
        sky=sky_blue,
        layers=[
            # distant tree line and water tower on the horizon, left of the building
            dict(name="far horizon", kind=("z", 700.0), carve=True,
                 poly=[(0, 290), (270, 290), (270, 522), (0, 522)]),
            # the facade: vertical plane vanishing at x=-335, meeting the ground at (720, 532)
            dict(name="facade", kind=("vp", -335.0, (720.0, 532.0)), carve=True,
                 poly=[(144, 126), (300, 0), (868, 0), (868, 547), (144, 527)]),
            # trees left of the building (~45 m)
            dict(name="trees", kind=("z", 45.0), carve=True,
                 poly=[(0, 175), (58, 175), (58, 300), (45, 345), (30, 372), (70, 372),
                       (100, 360), (140, 354), (200, 356), (232, 380), (262, 410),
                       (262, 505), (0, 505)]),
            # hedge, car and road sign on the left (~36 m)
            dict(name="hedge left", kind=("z", 36.0), carve=False,
                 poly=[(0, 468), (200, 468), (200, 528), (0, 528)]),
            # hedge in front of the building's left wing (~28 m)
            dict(name="hedge right", kind=("z", 28.0), carve=False,
                 poly=[(188, 486), (386, 486), (386, 537), (188, 537)]),
            # overhanging conifer branches at the top left (~12 m)
            dict(name="branches", kind=("z", 12.0), carve="all",
                 poly=[(0, 0), (262, 0), (262, 40), (150, 125), (95, 215), (0, 215)]),
        ]),

    # Oblique aerial view of a coastal town (sea at the top). 640x480.
    # No sky: the horizon lies above the frame. Its row comes from the divided highway,
    # whose image width (50 px at row 450, 38 at row 300, 30 at row 230) shrinks linearly to 0
    # at row ~ -130; at ~700 m altitude the road is then ~60 m wide including verges.
    "aerial": dict(
        source="aero3.jpg", hfov=50.0, horizon=-130.0, cam_height=700.0, ground_max=None,
        sky=None, layers=[]),
}


def approximate_depth(name, scene, rgb):
    h, w = rgb.shape[:2]
    cam = Camera.from_hfov(w, h, scene["hfov"])
    ground = Ground(cam, scene["horizon"], scene["cam_height"])
    z = ground.z_map()
    if scene["ground_max"] is not None:
        z = np.minimum(z, scene["ground_max"])

    covered = np.zeros((h, w), dtype=bool)
    carvable = np.zeros((h, w), dtype=bool)
    carve_all = np.zeros((h, w), dtype=bool)
    for layer in scene["layers"]:
        mask = polygon_mask(w, h, layer["poly"])
        kind = layer["kind"]
        if kind[0] == "z":
            lz = np.full((h, w), float(kind[1]))
        elif kind[0] == "row":
            lz = np.full((h, w), ground.z_at_row(kind[1]))
        elif kind[0] == "base":
            normal, p0 = vertical_plane_through(ground, ground.point(*kind[1]),
                                                ground.point(*kind[2]))
            lz = plane_z(cam, normal, p0)
        elif kind[0] == "vp":
            x_vp, anchor = kind[1], kind[2]
            direction = np.array([(x_vp - cam.cx) / cam.f, (ground.y_h - cam.cy) / cam.f, 1.0])
            normal = np.cross(direction, ground.n)
            normal /= np.linalg.norm(normal)
            lz = plane_z(cam, normal, ground.point(*anchor))
        else:
            raise ValueError(f"{name}: unknown layer kind {kind[0]}")
        ok = mask & np.isfinite(lz)
        z[ok] = lz[ok]
        covered |= mask
        carvable = np.where(mask, bool(layer["carve"]), carvable)
        carve_all = np.where(mask, layer["carve"] == "all", carve_all)

    rows = cam.uy * cam.f + cam.cy
    above = rows <= ground.y_h
    sky = above & ~covered                                   # open sky: nothing marked there
    if scene["sky"] is not None and sky.any():
        sky_colour = scene["sky"](rgb)
        passable = sky_colour & (sky | (covered & carvable))
        sky = sky | flood(sky, passable) | (above & carve_all & sky_colour)
    holes = ~sky & ~np.isfinite(z)
    n_holes = int(holes.sum())
    if n_holes:
        z = fill_nearest(np.where(np.isfinite(z), z, 0.0), holes)
    dist = z * cam.ray_len
    dist[sky] = 0.0
    return dist.astype(np.float32), cam, n_holes


def aloe_depth(disp):
    h, w = disp.shape
    f = FOCAL_FULL_PX * w / 1282.0          # aloe full size is 1282 px wide: f = 3740 px
    cam = Camera(w, h, f)
    valid = disp > 0
    z = np.zeros_like(disp)
    z[valid] = f * BASELINE_M / (disp[valid] + DOFFS_ALOE)
    dist = z * cam.ray_len
    dist[~valid] = 0.0
    return fill_occlusions(dist, valid).astype(np.float32), cam


def fill_occlusions(dist, valid):
    """Unknown ground-truth disparity is (almost always) background seen by one camera only:
    each run of unknown pixels in a row takes the FARTHER of its two valid neighbours in that
    row (the standard stereo occlusion fill), so the depth map has no holes that fog would
    turn into sky."""
    out = dist.copy()
    h, w = dist.shape
    for y in range(h):
        row_valid = valid[y]
        x = 0
        while x < w:
            if row_valid[x]:
                x += 1
                continue
            start = x
            while x < w and not row_valid[x]:
                x += 1
            left = dist[y, start - 1] if start > 0 else 0.0
            right = dist[y, x] if x < w else 0.0
            out[y, start:x] = max(left, right)
    return out


# ----------------------------------------------------------------------------- main

def photo_path(stem):
    return os.path.join(HERE, stem + ".jpg")


def depth_path(stem):
    return os.path.join(HERE, stem + "_depth.exr")


def generate():
    common = {"Software": "libmr sample_photos/make_depth.py"}
    disp = read_gray_u8(os.path.join(HERE, "aloe_disparity.png"))
    photo = read_rgb(photo_path("aloe"))
    if disp.shape != photo.shape[:2]:
        sys.exit("ERROR: aloe_disparity.png and aloe.jpg differ in size")
    dist, cam = aloe_depth(disp)
    write_depth(depth_path("aloe"), dist, dict(common, **{
        "ImageDescription": "distance along the ray in metres, 0 = unknown; Middlebury 2006 "
                            "Aloe ground truth, z = f*B/(d+doffs)",
        "mr:focal_px": float(cam.f), "mr:baseline_m": BASELINE_M, "mr:doffs_px": DOFFS_ALOE}),
        compression="piz")     # exact float32 values (no rounding), for loader tests
    print(f"aloe: f = {cam.f:.1f} px (hfov {cam.hfov_deg():.2f} deg), B = {BASELINE_M} m, "
          f"doffs = {DOFFS_ALOE} px")

    for stem, scene in SCENES.items():
        rgb = read_rgb(photo_path(stem))
        dist, cam, n_holes = approximate_depth(stem, scene, rgb)
        write_depth(depth_path(stem), round_mantissa(dist), dict(common, **{
            "ImageDescription": "distance along the ray in metres, 0 = sky; APPROXIMATE "
                                "hand-built scene model (see sample_photos/README.md)",
            "mr:hfov_deg": float(scene["hfov"]), "mr:horizon_row": float(scene["horizon"]),
            "mr:camera_height_m": float(scene["cam_height"])}), compression="zip")
        print(f"{stem}: f = {cam.f:.1f} px (hfov {scene['hfov']} deg), horizon row "
              f"{scene['horizon']}, camera height {scene['cam_height']} m, "
              f"{n_holes} pixels filled from neighbours")


def colormap(t):
    """Perceptual-ish colour ramp for t in [0, 1] (near = yellow, far = dark purple)."""
    stops = np.array([[0.99, 0.91, 0.14], [0.95, 0.55, 0.20], [0.80, 0.28, 0.38],
                      [0.50, 0.12, 0.50], [0.18, 0.05, 0.35]])
    t = np.clip(t, 0, 1) * (len(stops) - 1)
    i = np.minimum(t.astype(int), len(stops) - 2)
    frac = (t - i)[..., None]
    return stops[i] * (1 - frac) + stops[i + 1] * frac


def check(viz_dir):
    stems = ["aloe"] + list(SCENES)
    ok = True
    for stem in stems:
        buf = oiio.ImageBuf(depth_path(stem))
        spec = buf.spec()
        photo = oiio.ImageBuf(photo_path(stem)).spec()
        d = buf.get_pixels(oiio.FLOAT)[:, :, 0]
        same = (spec.width, spec.height) == (photo.width, photo.height)
        fmt_ok = spec.nchannels == 1 and list(spec.channelnames) == ["Z"] and \
            spec.format == oiio.TypeDesc(oiio.FLOAT)
        surf = d > 0
        finite = bool(np.isfinite(d).all())
        ok &= same and fmt_ok and finite and not (d < 0).any()
        sha = hashlib.sha256(open(depth_path(stem), "rb").read()).hexdigest()[:16]
        print(f"{stem:9s} {spec.width}x{spec.height} size {'ok' if same else 'MISMATCH'} "
              f"format {'ok' if fmt_ok else 'BAD'}  min {d[surf].min():8.2f} m  "
              f"max {d[surf].max():8.2f} m  median {np.median(d[surf]):8.2f} m  "
              f"no-surface {100.0 * (~surf).mean():5.2f} %  sha256 {sha}")
        if viz_dir:
            os.makedirs(viz_dir, exist_ok=True)
            lo, hi = np.log(d[surf].min()), np.log(d[surf].max())
            t = (np.log(np.where(surf, d, 1.0)) - lo) / max(hi - lo, 1e-6)
            rgb = colormap(t)
            rgb[~surf] = (0.45, 0.75, 1.0) if stem != "aloe" else (0.0, 0.0, 0.0)
            photo_rgb = read_rgb(photo_path(stem))
            write_png(os.path.join(viz_dir, f"{stem}_depth.png"),
                      np.concatenate([photo_rgb, rgb], axis=1))
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--check", action="store_true",
                    help="read the EXRs back and print statistics instead of writing them")
    ap.add_argument("--viz", metavar="DIR",
                    help="with --check: write photo | colour-mapped depth PNGs into DIR")
    args = ap.parse_args()
    if args.check:
        sys.exit(0 if check(args.viz) else 1)
    generate()


if __name__ == "__main__":
    main()
