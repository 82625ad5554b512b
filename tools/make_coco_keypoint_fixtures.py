#!/usr/bin/env python3
"""Golden values for keypoint evaluation (`vkdiff eval --iou-type keypoints`): random COCO
keypoint ground truth and results scored by pycocotools' COCOeval with iouType "keypoints".

Two ground truths: 17 keypoints (COCO's person layout, scored with pycocotools' own sigmas) and 9
(vkdiff's 3D-box corners and centre, scored with 1/9 each, Ultralytics' rule for other skeletons,
and with sigmas given by hand). Each has two categories, objects small to large, keypoints
unlabelled (v 0) and labelled invisible (v 1), objects with no labelled keypoint (ignored by
num_keypoints 0), crowd regions, an image without ground truth; the results jitter the ground
truth by a random fraction of the object's size, some duplicated, some in the wrong category,
some false positives, scores rounded so that they tie. Results come twice: keypoints only (loadRes
takes each area from the keypoints' extent) and with a detector's box (areas from the boxes).

Recorded per run: the ten statistics (at the last cap; with caps other than pycocotools' [20],
where summarize() gives -1, the same means taken from the arrays at the last cap), per category,
per area range, the precision and recall arrays' sums, and every OKS of COCOeval's `ious`.

Usage: make_coco_keypoint_fixtures.py OUT_DIR   (tests/fixtures/eval/keypoints)
Made with pycocotools 2.0.11 and numpy 2.4.6 (Python 3.11.7).
"""
import contextlib
import copy
import importlib.metadata
import io
import json
import sys

import numpy as np
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

rng = np.random.default_rng(70)
SIZES = [(240, 320), (180, 240)]


def ground_truth(k):
    images, anns, results = [], [], []
    aid = 1
    for img in range(1, 9):
        h, w = SIZES[img % 2]
        images.append({"id": img, "height": h, "width": w, "file_name": f"{img:04d}.png"})
        for _ in range(int(rng.integers(1, 6)) if img != 8 else 0):
            # Sides from 10 px (small) to 150 px (large).
            bw, bh = float(rng.choice([12.0, 45.0, 140.0]) * rng.uniform(0.7, 1.2)), float(rng.uniform(10, 140))
            x, y = float(rng.uniform(0, w - bw)), float(rng.uniform(0, h - bh))
            xs, ys = rng.uniform(x, x + bw, k), rng.uniform(y, y + bh, k)
            vis = rng.choice([0, 1, 2], k, p=[0.2, 0.2, 0.6])
            if rng.random() < 0.1:
                vis[:] = 0
            kp = []
            for px, py, v in zip(xs, ys, vis):
                kp += [0, 0, 0] if v == 0 else [round(float(px), 2), round(float(py), 2), int(v)]
            crowd = int(rng.random() < 0.08)
            cat = int(rng.integers(1, 3))
            anns.append({"id": aid, "image_id": img, "category_id": cat, "bbox": [round(v, 2) for v in (x, y, bw, bh)],
                         "area": round(bw * bh * float(rng.uniform(0.5, 0.9)), 2), "iscrowd": crowd,
                         "keypoints": kp, "num_keypoints": int((vis > 0).sum())})
            aid += 1
            # Detections: every keypoint predicted (an unlabelled one anywhere in the box), jittered
            # by 0.5 % to 15 % of the object's size; sometimes twice, sometimes the wrong category.
            for _ in range(int(rng.integers(0, 3))):
                spread = float(rng.choice([0.005, 0.02, 0.05, 0.15])) * np.sqrt(bw * bh)
                dx = np.where(vis > 0, xs, rng.uniform(x, x + bw, k)) + rng.normal(0, spread, k)
                dy = np.where(vis > 0, ys, rng.uniform(y, y + bh, k)) + rng.normal(0, spread, k)
                score = float(round(rng.uniform(0.05, 1.0), 1))
                results.append({"image_id": img, "category_id": cat if rng.random() < 0.9 else 3 - cat,
                                "keypoints": [round(float(v), 2) for p in zip(dx, dy, np.ones(k)) for v in p], "score": score})
        # False positives, on every image (the last has no ground truth).
        for _ in range(int(rng.integers(0, 3))):
            x0, y0, s = rng.uniform(0, w - 60), rng.uniform(0, h - 60), rng.uniform(5, 60)
            pts = [round(float(v), 2) for _ in range(k) for v in (x0 + rng.uniform(0, s), y0 + rng.uniform(0, s), 1.0)]
            results.append({"image_id": img, "category_id": int(rng.integers(1, 3)), "keypoints": pts,
                            "score": float(round(rng.uniform(0.05, 1.0), 2))})
    names = [f"k{i}" for i in range(k)]
    cats = [{"id": c, "name": n, "keypoints": names, "skeleton": []} for c, n in [(1, "box"), (2, "crate")]]
    return {"images": images, "annotations": anns, "categories": cats}, results


