#!/usr/bin/python3
"""Tests of the material transfer's gallery measures (gallery/material_measures.py) on images whose
answer is known, and of scripts/gallery_material end to end on one tuning photo.

    gallery_material_measures_test.py [path/to/mr]

Without the mr binary only the numpy cases run. Exit 0 when every check passes; each failed check
prints one line.
"""

import csv
import os
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "gallery"))
import material_measures as MM  # noqa: E402

W, H = 160, 120
failures = []


def check(cond, what):
    print(("ok    " if cond else "FAIL  ") + what)
    if not cond:
        failures.append(what)


def textured(seed, strength=0.3):
    """A grey photo with a smooth multi-scale texture (log contrast ~strength)."""
    rng = np.random.default_rng(seed)
    t = np.zeros((H, W))
    for scale in (2, 4, 8):
        small = rng.normal(size=(H // scale + 1, W // scale + 1))
        t += np.kron(small, np.ones((scale, scale)))[:H, :W]
    t = np.exp(strength * t / t.std())
    return np.repeat((0.2 * t)[..., None], 3, axis=2).astype(np.float32)


def main():
    labels = np.zeros((H, W), int)
    labels[:, 20:80] = 1
    labels[:, 80:140] = 2
    photo = textured(1)

    # Speckle: a new colour on both regions, clean, is no speckle (its steps at the regions'
    # borders lie between their neighbours), whether or not the photo has an edge there.
    result = photo.copy()
    result[labels == 1] *= np.array([1.5, 0.6, 0.4], np.float32)
    result[labels == 2] *= np.array([0.4, 0.7, 1.6], np.float32)
    frac, band, _ = MM.speckle(photo, result, labels)
    check(band > 6 * H and frac == 0, f"clean re-colouring: speckle {100 * frac:.3f} % of {band} band pixels is 0")
    # A 1-pixel dark line along the border between the regions (a sliver of an old dark
    # material) and isolated bright specks along the outer border are counted.
    lined = result.copy()
    lined[:, 80] *= 0.3
    for y in range(0, H, 4):
        lined[y, 139] *= 3.0
    frac, band, spk = MM.speckle(photo, lined, labels)
    expected = H + H // 4
    # Every line pixel and speck; a few of their neighbours on a step of the texture too (the
    # line makes them local extremes).
    check(spk[:, 80].all() and spk[::4, 139].all() and spk.sum() < 1.2 * expected,
          f"a dark line and {H // 4} specks: {int(spk.sum())} speckle pixels, all {expected} of them found")
    # Where the photo itself has the line, it is not created by the transfer.
    photo_lined = photo.copy()
    photo_lined[:, 80] *= 0.3
    frac, _, _ = MM.speckle(photo_lined, np.where((labels > 0)[..., None], lined, photo_lined), labels)
    check(frac < 0.05, f"a line the photo has: speckle {100 * frac:.2f} % (only the specks)")
    # Near black, a step of a code or two is the 8-bit coding's (invisible), not a speck: the same
    # specks 3 x the level of a dark result (sRGB codes 1 -> 3) are not counted, 3 x a mid-grey
    # one's are.
    for level, counted in ((0.0003, False), (0.05, True)):
        dark = np.full_like(photo, level)
        specked = dark.copy()
        for y in range(0, H, 4):
            specked[y, 139] *= 3.0
        _, _, spk = MM.speckle(dark, specked, labels)
        found = int(spk[::4, 139].sum())
        check(found == (H // 4 if counted else 0),
              f"{H // 4} specks 3 x a region of level {level}: {found} counted ({'all' if counted else 'none'} expected)")
    # Texture: kept exactly (a colour gain) gives correlation 1 and ratio 1 (within 1 %: the noise
    # floor, 0.003, is not scaled by the gain; the photo's level is ~0.2); flattened halves the
    # ratio; replaced by another texture drops the correlation.
    tex = MM.texture(photo, result, labels)
    check(set(tex) == {1, 2} and all(abs(c - 1) < 1e-4 and abs(r - 1) < 0.01 for _, c, r in tex.values()),
          f"texture under a colour gain: {tex}")
    flattened = np.where((labels > 0)[..., None], 0.3 * photo ** 0.5, photo)
    tex = MM.texture(photo, flattened, labels)
    check(all(abs(r - 0.5) < 0.03 and c > 0.99 for _, c, r in tex.values()),
          f"texture flattened (photo^0.5): ratios {[round(r, 3) for _, _, r in tex.values()]} ~0.5")
    other = np.where((labels > 0)[..., None], textured(2), photo)
    tex = MM.texture(photo, other, labels)
    check(all(abs(c) < 0.2 for _, c, _ in tex.values()),
          f"another texture: correlations {[round(c, 3) for _, c, _ in tex.values()]} ~0")

    # A near-black region (level 0.001, 8-bit-like noise of +-50 %): with the floor its high-pass
    # is a fraction of the noise's, so a clean result of it is not scored as flattened.
    rng = np.random.default_rng(3)
    dark = np.full((H, W, 3), 0.001, np.float32) * rng.uniform(0.5, 1.5, (H, W, 1)).astype(np.float32)
    raw = MM.high_pass(dark, floor=0)[labels == 1].std()
    floored = MM.high_pass(dark)[labels == 1].std()
    check(floored < 0.3 * raw, f"near-black noise: high-pass std {floored:.3f} with the floor, {raw:.3f} without")

    # Colour change: 0 for the photo itself, large for the re-colouring.
    check(MM.colour_change(photo, photo, labels) == 0, "colour change of the photo itself is 0")
    check(MM.colour_change(photo, result, labels) > 10, "colour change of a strong re-colouring > 10")

    # Clipped: region pixels at code 255 in the result and not in the photo (display values).
    shown = np.clip(photo / photo.max(), 0, 1)
    blown = shown.copy()
    blown[:30, 20:80, 0] = 1.0  # 30 x 60 of region 1's 120 x 60 pixels, one channel at 255
    blown[:, :20] = 1.0  # outside the regions: not counted
    check(abs(MM.clipped(shown, blown, labels) - 30 * 60 / (2 * 60 * H)) < 1e-9,
          f"clipped share {MM.clipped(shown, blown, labels):.4f} = 1800 / 14400")
    check(MM.clipped(blown, blown, labels) == 0, "clipped where the photo was clipped already: 0")

    # Blockiness: a smooth ramp with fine grain (steps everywhere), and the same with 8 x 8
    # blocks of +-2 % added (the result); the ramp itself as the result.
    yy, xx = np.mgrid[0:H, 0:W]
    grain = 0.004 * (((xx * 3 + yy * 7) % 5) - 2)
    ramp = np.repeat((0.3 + 0.3 * xx / W + grain)[..., None], 3, axis=2)
    blocks = (((xx // 8) * 7 + (yy // 8) * 5) % 3 - 1)[..., None] * 0.02
    blocky = np.clip(ramp + blocks, 0, 1)
    b_same, b_blocky = MM.blockiness(ramp, ramp, labels), MM.blockiness(ramp, blocky, labels)
    check(b_same is not None and abs(b_same - 1) < 1e-9, f"blockiness of the photo itself {b_same}: 1")
    check(b_blocky is not None and b_blocky > 1.5, f"blockiness with 2 % blocks added {b_blocky}: > 1.5")
    check(MM.blockiness(blocky, ramp, labels) < 1, "blocks taken out: below 1")

    # Gaps left: regions 1 (x < 30) and 2 (x >= 40) with a 10-pixel gap between them, and an
    # unlabelled margin 30 pixels wide beyond region 2 that no region closes (not a gap). The
    # result changes the regions and the gap's left half: half of the gap is left; the rows
    # marked as sky do not count.
    g_labels = np.zeros((20, 100), np.int32)
    g_labels[:, :30], g_labels[:, 40:70] = 1, 2
    g_photo = np.full((20, 100, 3), 0.5)
    g_result = g_photo.copy()
    g_result[:, :35] = 0.2
    g_result[:, 40:70] = 0.8
    check(MM.enclosed_gaps(g_labels).sum() == 20 * 10, "enclosed gap: the 10 columns between the regions")
    share, n = MM.gaps_left(g_photo, g_result, g_labels)
    check(n == 200 and abs(share - 0.5) < 1e-9, f"gaps left {share} of {n}: half of 200")
    sky = np.zeros((20, 100), bool)
    sky[:10] = True
    share, n = MM.gaps_left(g_photo, g_result, g_labels, sky)
    check(n == 100 and abs(share - 0.5) < 1e-9, f"gaps left without the sky {share} of {n}: half of 100")
    check(MM.gaps_left(g_photo, g_photo, np.where(g_labels == 2, 0, g_labels))[0] is None,
          "one region and open space: no gap")

    # The script end to end on two tuning photos (plant, 500 x 333, its sample rocket; coffee,
    # 600 x 400, its sample cold_water, whose regions' borders sit a few pixels inside the saucer's
    # and the cup's rims: 3.2 % speckle before the borders were despeckled). Both under the
    # speckle bar.
    if len(sys.argv) > 1:
        with tempfile.TemporaryDirectory(prefix="gallery_material_") as tmp:
            p = subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "gallery_material"), "--half", "tune",
                                "--photos", "plant,coffee", "--mr", sys.argv[1], "--out", tmp],
                               capture_output=True, text=True)
            check(p.returncode == 0, "scripts/gallery_material ran: " + (p.stderr.strip().splitlines() or [""])[-1])
            rows = list(csv.DictReader(open(os.path.join(tmp, "results.csv")))) if p.returncode == 0 else []
            check(len(rows) == 2, f"two rows ({len(rows)})")
            for row in rows:
                name = row.get("photo")
                check(row.get("status") == "ok" and row.get("regions", "0") != "0",
                      f"{name}: status {row.get('status')!r}, {row.get('regions')} regions ({row.get('message', '')})")
                check(row.get("clipped_pct", "") != "" and row.get("blockiness", "") != "",
                      f"{name}: clipped {row.get('clipped_pct')} % and blockiness {row.get('blockiness')} reported")
                check(row.get("speckle_pct", "") != "" and float(row.get("delta_e") or 0) > 5,
                      f"{name}: measured (speckle {row.get('speckle_pct')} %, colour change {row.get('delta_e')})")
                check(row.get("speckle_pct", "") != "" and float(row["speckle_pct"]) < 100 * MM.TARGET_SPECKLE,
                      f"{name}: speckle {row.get('speckle_pct')} % under the bar {100 * MM.TARGET_SPECKLE} %")
            check(os.path.exists(os.path.join(tmp, "contact_sheet_01.png")), "contact sheet written")

    print(f"{len(failures)} failed" if failures else "all passed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
