"""Automatic artifact measures for fogged photos (issue 11), used by scripts/gallery and its test.

All measures compare a photo with its fogged version at the same size. Images are float arrays
(H, W, 3): display-referred ones are sRGB-encoded values in [0, 1] (what a viewer shows), linear
ones are scene-linear Rec.709 (mr's AOVs).

Definitions (the numbers are module constants so the test and the report print the same ones):

created edges      fraction of pixels where the fogged image's gradient magnitude is more than
                   CREATED_EDGE_RATIO (2) times the photo's AND above CREATED_EDGE_FLOOR. The
                   gradient is taken on display luma Y' = 0.2126 R' + 0.7152 G' + 0.0722 B' of
                   the sRGB-encoded values, after a Gaussian blur of EDGE_BLUR_SIGMA_PX (1 px,
                   to ignore sensor noise, JPEG blocks and the renderer's dither), with central
                   differences: |grad| = sqrt(gx^2 + gy^2) in luma per pixel. The floor, 0.01
                   luma/px, is what a step of about 0.025 (6 of 255 codes) gives after the blur
                   (peak of a blurred step h is h / (sqrt(2 pi) sigma) ~ 0.4 h): a just visible
                   step in a smooth area. Fog only softens (C = I T + R with smooth T and R
                   lowers every gradient of a smooth-depth scene), so any such pixel is a seam,
                   a window edge, a streak or a matte edge the photo did not have.
new pure white     fraction of pixels whose three sRGB-encoded channels are all >= WHITE_LEVEL
                   (250/255) in the fogged image but not in the photo.
fog colour chroma  the airlight colour A = inscatter / (1 - transmittance) per channel, from
                   mr's AOVs (scene-linear), median over pixels where the mean of
                   (1 - transmittance) >= AIRLIGHT_MIN_OPACITY (0.5; 0.05 when no pixel reaches
                   that, e.g. haze on a close-up; none when no pixel reaches 0.05). With sky
                   light only (Koschmieder) A is exactly albedo * L_sky, the fog's colour; with
                   sun or lamps it is the average colour of the light the fog scatters. Chroma
                   is CIELAB C*ab of A scaled to luminance Y = 1 (so exposure does not matter:
                   the chroma a white-exposed patch of that fog would have), D65 white, linear
                   Rec.709 -> XYZ (IEC 61966-2-1 matrix).
depth seams        depth discontinuities not on an image edge: pixel pairs (right and down
                   neighbours) whose depths differ by more than DEPTH_JUMP_RELATIVE (10 %) of
                   the nearer one (sky, +inf, against a surface counts as a jump; this is the
                   renderer's own d/10 break rule) and where the photo has no edge within
                   EDGE_SEARCH_RADIUS_PX (2 px): no pixel within that radius with blurred luma
                   gradient >= PHOTO_EDGE_LEVEL (0.02 luma/px, a step of ~0.05). Reported as a
                   count of pairs and as the fraction of all jump pairs.
"""

import math

import numpy as np

CREATED_EDGE_RATIO = 2.0
CREATED_EDGE_FLOOR = 0.01  # luma per pixel, after the blur
EDGE_BLUR_SIGMA_PX = 1.0
WHITE_LEVEL = 250.0 / 255.0
AIRLIGHT_MIN_OPACITY = 0.5
AIRLIGHT_FALLBACK_OPACITY = 0.05
DEPTH_JUMP_RELATIVE = 0.10
PHOTO_EDGE_LEVEL = 0.02
EDGE_SEARCH_RADIUS_PX = 2

# Targets of issue 11 (held-out half).
TARGET_CREATED_EDGES = 0.0002  # fraction of pixels (0.02 %), dense fog and haze
TARGET_NEW_WHITE = 0.02  # fraction of pixels (2 %), sun looks


