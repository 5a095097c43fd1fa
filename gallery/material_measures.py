"""Measures of a material transfer on a real photo (issue 11 item 6), used by
scripts/gallery_material and its test.

Images are float arrays (H, W, 3) of scene-linear Rec.709 values (decode sRGB files with
srgb_to_linear first); `labels` is an int array (H, W), 0 = not a region. The definitions are the
C++ acceptance tests' (tests/material_transfer_test.cpp, MaterialRealPhoto.*), so the gallery and
the synthetic tests judge by the same numbers:

speckle      a pixel within SPECKLE_BAND_PX (2) of a label change (a 5 x 5 window holding another
             label, 0 included; next to a region) is a speck or part of a 1-pixel line when, in
             the result, its log RGB lies beyond both of its neighbours along one of the 2 axes
             (horizontal, vertical) by more than SPECKLE_JUMP (0.3, a
             35 % jump) in some channel, while in the photo it lies beyond them by less than
             SPECKLE_PHOTO_CALM (0.1). A pixel on a step between two colours lies between its
             neighbours in every direction, so a region's border on a weak edge of the photo (the
             new material beside an untouched object) is not counted; a dark or bright rim, a
             sliver of the old material or a tooth of a ragged border is. Log values of
             value + SPECKLE_NOISE_FLOOR (0.003, the texture's floor below: sRGB code 10 of
             255), as for texture: a step of a code or two near black (code 1 to 3 is a factor
             of 3) is the 8-bit coding's and invisible, not a speck (since 2026-12-07, third
             session; before, gallery/tune after_the_rain's 47 band pixels at codes 1-4 counted
             0.67 %). Reported as the fraction of those band pixels; bar TARGET_SPECKLE (0.5 %).
median speckle the C++ test's definition (MaterialRealPhoto.NoSpeckleAlongRegionEdgesAndThinGaps:
             log RGB more than 0.3 from the median of the 3 x 3 neighbourhood, less than 0.1 in
             the photo), here with the same noise floor (the synthetic test has no noise and no
             floor), in the same band. It also counts step pixels where a ragged border's corner
             makes the 3 x 3 median the other side's. Reported, no bar.
texture      per region, over its pixels at least TEXTURE_INSET_PX (6) from its border: the
             correlation of the high-pass of log(luminance + TEXTURE_NOISE_FLOOR) (value - 7 x 7
             box mean) between the photo and the result (bar >= TARGET_TEXTURE_CORRELATION, 0.9), and the ratio of their
             standard deviations (the result's over the photo's; bar > TARGET_CONTRAST_RATIO, 0.5:
             not flattened). Regions with fewer than 500 such pixels are skipped. The floor,
             0.003 (linear, white = 1: sRGB code 10 of 255), is the 8-bit photo's coding noise
             (one code is 10 % of the value there, JPEG blocks more): without it a near-black
             region's "texture" is its JPEG blocks and noise, and a result that shows them (as
             grain) scores better than a clean one. The synthetic C++ tests have no floor (no
             noise). Applied to photo and result alike.
clipped      the share of region pixels with a channel at the 8-bit code 255 in the result where
             the photo has none there (display-referred images, values in [0, 1]): a light
             material on a brightly lit surface blown flat. Reported, no bar (`mr material` writes
             its changed pixels through the highlight roll-off, which reaches 255 only far above
             white).
blockiness   per region (eroded by 2 px; at least 500 neighbour pairs within the blocks and 62
             across their borders), the mean |step| of display luma
             between neighbours across the 8 x 8 JPEG block grid (x or y = 8k - 1 to 8k) over the
             mean |step| elsewhere, in the result over the same in the photo; reported as the
             largest over the regions, no bar. 1: the blocks no plainer than in the photo; a dark
             region given a light material magnifies its blocks (anne_helene's black shirt made
             white: 1.30 before 2026-12-07, 1.11 after).
gaps left    the share of the unlabelled pixels enclosed between region pixels (the same region or
             two) at most GAP_SPAN_PX (16) apart along a row or a column, sky excluded, that the
             result leaves within 2 codes of the photo in every channel (display-referred): a
             line of the old material between new ones, where two regions were painted on either
             side of a soft border and its blend left out. Reported, no bar (a thin object of
             its own between regions, a pole or a seam, is right to stay).
colour change the mean CIELAB Delta E*ab (D65, both images scaled by the same exposure, the photo's
             99th percentile luminance to 1) between photo and result over the regions: shows that
             the transfer changed something (a result equal to the photo passes the other two).
"""

import numpy as np

SPECKLE_BAND_PX = 2
SPECKLE_JUMP = 0.3
SPECKLE_PHOTO_CALM = 0.1
TEXTURE_INSET_PX = 6
TEXTURE_WINDOW_PX = 7
TEXTURE_MIN_PIXELS = 500
TEXTURE_NOISE_FLOOR = 0.003
SPECKLE_NOISE_FLOOR = TEXTURE_NOISE_FLOOR

