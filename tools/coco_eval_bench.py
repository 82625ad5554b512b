#!/usr/bin/env python3
"""`vkdiff eval` beside pycocotools on a COCO file the size of the paper's test set: 195 images
of 720×1280 with ~145 polygon instances each (M18K's layout), and predictions as compressed RLE
(the ground truth's masks, jittered, plus false positives), then pycocotools' COCOeval timed.

Usage: coco_eval_bench.py OUT_DIR   (writes gt.json and pred.json, prints pycocotools' time)
Then:  time ./target/release/vkdiff eval --gt OUT_DIR/gt.json --pred OUT_DIR/pred.json --max-dets 1,10,300
Made with pycocotools 2.0.10 and numpy 2.4.6.
"""
import contextlib
import io
import json
import sys
import time

import numpy as np
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

rng = np.random.default_rng(7)
H, W, IMAGES, PER_IMAGE = 720, 1280, 195, 145
out = sys.argv[1]


def polygon(cx, cy, r, n=16):
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rad = r * rng.uniform(0.85, 1.15, n)
    return [float(round(v, 1)) for a, q in zip(ang, rad) for v in (cx + q * np.cos(a), cy + q * np.sin(a))]


images, anns, preds = [], [], []
for img in range(1, IMAGES + 1):
    images.append({"id": img, "height": H, "width": W, "file_name": f"{img}.jpg"})
    for _ in range(PER_IMAGE):
        cx, cy, r = rng.uniform(30, W - 30), rng.uniform(30, H - 30), rng.uniform(8, 40)
        seg = [polygon(cx, cy, r)]
        rle = mask_utils.merge(mask_utils.frPyObjects(seg, H, W))
        anns.append({"id": len(anns) + 1, "image_id": img, "category_id": 1, "segmentation": seg,
                     "area": float(mask_utils.area(rle)), "bbox": [float(v) for v in mask_utils.toBbox(rle)], "iscrowd": 0})
        if rng.random() < 0.9:
            p = mask_utils.merge(mask_utils.frPyObjects([polygon(cx + rng.normal(0, 2), cy + rng.normal(0, 2), r)], H, W))
            preds.append({"image_id": img, "category_id": 1, "segmentation": {"size": [H, W], "counts": p["counts"].decode()}, "score": float(rng.uniform(0.3, 1.0))})
    for _ in range(20):
        p = mask_utils.merge(mask_utils.frPyObjects([polygon(rng.uniform(30, W - 30), rng.uniform(30, H - 30), rng.uniform(8, 40))], H, W))
        preds.append({"image_id": img, "category_id": 1, "segmentation": {"size": [H, W], "counts": p["counts"].decode()}, "score": float(rng.uniform(0.0, 0.6))})

json.dump({"info": {}, "images": images, "annotations": anns, "categories": [{"id": 1, "name": "mushroom"}]}, open(f"{out}/gt.json", "w"))
json.dump(preds, open(f"{out}/pred.json", "w"))
start = time.perf_counter()
with contextlib.redirect_stdout(io.StringIO()):
    coco = COCO(f"{out}/gt.json")
    res = coco.loadRes(f"{out}/pred.json")
    e = COCOeval(coco, res, "segm")
    e.params.maxDets = [1, 10, 300]
    e.evaluate()
    e.accumulate()
e.summarize()
print(f"pycocotools: {time.perf_counter() - start:.1f} s for {len(anns)} ground-truth annotations and {len(preds)} predictions "
      f"(load, evaluate, accumulate; summarize's AP line is its -1 at 100 detections)")
print("stats", [round(float(v), 6) for v in e.stats])
