#!/usr/bin/env python3
"""Golden values for `eval/`: a random COCO ground truth (polygons, uncompressed and compressed
RLE, crowd regions, two categories, every area range) and random segm and bbox results (score
ties, images without detections or without ground truth), scored by pycocotools' COCOeval.

Detector output files: `dt_both.json` holds every segm result with a detector's box beside its
mask (as Detectron2, MMDetection and YOLO export them), scored as `loadRes` reads it (areas from
the boxes, since the first result has one) and as Detectron2 scores it (boxes dropped: areas from
the masks); `dt_mixed.json` is the same with some masks missing (`loadRes` makes them the box's
polygon). The segm-only results are also scored as boxes (`loadRes` takes each box from its mask).

A second ground truth, `gt_area_bounds.json`, puts objects and unmatched detections exactly on
the area ranges' bounds (32², 96²) and beside them (`coco_area_bounds.py`), scored as masks
(`dt_area_bounds_segm.json`) and as boxes (`dt_area_bounds_bbox.json`). Every run's AP, AP50,
AP75 and AR at each cap are kept per area range (`per_area`).

Usage: make_coco_eval_fixtures.py OUT_DIR
  (writes gt.json, dt_segm.json, dt_bbox.json, dt_both.json, dt_mixed.json, gt_area_bounds.json,
  dt_area_bounds_segm.json, dt_area_bounds_bbox.json, expected.json)
Made with pycocotools 2.0.11 and numpy 2.4.6 (Python 3.11); the values of the first three files
are those pycocotools 2.0.10 gave. The per-category figures were added with pycocotools 2.0.11 and
numpy 2.4.6 (Python 3.11); the files it writes are byte for byte the earlier ones. So were the
mIoU and foreground IoU figures (`mask_scores`), and the area-range bounds and `per_area` figures
(pycocotools 2.0.11, numpy 2.4.6, Python 3.11.7; the earlier files byte for byte the same).
"""
import contextlib
import copy
import importlib.metadata
import io
import json
import sys

import numpy as np
from coco_area_bounds import scene as area_bounds_scene
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

# Detector boxes: a few pixels larger than the mask's own box, as box heads predict them, so an
# object near a size-class boundary is small by its mask and medium by its box.
box_rng = np.random.default_rng(2121)
results_both = []
for r in results_segm:
    x, y, w, h = mask_utils.toBbox(r["segmentation"])
    dx, dy = box_rng.uniform(0, 3, 2)
    box = [float(round(v, 2)) for v in (x - dx, y - dy, w + dx + box_rng.uniform(0, 4), h + dy + box_rng.uniform(0, 4))]
    results_both.append({"image_id": r["image_id"], "category_id": r["category_id"], "bbox": box, "segmentation": r["segmentation"], "score": r["score"]})
results_mixed = [{k: v for k, v in r.items() if not (k == "segmentation" and i % 5 == 3)} for i, r in enumerate(results_both)]
results_boxless = [{k: v for k, v in r.items() if k != "bbox"} for r in results_both]

gt = {"info": {"description": "vkdiff eval fixture"}, "images": images, "annotations": anns, "categories": [{"id": 1, "name": "cap"}, {"id": 2, "name": "stem"}]}
gt_bounds, segm_bounds, bbox_bounds = area_bounds_scene()
out = sys.argv[1]
for name, obj in [("gt.json", gt), ("dt_segm.json", results_segm), ("dt_bbox.json", results_bbox), ("dt_both.json", results_both), ("dt_mixed.json", results_mixed),
                  ("gt_area_bounds.json", gt_bounds), ("dt_area_bounds_segm.json", segm_bounds), ("dt_area_bounds_bbox.json", bbox_bounds)]:
    with open(f"{out}/{name}", "w") as f:
        json.dump(obj, f)