GAP_SPAN_PX = 16
TARGET_SPECKLE = 0.005
TARGET_TEXTURE_CORRELATION = 0.9
TARGET_CONTRAST_RATIO = 0.5


def srgb_to_linear(v):
    v = np.asarray(v, np.float32)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _shifts(a, r):
    """The (2r+1)^2 shifted copies of a 2-D array, edges replicated."""
    h, w = a.shape
    p = np.pad(a, r, mode="edge")
    return [p[r + dy:r + dy + h, r + dx:r + dx + w] for dy in range(-r, r + 1) for dx in range(-r, r + 1)]


def _median3_deviation(img):
    """Per pixel, the largest over channels of |log v - median of the 3 x 3 log values|."""
    worst = np.zeros(img.shape[:2], np.float32)
    for c in range(3):
        lg = np.log(np.maximum(img[..., c], 0) + SPECKLE_NOISE_FLOOR).astype(np.float32)
        med = np.median(np.stack(_shifts(lg, 1)), axis=0)
        worst = np.maximum(worst, np.abs(lg - med))
    return worst


def label_band(labels, radius=SPECKLE_BAND_PX):
    """Pixels whose (2 radius + 1)^2 window holds a label other than their own."""
    band = np.zeros(labels.shape, bool)
    for s in _shifts(labels, radius):
        band |= s != labels
    return band


def _extremum(img):
    """Per pixel, the largest over channels and the 2 axes of how far its log value lies beyond
    both neighbours along the axis (0 when it lies between them). Not the diagonals: a pixel at
    the corner of two steps (a region's border meeting a texture's edge) lies beyond both of its
    diagonal neighbours without being a speck. A 1-pixel line at any angle is still found (its
    pixels have both neighbours off the line along at least one axis)."""
    worst = np.zeros(img.shape[:2], np.float32)
    h, w = img.shape[:2]
    for c in range(3):
        lg = np.pad(np.log(np.maximum(img[..., c], 0) + SPECKLE_NOISE_FLOOR).astype(np.float32), 1,
                    mode="edge")
        v = lg[1:h + 1, 1:w + 1]
        for dy, dx in ((0, 1), (1, 0)):
            a = lg[1 + dy:h + 1 + dy, 1 + dx:w + 1 + dx]
            b = lg[1 - dy:h + 1 - dy, 1 - dx:w + 1 - dx]
            peak = np.minimum(v - a, v - b)
            trough = np.minimum(a - v, b - v)
            worst = np.maximum(worst, np.maximum(peak, trough))
    return worst


def edge_band(labels):
    """Pixels within SPECKLE_BAND_PX of a label change and of a region."""
    band = label_band(labels)
    # Only band pixels next to a region matter (two unlabelled areas meeting are not a seam).
    near_region = np.zeros(labels.shape, bool)
    for s in _shifts(labels, SPECKLE_BAND_PX):
        near_region |= s > 0
    return band & near_region


def speckle(photo, result, labels):
    """(fraction of band pixels that are specks or lines, band pixel count, speckle mask)."""
    band = edge_band(labels)
    spk = band & (_extremum(result) > SPECKLE_JUMP) & (_extremum(photo) < SPECKLE_PHOTO_CALM)
    n = int(band.sum())
    return (float(spk.sum()) / n if n else 0.0), n, spk


def median_speckle(photo, result, labels):
    """The C++ test's definition in the same band: (fraction, band pixel count)."""
    band = edge_band(labels)
    spk = band & (_median3_deviation(result) > SPECKLE_JUMP) & (_median3_deviation(photo) < SPECKLE_PHOTO_CALM)
    n = int(band.sum())
    return (float(spk.sum()) / n if n else 0.0), n


def _box_mean(a, r):
    """Mean over a (2r+1)^2 window (edges replicated), via an integral image."""
    h, w = a.shape
    p = np.pad(a.astype(np.float64), r, mode="edge")
    s = np.zeros((p.shape[0] + 1, p.shape[1] + 1))
    s[1:, 1:] = p.cumsum(0).cumsum(1)
    k = 2 * r + 1
    return ((s[k:k + h, k:k + w] - s[:h, k:k + w] - s[k:k + h, :w] + s[:h, :w]) / (k * k)).astype(np.float32)


def luminance(img):
    return 0.2126 * img[..., 0] + 0.7152 * img[..., 1] + 0.0722 * img[..., 2]