def luma(img):
    """Display luma Y' of sRGB-encoded RGB (Rec.709 weights on the encoded values)."""
    img = np.asarray(img, dtype=np.float64)
    if img.ndim == 2:
        return img
    return 0.2126 * img[..., 0] + 0.7152 * img[..., 1] + 0.0722 * img[..., 2]


def gaussian_blur(a, sigma):
    """Separable Gaussian blur with edge replication (radius 3 sigma)."""
    if sigma <= 0:
        return a
    r = max(1, int(math.ceil(3 * sigma)))
    x = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    k /= k.sum()
    p = np.pad(a, ((r, r), (0, 0)), mode="edge")
    a = sum(k[i] * p[i:i + a.shape[0], :] for i in range(2 * r + 1))
    p = np.pad(a, ((0, 0), (r, r)), mode="edge")
    return sum(k[i] * p[:, i:i + a.shape[1]] for i in range(2 * r + 1))


def gradient_magnitude(y):
    """Central-difference gradient magnitude (per pixel) of a 2-D array, edges replicated."""
    p = np.pad(y, 1, mode="edge")
    gx = 0.5 * (p[1:-1, 2:] - p[1:-1, :-2])
    gy = 0.5 * (p[2:, 1:-1] - p[:-2, 1:-1])
    return np.hypot(gx, gy)


def edge_strength(display_img):
    return gradient_magnitude(gaussian_blur(luma(display_img), EDGE_BLUR_SIGMA_PX))


def created_edges(photo, fogged):
    """Boolean map and fraction of pixels with an edge the photo does not have."""
    g_in = edge_strength(photo)
    g_out = edge_strength(fogged)
    mask = (g_out > CREATED_EDGE_RATIO * g_in) & (g_out > CREATED_EDGE_FLOOR)
    return mask, float(mask.mean())


def new_white(photo, fogged):
    def white(img):
        img = np.asarray(img)
        if img.ndim == 2:
            return img >= WHITE_LEVEL
        return np.all(img[..., :3] >= WHITE_LEVEL, axis=-1)

    mask = white(fogged) & ~white(photo)
    return mask, float(mask.mean())


_RGB709_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805],
                           [0.2126, 0.7152, 0.0722],
                           [0.0193, 0.1192, 0.9505]])
_D65 = _RGB709_TO_XYZ @ np.ones(3)


def chroma_ab(linear_rgb):
    """CIELAB C*ab of a linear Rec.709 colour scaled to Y = 1 (D65 white); None for black."""
    xyz = _RGB709_TO_XYZ @ np.asarray(linear_rgb, dtype=np.float64)
    if not np.all(np.isfinite(xyz)) or xyz[1] <= 0:
        return None
    xyz = xyz / xyz[1]

    def f(t):
        d = 6.0 / 29.0
        return np.where(t > d ** 3, np.cbrt(t), t / (3 * d * d) + 4.0 / 29.0)

    fx, fy, fz = f(xyz / _D65)
    a = 500.0 * (fx - fy)
    b = 200.0 * (fy - fz)
    return float(math.hypot(a, b))


def airlight_colour(inscatter, transmittance):
    """Median A = inscatter / (1 - T) over pixels where the fog is opaque enough; None if none."""
    opacity = 1.0 - np.asarray(transmittance, dtype=np.float64)
    mean_opacity = opacity.mean(axis=-1)
    for level in (AIRLIGHT_MIN_OPACITY, AIRLIGHT_FALLBACK_OPACITY):
        sel = mean_opacity >= level
        if sel.any():
            with np.errstate(divide="ignore", invalid="ignore"):
                a = np.asarray(inscatter, dtype=np.float64)[sel] / np.maximum(opacity[sel], 1e-6)
            a = a[np.all(np.isfinite(a), axis=-1)]
            if len(a):
                return np.median(a, axis=0), level
    return None, None