expected = {"pycocotools": importlib.metadata.version("pycocotools"), "numpy": np.__version__}
runs = [
    ("segm", "dt_segm.json", [1, 10, 100], "", "gt.json"),
    ("bbox", "dt_bbox.json", [1, 10, 100], "", "gt.json"),
    ("segm", "dt_segm.json", [1, 3, 5], "", "gt.json"),
    ("segm", "dt_both.json", [1, 10, 100], " both", "gt.json"),
    ("segm", results_boxless, [1, 10, 100], " both, boxes dropped", "gt.json"),
    ("segm", "dt_mixed.json", [1, 10, 100], " mixed", "gt.json"),
    ("bbox", "dt_segm.json", [1, 10, 100], " from masks", "gt.json"),
    ("segm", "dt_area_bounds_segm.json", [1, 10, 100], " area bounds", "gt_area_bounds.json"),
    ("bbox", "dt_area_bounds_bbox.json", [1, 10, 100], " area bounds", "gt_area_bounds.json"),
]
for iou_type, dt_file, max_dets, label, gt_file in runs:
    with contextlib.redirect_stdout(io.StringIO()):
        coco = COCO(f"{out}/{gt_file}")
        # loadRes fills in area, id and iscrowd on the dicts it is given: give it copies.
        res = coco.loadRes(f"{out}/{dt_file}" if isinstance(dt_file, str) else copy.deepcopy(dt_file))
        e = COCOeval(coco, res, iou_type)
        e.params.maxDets = max_dets
        e.evaluate()
        e.accumulate()
        e.summarize()
    key = f"{iou_type} {max_dets}{label}"
    expected[key] = {"stats": [float(v) for v in e.stats],
                     "precision_sum": float(e.eval["precision"].sum()), "recall_sum": float(e.eval["recall"].sum())}
    # summarize() takes AP at 100 detections whatever maxDets says (-1 when 100 is not among
    # them); its own mean at the last cap, for vkdiff, which reports that.
    p = e.eval["precision"][:, :, :, 0, 2]
    expected[key]["ap_at_last_max_dets"] = float(np.mean(p[p > -1])) if (p > -1).any() else -1.0
    # Per category (e.params.catIds order), all areas, the last cap: AP, AP50 and AR as the
    # per-category slices of precision[t, r, k, a, m] and recall[t, k, a, m] give them.
    def mean(v):
        return float(np.mean(v[v > -1])) if (v > -1).any() else -1.0
    pr, rc = e.eval["precision"], e.eval["recall"]
    expected[key]["per_category"] = [
        {"id": int(c), "AP": mean(pr[:, :, k, 0, -1]), "AP50": mean(pr[0, :, k, 0, -1]), "AR": mean(rc[:, k, 0, -1])}
        for k, c in enumerate(e.params.catIds)
    ]
    # Per area range (e.params.areaRngLbl order), over categories: AP over IoU 0.50:0.95, at
    # 0.50 and 0.75 (the last cap), and AR at each cap.
    expected[key]["per_area"] = [
        {"area": name, "AP": mean(pr[:, :, :, a, -1]), "AP50": mean(pr[0, :, :, a, -1]),
         "AP75": mean(pr[5, :, :, a, -1]), "AR": [mean(rc[:, :, a, m]) for m in range(len(max_dets))]}
        for a, name in enumerate(e.params.areaRngLbl)
    ]

# Instance mIoU and foreground IoU, computed apart from COCOeval's IoU code: numpy over the
# masks pycocotools decodes. The matches are COCOeval's own (IoU 0.5, area "all", the last cap);
# an instance without a match counts 0 in mIoU and is left out of the matched mean.
def mask_scores(dt_file, thresholds):
    with contextlib.redirect_stdout(io.StringIO()):
        coco = COCO(f"{out}/gt.json")
        res = coco.loadRes(f"{out}/{dt_file}")
        e = COCOeval(coco, res, "segm")
        e.evaluate()
    ious = []
    for ev in e.evalImgs:
        if ev is None or ev["aRng"] != e.params.areaRng[0]:
            continue
        for gid, dt_id, ignored in zip(ev["gtIds"], ev["gtMatches"][0], ev["gtIgnore"]):
            if ignored:
                continue
            if dt_id == 0:
                ious.append(None)
                continue
            g, d = coco.annToMask(coco.anns[gid]).astype(bool), res.annToMask(res.anns[int(dt_id)]).astype(bool)
            ious.append(float((g & d).sum() / (g | d).sum()))
    matched = [v for v in ious if v is not None]
    scores = {"mIoU": sum(matched) / len(ious), "mIoU_matched": sum(matched) / len(matched),
              "instances": len(ious), "matched": len(matched)}
    for threshold in thresholds:
        inter = union = 0
        for img in coco.getImgIds():
            g = np.zeros((H, W), bool)
            for a in coco.loadAnns(coco.getAnnIds(imgIds=[img])):
                g |= coco.annToMask(a).astype(bool)
            p = np.zeros((H, W), bool)
            for a in res.loadAnns(res.getAnnIds(imgIds=[img])):
                if a["score"] >= threshold:
                    p |= res.annToMask(a).astype(bool)
            inter += int((g & p).sum())
            union += int((g | p).sum())
        scores[f"foreground_IoU@{threshold}"] = inter / union
    return scores


expected["mask_scores"] = {f: mask_scores(f, [0.5, 0.3]) for f in ["dt_segm.json", "dt_mixed.json"]}

# Every polygon's mask, to hold the rasteriser to frPyObjects pixel for pixel.
expected["polygon_rles"] = [
    {"id": a["id"], "counts": mask_utils.merge(mask_utils.frPyObjects(a["segmentation"], H, W))["counts"].decode()}
    for a in anns if isinstance(a["segmentation"], list)
]
with open(f"{out}/expected.json", "w") as f:
    json.dump(expected, f, indent=1)
print({k: v["stats"][:3] for k, v in expected.items() if isinstance(v, dict) and "stats" in v})
