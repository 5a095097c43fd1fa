#!/usr/bin/python3
"""Rebuild gallery/tune/, gallery/heldout/, gallery/fresh/ and gallery/LICENSES from gallery/manifest.csv.

The photos come from Debian 12 packages unpacked with `apt-get download PKG; dpkg-deb -x PKG.deb ROOT/PKG`:
    gallery/make_gallery.py ROOT [--only NAME,NAME]
With --only, just the named photos are converted (ROOT needs only their packages); the others keep
their files, whose sizes go into LICENSES.
Each photo is first turned upright (optional `turn` = 90, 180 or 270 degrees clockwise, for an
original stored on its side or upside down without an EXIF Orientation saying so), then cropped (optional `crop` = x0 y0 x1 y1 as fractions of width/height, used for the
panorama strips), reduced so the longest side is at most 1280 px (never enlarged) and written as
8-bit sRGB JPEG, quality 90, with 3 channels (grey photos are replicated into R=G=B).
An Enlightenment background (`.edj`, an Eet archive) holds the same photo as several plain JPEG
streams of different sizes; the largest one is used, cut out byte for byte.
"""
import csv, os, re, struct, sys, tempfile
import OpenImageIO as oiio

HERE = os.path.dirname(os.path.abspath(__file__))
LONGEST_PX = 1280


def jpeg_streams(data):
    """(start, end, width, height) of each complete JPEG stream (SOI .. EOI) embedded in data."""
    found = []
    for m in re.finditer(b"\xff\xd8\xff", data):
        p, w, h = m.start() + 2, 0, 0
        while p + 4 <= len(data) and data[p] == 0xFF:
            marker = data[p + 1]
            if marker == 0xFF:  # fill byte
                p += 1
                continue
            if marker == 0xD9:  # EOI
                found.append((m.start(), p + 2, w, h))
                break
            if 0xD0 <= marker <= 0xD7 or marker == 0x01:  # no length field
                p += 2
                continue
            length = struct.unpack(">H", data[p + 2:p + 4])[0]
            if marker in (0xC0, 0xC1, 0xC2):  # SOF: height, width
                h, w = struct.unpack(">HH", data[p + 5:p + 9])
            p += 2 + length
            if marker == 0xDA:  # entropy-coded data runs to the next marker other than stuffing or RST
                while p + 1 < len(data) and not (data[p] == 0xFF and data[p + 1] != 0x00
                                                  and not 0xD0 <= data[p + 1] <= 0xD7):
                    p += 1
    return found


def largest_embedded_jpeg(src, tmp_dir):
    data = open(src, "rb").read()
    streams = jpeg_streams(data)
    if not streams:
        raise SystemExit(f"make_gallery: no JPEG stream in {src}")
    start, end, w, h = max(streams, key=lambda s: s[2] * s[3])
    path = os.path.join(tmp_dir, os.path.basename(src) + ".jpg")
    with open(path, "wb") as f:
        f.write(data[start:end])
    return path, w, h


def convert(src, dst, crop, turn=""):
    with tempfile.TemporaryDirectory(prefix="make_gallery_") as tmp_dir:
        if src.endswith(".edj"):
            src = largest_embedded_jpeg(src, tmp_dir)[0]
        return convert_file(src, dst, crop, turn)


