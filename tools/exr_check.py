#!/usr/bin/env python3
"""Reads a scene's depth.exr files with the OpenEXR reference library (C++ through its Python
binding), an implementation independent of ours and of the `exr` crate the tests use.

Versions used: Python 3.11.7, OpenEXR 3.5.3 (PyPI), numpy 2.4.6.
Setup: pip install OpenEXR numpy
Usage: tools/exr_check.py DIR   (checks DIR/depth.exr and DIR/crops/*/depth.exr)
"""
import json
import pathlib
import sys

import Imath
import numpy as np
import OpenEXR


def check(path):
    exr = OpenEXR.InputFile(str(path))
    header = exr.header()
    channels = header["channels"]
    assert list(channels) == ["Z"], f"{path}: channels {list(channels)}"
    assert channels["Z"].type == Imath.PixelType(Imath.PixelType.FLOAT), f"{path}: Z is not FLOAT"
    window = header["dataWindow"]
    width, height = window.max.x - window.min.x + 1, window.max.y - window.min.y + 1
    z = np.frombuffer(exr.channel("Z", Imath.PixelType(Imath.PixelType.FLOAT)), dtype=np.float32).reshape(height, width)
    assert np.isfinite(z).all(), f"{path}: non-finite depth"
    print(f"{path}: {width}x{height} Z, {header['compression']}, depth {z.min():.4f}..{z.max():.4f} m")
    return z


def main():
    folder = pathlib.Path(sys.argv[1])
    full = check(folder / "depth.exr")
    for crop in sorted((folder / "crops").glob("*")):
        z = check(crop / "depth.exr")
        # The crop is a window of the full frame: find it by its camera offset.
        x0, y0 = json.loads((crop / "camera.json").read_text())["crop_offset_px"]
        assert np.array_equal(z, full[y0:y0 + z.shape[0], x0:x0 + z.shape[1]]), f"{crop}: not a window of the full depth"


if __name__ == "__main__":
    main()