def with_boxes(results):
    """Each result with a detector's box: its keypoints' extent grown by a few pixels."""
    out = []
    for r in results:
        xs, ys = r["keypoints"][0::3], r["keypoints"][1::3]
        pad = rng.uniform(0, 4, 4)
        box = [min(xs) - pad[0], min(ys) - pad[1], max(xs) - min(xs) + pad[0] + pad[2], max(ys) - min(ys) + pad[1] + pad[3]]
        out.append({**r, "bbox": [round(float(v), 2) for v in box]})
    return out


def mean(v):
    return float(np.mean(v[v > -1])) if (v > -1).any() else -1.0


out = sys.argv[1]
files = {}
for k in (17, 9):
    gt, results = ground_truth(k)
    files[f"gt_{k}.json"] = gt
    files[f"dt_{k}.json"] = results
    files[f"dt_{k}_boxes.json"] = with_boxes(results)
for name, obj in files.items():
    with open(f"{out}/{name}", "w") as f:
        json.dump(obj, f)

custom = [0.05, 0.05, 0.05, 0.05, 0.08, 0.08, 0.08, 0.08, 0.1]
runs = [
    ("gt_17.json", "dt_17.json", None, [20]),
    ("gt_17.json", "dt_17_boxes.json", None, [20]),
    ("gt_9.json", "dt_9.json", [1 / 9] * 9, [20]),
    ("gt_9.json", "dt_9_boxes.json", custom, [20]),
    ("gt_9.json", "dt_9.json", custom, [1, 5]),
]
expected = {"pycocotools": importlib.metadata.version("pycocotools"), "numpy": np.__version__, "runs": []}
for gt_file, dt_file, sigmas, caps in runs:
    with contextlib.redirect_stdout(io.StringIO()):
        coco = COCO(f"{out}/{gt_file}")
        # loadRes fills in area, id and bbox on the dicts it is given: give it copies.
        res = coco.loadRes(copy.deepcopy(files[dt_file]))
        e = COCOeval(coco, res, "keypoints")
        if sigmas is not None:
            e.params.kpt_oks_sigmas = np.array(sigmas)
        e.params.maxDets = caps
        e.evaluate()
        e.accumulate()
        e.summarize()
    pr, rc = e.eval["precision"], e.eval["recall"]
    # _summarizeKps at the last cap: all, medium, large are area ranges 0, 1, 2; OKS .5 and .75
    # thresholds 0 and 5.
    stats = [mean(pr[:, :, :, 0, -1]), mean(pr[0, :, :, 0, -1]), mean(pr[5, :, :, 0, -1]), mean(pr[:, :, :, 1, -1]),
             mean(pr[:, :, :, 2, -1]), mean(rc[:, :, 0, -1]), mean(rc[0, :, 0, -1]), mean(rc[5, :, 0, -1]),
             mean(rc[:, :, 1, -1]), mean(rc[:, :, 2, -1])]
    if caps == [20]:
        assert np.allclose(stats, e.stats, atol=1e-12), (stats, e.stats)
    oks = []
    for (img, cat), m in sorted(e.ious.items()):
        if len(m) == 0:
            continue
        dts = sorted(e._dts[img, cat], key=lambda d: -d["score"])[: caps[-1]]  # Python's sort is stable, as mergesort
        gts = e._gts[img, cat]
        oks += [[d["id"], g["id"], float(m[i, j])] for i, d in enumerate(dts) for j, g in enumerate(gts)]
    expected["runs"].append({
        "gt": gt_file, "dt": dt_file, "kpt_sigmas": None if sigmas is None else [float(s) for s in sigmas],
        "max_dets": caps, "used_sigmas": [float(s) for s in e.params.kpt_oks_sigmas],
        "stats": stats, "pycocotools_stats": [float(v) for v in e.stats],
        "precision_sum": float(pr.sum()), "recall_sum": float(rc.sum()),
        "per_category": [{"id": int(c), "AP": mean(pr[:, :, k, 0, -1]), "AP50": mean(pr[0, :, k, 0, -1]), "AR": mean(rc[:, k, 0, -1])}
                         for k, c in enumerate(e.params.catIds)],
        "per_area": [{"area": name, "AP": mean(pr[:, :, :, a, -1]), "AR": mean(rc[:, :, a, -1])}
                     for a, name in enumerate(e.params.areaRngLbl)],
        "oks": oks,
    })
with open(f"{out}/expected.json", "w") as f:
    json.dump(expected, f, indent=1)
for r in expected["runs"]:
    print(r["gt"], r["dt"], r["max_dets"], [round(v, 4) for v in r["stats"]], len(r["oks"]), "OKS")
