#!/usr/bin/env python3
"""A JPEG corpus and what Pillow decodes from each file, for `formats/tests/jpeg.rs`.

Every file is written by a real encoder: Pillow (its bundled libjpeg-turbo), libjpeg-turbo's
`cjpeg` and ImageMagick's `convert` (Debian 12's libjpeg62-turbo 2.1.5), covering baseline and
progressive, 4:4:4 / 4:2:2 / 4:2:0 / 4:4:0 / 4:1:1, greyscale, RGB, CMYK and YCCK, restart
markers, EXIF orientation, qualities 5..100, odd and tiny sizes, and data cut short. The expected
pixels are `PIL.Image.open(f).convert("RGB")`, as torch-fidelity reads images, saved as PNG; files
Pillow refuses are listed with the error it raised.

    python3 -m venv /tmp/ref && /tmp/ref/bin/pip install pillow numpy
    apt-get install libjpeg-turbo-progs imagemagick
    /tmp/ref/bin/python tools/make_jpeg_fixtures.py tests/fixtures/jpeg

Made with Pillow 13.0.0 (libjpeg-turbo 3.2.0), numpy 2.4.6, cjpeg 2.1.5, ImageMagick 6.9.11.
"""

import io
import json
import os
import subprocess
import sys
import tempfile

import numpy as np
from PIL import Image, features

OUT = sys.argv[1]
rng = np.random.default_rng(21)


def scene(w, h):
    """A photo-like RGB image: smooth gradients, texture, hard edges and saturated patches (which
    push the YCbCr → RGB conversion against its clamps)."""
    yy, xx = np.mgrid[:h, :w].astype(np.float64)
    r = 128 + 100 * np.sin(xx / 7.0 + yy / 11.0)
    g = 90 + 80 * np.cos(yy / 5.0) + 30 * np.sin(xx * yy / 300.0)
    b = 60 + 150 * (xx / max(w - 1, 1))
    img = np.stack([r, g, b], -1) + rng.normal(0, 12, (h, w, 3))
    for _ in range(4):
        x0, y0 = rng.integers(0, w), rng.integers(0, h)
        img[y0 : y0 + h // 4 + 1, x0 : x0 + w // 5 + 1] = rng.choice([0, 255], 3)
    return Image.fromarray(np.clip(img, 0, 255).astype(np.uint8), "RGB")


def pillow(img, **kw):
    buf = io.BytesIO()
    img.save(buf, "JPEG", **kw)
    return buf.getvalue()


def tool(cmd, img):
    """Runs an encoder on `img` (given as a PPM/PGM file) and returns the JPEG bytes."""
    with tempfile.TemporaryDirectory() as d:
        src = os.path.join(d, "in.pnm")
        img.save(src)
        out = os.path.join(d, "out.jpg")
        subprocess.run([c.replace("IN", src).replace("OUT", out) for c in cmd], check=True)
        return open(out, "rb").read()


def first_scans(data, n):
    """The first `n` scans of a progressive file, then its end: an image the encoder never refined."""
    at = -1
    for _ in range(n + 1):
        at = data.index(b"\xff\xda", at + 1)
    return data[:at] + b"\xff\xd9"


def without_huffman_tables(data):
    """The file with its DHT segments removed, as motion-JPEG frames come (the decoder then takes
    the standard tables, which Pillow's encoder used)."""
    out, at = data[:2], 2
    while True:
        marker, length = data[at : at + 2], int.from_bytes(data[at + 2 : at + 4], "big")
        if marker != b"\xff\xc4":
            out += data[at : at + 2 + length]
        at += 2 + length
        if marker == b"\xff\xda":
            return out + data[at:]


def scans(text):
    """A cjpeg scan script in a file that lives as long as the process."""
    f = tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False)
    f.write(text)
    f.close()
    return f.name


# Each component in its own sequential scan (non-interleaved, multi-scan baseline).
SEQUENTIAL_PER_COMPONENT = scans("0;\n1;\n2;\n")
# Spectral selection only, bands in odd places, the chroma DC scan apart from the luma one.
SPECTRAL_ONLY = scans("0: 0-0, 0, 0;\n1 2: 0-0, 0, 0;\n0: 1-9, 0, 0;\n2: 1-63, 0, 0;\n0: 10-63, 0, 0;\n1: 1-63, 0, 0;\n")
# Successive approximation down to the last bit, DC refined twice.
DEEP_REFINEMENT = scans(
    "0 1 2: 0-0, 0, 2;\n0: 1-63, 0, 3;\n1: 1-63, 0, 1;\n2: 1-63, 0, 1;\n0 1 2: 0-0, 2, 1;\n"
    "0: 1-63, 3, 2;\n0: 1-63, 2, 1;\n0: 1-63, 1, 0;\n1: 1-63, 1, 0;\n2: 1-63, 1, 0;\n0 1 2: 0-0, 1, 0;\n"
)


def with_adobe_transform(data, transform):
    """The same file with its Adobe APP14 colour transform byte set (CMYK → YCCK)."""
    at = data.index(b"\xff\xee")
    assert data[at + 4 : at + 9] == b"Adobe"
    return data[: at + 15] + bytes([transform]) + data[at + 16 :]


def until_scan_data(data, fraction):
    """The file cut `fraction` into its entropy-coded data of the first scan."""
    sos = data.index(b"\xff\xda")
    start = sos + 2 + int.from_bytes(data[sos + 2 : sos + 4], "big")
    return data[: start + int((len(data) - start) * fraction)]


big = scene(131, 97)
small = scene(61, 43)
grey = small.convert("L")
cmyk = small.convert("CMYK")
exif = Image.Exif()
exif[0x0112] = 6  # orientation: rotate 90° clockwise to display; Pillow's open ignores it