def convert_file(src, dst, crop, turn=""):
    buf = oiio.ImageBuf(src)
    if buf.has_error:
        raise SystemExit(f"make_gallery: cannot read {src}: {buf.geterror()}")
    spec = buf.spec()
    chans = (0, 1, 2) if spec.nchannels >= 3 else (0, 0, 0)
    buf = oiio.ImageBufAlgo.channels(buf, chans)
    turns = {"": None, "90": oiio.ImageBufAlgo.rotate90, "180": oiio.ImageBufAlgo.rotate180,
             "270": oiio.ImageBufAlgo.rotate270}
    if turn not in turns:
        raise SystemExit(f"make_gallery: {dst}: turn must be 90, 180 or 270, not {turn!r}")
    if turns[turn]:
        buf = turns[turn](buf)
    spec = buf.spec()
    if crop:
        x0, y0, x1, y1 = (float(v) for v in crop.split())
        roi = oiio.ROI(round(x0 * spec.width), round(x1 * spec.width),
                       round(y0 * spec.height), round(y1 * spec.height), 0, 1, 0, 3)
        buf = oiio.ImageBufAlgo.cut(buf, roi)
    w, h = buf.spec().width, buf.spec().height
    scale = min(1.0, LONGEST_PX / max(w, h))
    if scale < 1.0:
        nw, nh = max(1, round(w * scale)), max(1, round(h * scale))
        buf = oiio.ImageBufAlgo.resize(buf, roi=oiio.ROI(0, nw, 0, nh, 0, 1, 0, 3))
    # OIIO aborts writing an empty IPTC field (ImageDescription is the IPTC caption too). Read the
    # values through the spec: ParamValue.value crashes on some metadata types.
    spec = buf.spec()
    for name in [a.name for a in spec.extra_attribs
                 if a.type == oiio.TypeString and spec.get_string_attribute(a.name) == ""]:
        buf.specmod().erase_attribute(name)
    buf.specmod().attribute("compression", "jpeg:90")
    buf.specmod().attribute("oiio:ColorSpace", "sRGB")
    tmp = dst + ".tmp.jpg"
    if not buf.write(tmp, "uint8"):
        raise SystemExit(f"make_gallery: cannot write {dst}: {buf.geterror()}")
    os.replace(tmp, dst)
    return buf.spec().width, buf.spec().height


def main():
    args = sys.argv[1:]
    only = None
    if len(args) == 3 and args[1] == "--only":
        only = set(args[2].split(","))
        args = args[:1]
    if len(args) != 1:
        raise SystemExit(__doc__)
    root = args[0]
    with open(os.path.join(HERE, "manifest.csv"), newline="") as f:
        rows = list(csv.DictReader(f))
    lines = []
    for r in rows:
        out_dir = os.path.join(HERE, r["half"])
        os.makedirs(out_dir, exist_ok=True)
        dst = os.path.join(out_dir, r["name"] + ".jpg")
        if only is None or r["name"] in only:
            w, h = convert(os.path.join(root, r["package"]) + r["original_path"], dst, r["crop"],
                           r.get("turn") or "")
            print(f"{r['half']}/{r['name']}.jpg {w}x{h}")
        else:
            spec = oiio.ImageInput.open(dst).spec()
            w, h = spec.width, spec.height
        lines.append((r, w, h))
    with open(os.path.join(HERE, "LICENSES"), "w") as f:
        f.write("Provenance and licences of the gallery photos (generated by make_gallery.py from manifest.csv)\n")
        f.write("=" * 96 + "\n\n")
        crops = sum(1 for r, _, _ in lines if r["crop"])
        f.write(f"Every photo is a reduced copy (longest side <= 1280 px, JPEG quality 90; {crops} are 3:1 crops)\n"
                "of a file shipped in a Debian 12 (bookworm) package. Licence and author are as stated in that\n"
                "package's /usr/share/doc/<package>/copyright file (for plasma-workspace-wallpapers also the\n"
                "wallpaper's metadata.json; for python3-skimage the docstring of the data fetcher in\n"
                "skimage/data/_fetchers.py; for palapeli-data the puzzle's .desktop file; for lxqt-themes the\n"
                "wallpapers' License file; for python3-sklearn sklearn/datasets/images/README.txt). An .edj\n"
                "original is an Enlightenment background: the photo is its largest embedded JPEG stream.\n"
                "CC-BY/CC-BY-SA photos: attribution below; the reduced copies are shared under the same licence\n"
                "as the original.\n\n")
        for r, w, h in lines:
            f.write(f"{r['half']}/{r['name']}.jpg  ({w}x{h}; {r['category']})\n")
            f.write(f"  package:  {r['package']} {r['version']} (Debian 12)\n")
            f.write(f"  original: {r['original_path']}" + (f"  (turned {r['turn']} degrees clockwise)" if r.get('turn') else "")
                    + (f"  (crop x0 y0 x1 y1 = {r['crop']})" if r['crop'] else "") + "\n")
            f.write(f"  licence:  {r['licence']}\n")
            f.write(f"  author:   {r['author']}\n\n")


if __name__ == "__main__":
    main()