def high_pass(img, floor=TEXTURE_NOISE_FLOOR):
    lg = np.log(np.maximum(luminance(img), 0) + max(floor, 1e-6)).astype(np.float32)
    return lg - _box_mean(lg, TEXTURE_WINDOW_PX // 2)


def inset(mask, r=TEXTURE_INSET_PX):
    """mask eroded by a (2r+1)^2 square (pixels at least r from its border)."""
    out = mask.copy()
    for s in _shifts(mask, r):
        out &= s
    return out


def texture(photo, result, labels):
    """Per region id: (pixel count, correlation, contrast ratio) of the log-luminance high-pass."""
    hp_photo, hp_result = high_pass(photo), high_pass(result)
    out = {}
    for k in np.unique(labels):
        if k <= 0:
            continue
        m = inset(labels == k)
        n = int(m.sum())
        if n < TEXTURE_MIN_PIXELS:
            continue
        a = hp_photo[m].astype(np.float64)
        b = hp_result[m].astype(np.float64)
        a -= a.mean()
        b -= b.mean()
        va, vb = float((a * a).sum()), float((b * b).sum())
        corr = float((a * b).sum() / np.sqrt(va * vb)) if va > 0 and vb > 0 else 0.0
        ratio = float(np.sqrt(vb / va)) if va > 0 else 0.0
        out[int(k)] = (n, corr, ratio)
    return out


def _lab(linear):
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = linear.reshape(-1, 3).astype(np.float64) @ m.T / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(np.maximum(xyz, 0)), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    lab = np.stack([116 * f[:, 1] - 16, 500 * (f[:, 0] - f[:, 1]), 200 * (f[:, 1] - f[:, 2])], 1)
    return lab.reshape(linear.shape)


def clipped(photo_display, result_display, labels):
    """Share of the region pixels clipped (a channel at code 255) in the result and not in the photo."""
    m = labels > 0
    if not m.any():
        return 0.0
    full = 254.5 / 255

    def at_255(img):
        return np.any(np.asarray(img)[..., :3] >= full, axis=-1)

    return float((at_255(result_display) & ~at_255(photo_display) & m).sum() / m.sum())


def _block_ratio(luma, mask):
    dh = np.abs(np.diff(luma, axis=1))
    dv = np.abs(np.diff(luma, axis=0))
    mh = mask[:, 1:] & mask[:, :-1]
    mv = mask[1:, :] & mask[:-1, :]
    on_h = (np.arange(dh.shape[1]) % 8 == 7)[None, :]
    on_v = (np.arange(dv.shape[0]) % 8 == 7)[:, None]
    across = np.concatenate([dh[mh & on_h], dv[mv & on_v]])
    within = np.concatenate([dh[mh & ~on_h], dv[mv & ~on_v]])
    if across.size < TEXTURE_MIN_PIXELS // 8 or within.size < TEXTURE_MIN_PIXELS:
        return None
    return float(across.mean() / max(within.mean(), 1e-9))


def blockiness(photo_display, result_display, labels):
    """Largest over the regions of the result's block-grid step ratio over the photo's (None: no region)."""
    def luma(img):
        img = np.asarray(img, np.float64)
        return 0.2126 * img[..., 0] + 0.7152 * img[..., 1] + 0.0722 * img[..., 2]

    yp, yr = luma(photo_display), luma(result_display)
    worst = None
    for k in np.unique(labels[labels > 0]):
        inner = inset(labels == k, 2)
        bp, br = _block_ratio(yp, inner), _block_ratio(yr, inner)
        if bp is None or br is None:
            continue
        ratio = br / bp
        worst = ratio if worst is None else max(worst, ratio)
    return worst


def enclosed_gaps(labels):
    """Unlabelled pixels with a region pixel on both sides within GAP_SPAN_PX along a row or a
    column (the two region pixels at most GAP_SPAN_PX + 1 apart)."""
    region = np.asarray(labels) > 0
    out = np.zeros(region.shape, bool)
    for r, back in ((region, False), (region.T, True)):
        w = r.shape[1]
        index = np.broadcast_to(np.arange(w)[None, :], r.shape)
        before = np.maximum.accumulate(np.where(r, index, -(10 ** 9)), axis=1)
        after = np.minimum.accumulate(np.where(r, index, 10 ** 9)[:, ::-1], axis=1)[:, ::-1]
        gap = ~r & (after - before <= GAP_SPAN_PX + 1)
        out |= gap.T if back else gap
    return out


def gaps_left(photo_display, result_display, labels, sky=None):
    """(share, count): the enclosed gap pixels (enclosed_gaps, sky excluded) the result leaves
    within 2 codes of the photo; (None, 0) when there are none."""
    gap = enclosed_gaps(labels)
    if sky is not None:
        gap &= ~np.asarray(sky, bool)
    n = int(gap.sum())
    if n == 0:
        return None, 0
    same = np.all(np.abs(np.asarray(result_display, np.float64)[..., :3] -
                         np.asarray(photo_display, np.float64)[..., :3]) <= 2.5 / 255, axis=-1)
    return float((same & gap).sum() / n), n


def colour_change(photo, result, labels):
    """Mean Delta E*ab between photo and result over the region pixels (0 without regions)."""
    m = labels > 0
    if not m.any():
        return 0.0
    scale = 1.0 / max(1e-6, float(np.percentile(luminance(photo), 99)))
    d = _lab(photo[m][None] * scale) - _lab(result[m][None] * scale)
    return float(np.sqrt((d * d).sum(-1)).mean())
