#!/usr/bin/env python3
"""COCO mask goldens from the reference implementation (pycocotools), for vkdiff-render's tests.

Versions used to write the committed fixture: Python 3.11.7, pycocotools 2.0.11, numpy 2.4.6.
Setup: pip install pycocotools numpy

Two uses:
  tools/coco_golden.py fixture [--out render/tests/fixtures/coco_rle_golden.json]
      Builds label images (random clumped blobs plus edge cases: labels on every border, a
      single first/last pixel, a full image, runs long enough for multi-character counts and
      negative deltas), encodes every label with pycocotools.mask.encode, and writes the label
      images with pycocotools' compressed counts, areas and boxes. CI reads that file; it
      never runs Python.
  tools/coco_golden.py check DIR
      Loads DIR/annotations.json with pycocotools.coco.COCO and checks, for every annotation,
      that annToMask equals (instances.png == id), that area equals mask.area, that bbox equals
      mask.toBbox, and that ids run 1..K; then does the same for every DIR/crops/*/.
"""
import argparse
import json
import pathlib
import sys
from importlib.metadata import version

import numpy as np
from pycocotools import mask as mask_util

ALPHABET = ".abcdefghijklmnopqrstuvwxyz"  # '.' is label 0 (background)


def blobs(rng, height, width, labels):
    """Label image with `labels` overlapping discs painted in order (later ones on top)."""
    image = np.zeros((height, width), dtype=np.uint16)
    yy, xx = np.mgrid[0:height, 0:width]
    for label in range(1, labels + 1):
        cy, cx = rng.uniform(0, height), rng.uniform(0, width)
        r = rng.uniform(1, max(2, min(height, width) / 3))
        image[(yy - cy) ** 2 + (xx - cx) ** 2 <= r * r] = label
    return image


def cases():
    rng = np.random.default_rng(20240607)
    out = [("random blobs 40x23", blobs(rng, 23, 40, 9)), ("random blobs 17x64", blobs(rng, 64, 17, 12))]
    edge = np.zeros((9, 11), dtype=np.uint16)
    edge[0, :] = 1  # top row
    edge[:, 0] = 2  # left column (over the top row's first pixel)
    edge[-1, :] = 3  # bottom row
    edge[:, -1] = 4  # right column
    edge[4, 5] = 5  # one pixel inside
    out.append(("borders and a single pixel", edge))
    corners = np.zeros((5, 7), dtype=np.uint16)
    corners[0, 0], corners[-1, -1] = 1, 2
    out.append(("first and last pixel", corners))
    out.append(("full image", np.ones((6, 4), dtype=np.uint16)))
    # A big image with long and shrinking runs: counts need several characters and deltas go negative.
    big = np.zeros((300, 200), dtype=np.uint16)
    big[:, 10:150] = 1
    big[100:103, 60:70] = 2
    big[0:299, 180] = 3
    big[299, 199] = 4
    out.append(("long runs 200x300", big))
    return out


def encode(image, label):
    m = np.asfortranarray((image == label).astype(np.uint8))
    rle = mask_util.encode(m)
    return {
        "label": int(label),
        "counts": rle["counts"].decode("ascii"),
        "area": int(mask_util.area(rle)),
        "bbox": [int(v) for v in mask_util.toBbox(rle)],
    }


def fixture(out_path):
    doc = {
        "generator": "tools/coco_golden.py fixture",
        "versions": {"python": sys.version.split()[0], "pycocotools": version("pycocotools"), "numpy": np.__version__},
        "legend": "rows top to bottom; '.' is background, 'a' is label 1, 'b' label 2, ...",
        "cases": [],
    }
    for name, image in cases():
        h, w = image.shape
        doc["cases"].append({
            "name": name,
            "height": h,
            "width": w,
            "rows": ["".join(ALPHABET[v] for v in row) for row in image],
            "annotations": [encode(image, label) for label in sorted(set(np.unique(image)) - {0})],
        })
    pathlib.Path(out_path).write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {out_path}: {len(doc['cases'])} cases")


def read_png16(path):
    """16-bit grayscale PNG through Pillow if present, else imageio."""
    try:
        from PIL import Image
        return np.array(Image.open(path)).astype(np.int64)
    except ImportError:
        import imageio.v3 as iio
        return iio.imread(path).astype(np.int64)


def check_dir(folder):
    from pycocotools.coco import COCO
    coco = COCO(str(folder / "annotations.json"))
    ids = read_png16(folder / "instances.png")
    ann_ids = sorted(coco.getAnnIds())
    assert ann_ids == list(range(1, len(ann_ids) + 1)), "annotation ids must run 1..K"
    assert int(ids.max(initial=0)) == len(ann_ids), "instances.png ids must match annotations"
    for ann in coco.loadAnns(ann_ids):
        mask = coco.annToMask(ann).astype(bool)
        assert np.array_equal(mask, ids == ann["id"]), f"mask of {ann['id']} differs from instances.png"
        rle = ann["segmentation"]
        assert ann["area"] == int(mask_util.area(rle)) == int(mask.sum()), f"area of {ann['id']}"
        assert [int(v) for v in ann["bbox"]] == [int(v) for v in mask_util.toBbox(rle)], f"bbox of {ann['id']}"
    print(f"{folder}: {len(ann_ids)} annotations agree with pycocotools")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    f = sub.add_parser("fixture")
    f.add_argument("--out", default="render/tests/fixtures/coco_rle_golden.json")
    c = sub.add_parser("check")
    c.add_argument("dir", type=pathlib.Path)
    args = parser.parse_args()
    if args.command == "fixture":
        fixture(args.out)
    else:
        check_dir(args.dir)
        for crop in sorted((args.dir / "crops").glob("*")):
            check_dir(crop)


if __name__ == "__main__":
    main()
