#!/usr/bin/env python3
"""Golden values for `eval/`: a random COCO ground truth (polygons, uncompressed and compressed
RLE, crowd regions, two categories, every area range) and random segm and bbox results (score
ties, images without detections or without ground truth), scored by pycocotools' COCOeval.

Usage: make_coco_eval_fixtures.py OUT_DIR   (writes gt.json, dt_segm.json, dt_bbox.json, expected.json)
Made with pycocotools 2.0.10 and numpy 2.4.6 (Python 3.11).
"""
import contextlib
import io
import json
import sys

import numpy as np
import pycocotools
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

rng = np.random.default_rng(2026)
H, W = 90, 120


def polygon(cx, cy, r):
    n = int(rng.integers(3, 9))
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    rad = r * rng.uniform(0.6, 1.2, n)
    return [float(round(v, 2)) for a, q in zip(ang, rad) for v in (cx + q * np.cos(a), cy + q * np.sin(a))]


def shape_mask(cx, cy, r):
    yy, xx = np.mgrid[:H, :W]
    return np.asfortranarray(((xx - cx) ** 2 / r ** 2 + (yy - cy) ** 2 / (0.7 * r) ** 2 <= 1).astype(np.uint8))


def uncompressed(m):
    flat = m.flatten(order="F")
    counts, cur, run = [], 0, 0
    for v in flat:
        if v != cur:
            counts.append(run)
            cur, run = v, 0
        run += 1
    counts.append(run)
    return {"size": [H, W], "counts": [int(c) for c in counts]}


images, anns, results_segm, results_bbox = [], [], [], []
aid = 1
for img in range(1, 7):
    images.append({"id": img, "height": H, "width": W, "file_name": f"{img}.png"})
    for _ in range(int(rng.integers(0, 9)) if img != 6 else 0):
        cx, cy = rng.uniform(10, W - 10), rng.uniform(10, H - 10)
        r = float(rng.choice([3.0, 8.0, 25.0]) * rng.uniform(0.8, 1.3))
        kind = rng.integers(0, 3)
        if kind == 0:
            seg = [polygon(cx, cy, r)] + ([polygon(cx + r, cy, r / 2)] if rng.random() < 0.3 else [])
            rle = mask_utils.merge(mask_utils.frPyObjects(seg, H, W))
        else:
            m = shape_mask(cx, cy, r)
            rle = mask_utils.encode(m)
            seg = uncompressed(m) if kind == 1 else {"size": [H, W], "counts": rle["counts"].decode()}
        crowd = int(rng.random() < 0.1)
        anns.append({"id": aid, "image_id": img, "category_id": int(rng.integers(1, 3)), "segmentation": seg,
                     "area": float(mask_utils.area(rle)), "bbox": [float(v) for v in mask_utils.toBbox(rle)], "iscrowd": crowd})
        aid += 1
        # Detections near the ground truth: jittered, sometimes the wrong class. Inside a crowd
        # region, a detection half its size: matched (and ignored) only by the crowd rule.
        for j in range(int(rng.integers(0, 3)) + crowd):
            scale = 0.5 if crowd and j == 0 else rng.uniform(0.85, 1.15)
            m = shape_mask(cx + rng.normal(0, r / 10), cy + rng.normal(0, r / 10), r * scale)
            rle = mask_utils.encode(m)
            score = float(round(rng.uniform(0.05, 1.0), 1))  # ties on purpose
            cat = anns[-1]["category_id"] if rng.random() < 0.85 else 3 - anns[-1]["category_id"]
            results_segm.append({"image_id": img, "category_id": cat, "segmentation": {"size": [H, W], "counts": rle["counts"].decode()}, "score": score})
            results_bbox.append({"image_id": img, "category_id": cat, "bbox": [float(v) for v in mask_utils.toBbox(rle)], "score": score})
    # False positives away from everything (image 6 has no ground truth at all).
    for _ in range(int(rng.integers(0, 3))):
        m = shape_mask(rng.uniform(5, W - 5), rng.uniform(5, H - 5), float(rng.uniform(2, 20)))
        rle = mask_utils.encode(m)
        score = float(round(rng.uniform(0.05, 1.0), 2))
        results_segm.append({"image_id": img, "category_id": int(rng.integers(1, 3)), "segmentation": {"size": [H, W], "counts": rle["counts"].decode()}, "score": score})
        results_bbox.append({"image_id": img, "category_id": results_segm[-1]["category_id"], "bbox": [float(v) for v in mask_utils.toBbox(rle)], "score": score})

gt = {"info": {"description": "vkdiff eval fixture"}, "images": images, "annotations": anns, "categories": [{"id": 1, "name": "cap"}, {"id": 2, "name": "stem"}]}
out = sys.argv[1]
for name, obj in [("gt.json", gt), ("dt_segm.json", results_segm), ("dt_bbox.json", results_bbox)]:
    with open(f"{out}/{name}", "w") as f:
        json.dump(obj, f)

expected = {"pycocotools": pycocotools.__version__ if hasattr(pycocotools, "__version__") else "2.0.10", "numpy": np.__version__}
for iou_type, dt_file, max_dets in [("segm", "dt_segm.json", [1, 10, 100]), ("bbox", "dt_bbox.json", [1, 10, 100]), ("segm", "dt_segm.json", [1, 3, 5])]:
    with contextlib.redirect_stdout(io.StringIO()):
        coco = COCO(f"{out}/gt.json")
        res = coco.loadRes(f"{out}/{dt_file}")
        e = COCOeval(coco, res, iou_type)
        e.params.maxDets = max_dets
        e.evaluate()
        e.accumulate()
        e.summarize()
    key = f"{iou_type} {max_dets}"
    expected[key] = {"stats": [float(v) for v in e.stats],
                     "precision_sum": float(e.eval["precision"].sum()), "recall_sum": float(e.eval["recall"].sum())}
    # summarize() takes AP at 100 detections whatever maxDets says (-1 when 100 is not among
    # them); its own mean at the last cap, for vkdiff, which reports that.
    p = e.eval["precision"][:, :, :, 0, 2]
    expected[key]["ap_at_last_max_dets"] = float(np.mean(p[p > -1])) if (p > -1).any() else -1.0

# Every polygon's mask, to hold the rasteriser to frPyObjects pixel for pixel.
expected["polygon_rles"] = [
    {"id": a["id"], "counts": mask_utils.merge(mask_utils.frPyObjects(a["segmentation"], H, W))["counts"].decode()}
    for a in anns if isinstance(a["segmentation"], list)
]
with open(f"{out}/expected.json", "w") as f:
    json.dump(expected, f, indent=1)
print({k: v["stats"][:3] for k, v in expected.items() if isinstance(v, dict)})
