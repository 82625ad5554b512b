#!/usr/bin/env python3
"""Golden matches for `vkdiff dataset audit` (eval's `match_at`): pycocotools' COCOeval.evaluate()
at one IoU threshold, area "all", on the eval fixtures (tests/fixtures/eval: gt.json with
dt_segm.json as masks and dt_bbox.json as boxes), the results first cut to those scoring at least
a minimum, as the audit cuts them. Recorded per run: every match (the result's index in the cut
list, the ground truth's id, the IoU from COCOeval's `ious`), the ground truth left unmatched
(not ignored) and the results left unmatched.

Usage: make_coco_match_fixtures.py EVAL_FIXTURES OUT_DIR   (tests/fixtures/eval, …/eval/matching)
Made with pycocotools 2.0.11 and numpy 2.4.6 (Python 3.11.7).
"""
import contextlib
import importlib.metadata
import io
import json
import sys

import numpy as np
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

src, out = sys.argv[1], sys.argv[2]
expected = {"pycocotools": importlib.metadata.version("pycocotools"), "numpy": np.__version__, "runs": []}
for iou_type, dt_file, threshold, min_score in [("segm", "dt_segm.json", 0.5, 0.5), ("bbox", "dt_bbox.json", 0.5, 0.5),
                                                ("segm", "dt_segm.json", 0.75, 0.3), ("bbox", "dt_bbox.json", 0.3, 0.0)]:
    results = [r for r in json.load(open(f"{src}/{dt_file}")) if r["score"] >= min_score]
    with contextlib.redirect_stdout(io.StringIO()):
        coco = COCO(f"{src}/gt.json")
        res = coco.loadRes(results)
        e = COCOeval(coco, res, iou_type)
        e.params.iouThrs = np.array([threshold])
        e.params.areaRng, e.params.areaRngLbl = [[0, 1e10]], ["all"]
        e.params.maxDets = [100]
        e.evaluate()
    matched, missed, unmatched = [], [], []
    for ev in e.evalImgs:
        if ev is None:
            continue
        img, cat = ev["image_id"], ev["category_id"]
        ious = e.ious[img, cat]
        dts = sorted(e._dts[img, cat], key=lambda d: -d["score"])[:100]
        gt_index = {g["id"]: j for j, g in enumerate(e._gts[img, cat])}
        for i, (dt_id, gt_id) in enumerate(zip(ev["dtIds"], ev["dtMatches"][0])):
            assert dts[i]["id"] == dt_id
            if gt_id == 0:
                unmatched.append(dt_id - 1)
            else:
                matched.append([dt_id - 1, int(gt_id), float(ious[i, gt_index[int(gt_id)]])])
        missed += [int(g) for g, m, ignored in zip(ev["gtIds"], ev["gtMatches"][0], ev["gtIgnore"]) if m == 0 and not ignored]
    expected["runs"].append({"iou_type": iou_type, "results": dt_file, "iou": threshold, "min_score": min_score,
                             "matched": sorted(matched), "missed": sorted(missed), "unmatched": sorted(unmatched)})
with open(f"{out}/expected.json", "w") as f:
    json.dump(expected, f, indent=1)
for r in expected["runs"]:
    print(r["iou_type"], r["iou"], r["min_score"], len(r["matched"]), "matched", len(r["missed"]), "missed", len(r["unmatched"]), "unmatched")