cases = {
    "pil_420_q75": pillow(small),
    "pil_422_q90": pillow(small, quality=90, subsampling=1),
    "pil_444_q95": pillow(small, quality=95, subsampling=0),
    "pil_420_q100": pillow(small, quality=100, subsampling=2),
    "pil_420_q5": pillow(small, quality=5),
    "pil_420_big": pillow(big, quality=85),
    "pil_progressive_420": pillow(big, quality=80, progressive=True),
    "pil_progressive_444_optimize": pillow(small, progressive=True, optimize=True, subsampling=0),
    "pil_grey": pillow(grey),
    "pil_grey_progressive": pillow(grey, progressive=True),
    "pil_cmyk": pillow(cmyk, quality=90),
    "pil_ycck": with_adobe_transform(pillow(cmyk, quality=90), 2),
    "pil_restart_blocks": pillow(big, restart_marker_blocks=5),
    "pil_restart_rows_progressive": pillow(big, restart_marker_rows=1, progressive=True),
    "pil_exif_orientation": pillow(small, exif=exif.tobytes()),
    "pil_1x1": pillow(scene(1, 1)),
    "motion_jpeg_frame_without_tables": without_huffman_tables(pillow(small)),
    "pil_3x2_420": pillow(scene(3, 2)),
    "pil_17x9_422": pillow(scene(17, 9), subsampling=1),
    "cjpeg_411": tool(["cjpeg", "-sample", "4x1", "-outfile", "OUT", "IN"], big),
    "cjpeg_440": tool(["cjpeg", "-sample", "1x2", "-outfile", "OUT", "IN"], small),
    "cjpeg_rgb": tool(["cjpeg", "-rgb", "-outfile", "OUT", "IN"], small),
    "cjpeg_progressive_restart": tool(["cjpeg", "-progressive", "-restart", "3B", "-outfile", "OUT", "IN"], big),
    "cjpeg_422_restart_rows": tool(["cjpeg", "-sample", "2x1", "-restart", "1", "-quality", "60", "-outfile", "OUT", "IN"], big),
    "cjpeg_sequential_per_component": tool(["cjpeg", "-scans", SEQUENTIAL_PER_COMPONENT, "-outfile", "OUT", "IN"], big),
    "cjpeg_spectral_only": tool(["cjpeg", "-progressive", "-scans", SPECTRAL_ONLY, "-outfile", "OUT", "IN"], big),
    "cjpeg_deep_refinement": tool(["cjpeg", "-progressive", "-scans", DEEP_REFINEMENT, "-sample", "2x1", "-outfile", "OUT", "IN"], big),
    "cjpeg_grey_optimize": tool(["cjpeg", "-grayscale", "-optimize", "-outfile", "OUT", "IN"], small),
    "magick_420_progressive": tool(["convert", "IN", "-sampling-factor", "2x2", "-interlace", "Plane", "-quality", "85", "OUT"], big),
    "magick_cmyk": tool(["convert", "IN", "-colorspace", "CMYK", "-quality", "90", "OUT"], small),
    # Data that ends early at a marker: libjpeg-turbo warns, leaves the rest grey, Pillow shows it.
    "cut_at_eoi_baseline": until_scan_data(pillow(big), 0.6) + b"\xff\xd9",
    "cut_at_eoi_progressive": pillow(big, progressive=True)[:-900] + b"\xff\xd9",
    "progressive_first_scans_only": first_scans(pillow(big, progressive=True), 5),
    # Refused by both: the file ends inside the image data.
    "truncated_baseline": until_scan_data(pillow(big), 0.6),
    "truncated_progressive": pillow(big, progressive=True)[:-900],
    # Pillow decodes these (libjpeg-turbo); vkdiff refuses them with a reason.
    "cjpeg_arithmetic": tool(["cjpeg", "-arithmetic", "-outfile", "OUT", "IN"], small),
}

# Random settings on small random images: sizes 1..48, every mode and subsampling, any quality,
# progressive, optimised tables and restart intervals mixed.
pick = np.random.default_rng(2111)
for i in range(24):
    w, h = (int(v) for v in pick.integers(1, 49, 2))
    mode = ["RGB", "RGB", "L", "CMYK"][int(pick.integers(0, 4))]
    kw = {"quality": int(pick.integers(1, 101))}
    if mode == "RGB":
        kw["subsampling"] = int(pick.integers(0, 3))
    if pick.random() < 0.4:
        kw["progressive"] = True
    if pick.random() < 0.3:
        kw["optimize"] = True
    if pick.random() < 0.3:
        kw["restart_marker_blocks"] = int(pick.integers(1, 8))
    cases[f"random_{i:02d}_{mode.lower()}"] = pillow(scene(w, h).convert(mode), **kw)

os.makedirs(OUT, exist_ok=True)
index = {"pillow": Image.__version__, "libjpeg_turbo": features.version("libjpeg_turbo"), "numpy": np.__version__, "cases": {}}
for name, data in cases.items():
    with open(os.path.join(OUT, f"{name}.jpg"), "wb") as f:
        f.write(data)
    entry = {}
    try:
        with Image.open(io.BytesIO(data)) as im:
            rgb = im.convert("RGB")
            entry.update(width=rgb.width, height=rgb.height, pil_mode=im.mode)
        rgb.save(os.path.join(OUT, f"{name}.png"))
    except Exception as e:  # noqa: BLE001 — what Pillow raises is the expected outcome
        entry["pillow_error"] = f"{type(e).__name__}: {e}"
    index["cases"][name] = entry
with open(os.path.join(OUT, "index.json"), "w") as f:
    json.dump(index, f, indent=1)
print(json.dumps(index, indent=1))