def daylight_chroma(cct_k):
    """C*ab (at Y = 1, D65 white) of CIE daylight of a correlated colour temperature (4000-25000 K),
    from the CIE daylight-locus chromaticity formula (CIE 15:2004)."""
    t = float(cct_k)
    if t <= 7000:
        x = -4.6070e9 / t ** 3 + 2.9678e6 / t ** 2 + 0.09911e3 / t + 0.244063
    else:
        x = -2.0064e9 / t ** 3 + 1.9018e6 / t ** 2 + 0.24748e3 / t + 0.237040
    y = -3.000 * x * x + 2.870 * x - 0.275
    xyz = np.array([x / y, 1.0, (1 - x - y) / y])
    rgb = np.linalg.solve(_RGB709_TO_XYZ, xyz)
    return chroma_ab(rgb)


# Bound on the fog colour's chroma. Fog droplets (radius ~1-20 um, much larger than the
# wavelength) scatter all visible wavelengths alike, so fog and thick haze have no colour of their
# own: they take the colour of the light that falls on them (W. E. K. Middleton, "Vision through
# the Atmosphere", 1952; S. G. Narasimhan & S. K. Nayar, "Vision and the Atmosphere", IJCV 48(3),
# 2002, and "Contrast restoration of weather degraded images", PAMI 25(6), 2003, whose dichromatic
# model takes the airlight colour as the illumination colour; single-image dehazing methods such as
# He, Sun & Tang's dark channel prior, CVPR 2009, find the atmospheric light among the brightest,
# near-white pixels). The light outdoors is daylight: the CIE daylight locus (CIE 15:2004), which
# global daylight measurements (Judd, MacAdam & Wyszecki, JOSA 54(8), 1964) span from about
# 4000 K (low sun) to about 10000 K (blue shade, overcast). The bound is the chroma of the farther
# end as seen by a camera white-balanced to D65: max(C*(D40), C*(D100)) = 36.1 (the 4000 K end;
# 10000 K gives 21.1). It is deliberately generous (a sunset can tint fog warm); a lemon-yellow
# (1, 1, 0.2) fog has C* = 65, a slate blue (0.3, 0.35, 0.5) 22: chroma alone does not catch a
# hue off the daylight locus, so the report also prints the fog colour itself.
AIRLIGHT_CHROMA_BOUND = max(daylight_chroma(4000.0), daylight_chroma(10000.0))


def depth_seams(depth_m, photo, jump=DEPTH_JUMP_RELATIVE):
    """Depth discontinuities not on an image edge.

    Returns (count of jump pairs off edges, count of all jump pairs, boolean map of the pixels
    of the off-edge pairs)."""
    d = np.asarray(depth_m, dtype=np.float64)
    d = np.where(np.isfinite(d) & (d > 0), d, np.inf)
    photo_edge = edge_strength(photo) >= PHOTO_EDGE_LEVEL
    # Dilate the edge map by the search radius (square window).
    r = EDGE_SEARCH_RADIUS_PX
    p = np.pad(photo_edge, r, mode="constant")
    near_edge = np.zeros_like(photo_edge)
    for dy in range(2 * r + 1):
        for dx in range(2 * r + 1):
            near_edge |= p[dy:dy + photo_edge.shape[0], dx:dx + photo_edge.shape[1]]

    def jumps(a, b):
        lo = np.minimum(a, b)
        hi = np.maximum(a, b)
        with np.errstate(invalid="ignore"):
            both_inf = np.isinf(lo)
            return ~both_inf & ((hi - lo) > jump * lo)

    jh = jumps(d[:, :-1], d[:, 1:])
    jv = jumps(d[:-1, :], d[1:, :])
    off_h = jh & ~(near_edge[:, :-1] | near_edge[:, 1:])
    off_v = jv & ~(near_edge[:-1, :] | near_edge[1:, :])
    seam = np.zeros(d.shape, dtype=bool)
    seam[:, :-1] |= off_h
    seam[:-1, :] |= off_v
    total = int(jh.sum() + jv.sum())
    off = int(off_h.sum() + off_v.sum())
    return off, total, seam
