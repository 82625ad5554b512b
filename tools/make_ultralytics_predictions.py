#!/usr/bin/env python3
"""Ultralytics' own prediction files on a vkdiff set, for `vkdiff dataset audit --predictions`.

A render-only set (`vkdiff dataset --render-only --seed 11 --crops 0 --count 3 --width 320
--height 224`: 3 whole frames of 320×224, wider than tall, one category) is exported with
`vkdiff dataset export --format yolo`; tiny YOLO11 detect and segment models are built from
Ultralytics' own yaml (nc set to the set's one class) with random weights (torch.manual_seed(0),
no download; the segment head's last mask convolutions drawn N(0, 0.5²), else its masks are
empty and save_txt writes nothing) and run on it. Untrained, they box the whole frame, which
still tells x from y on a frame wider than tall:

- `predict(save_txt=True, save_conf=True)` writes `labels/STEM.txt`
  (ultralytics/engine/results.py, Results.save_txt: `class x_c y_c w h conf` normalised, or for
  a segment model `class x1 y1 … xn yn conf`, `%g`; no file for an image with no detection);
- `val(save_json=True)` writes `predictions.json` (ultralytics/models/yolo/detect/val.py,
  DetectionValidator.pred_to_json: `image_id` int(stem) where numeric, `file_name`,
  `category_id` class_map[class] = class + 1 for a set that is not COCO, `bbox` x, y, w, h in
  pixels to 3 decimals, `score` to 5; segment/val.py adds `segmentation` as compressed RLE).

Written to OUT: detect/labels/*.txt, detect/predictions.json, segment/labels/*.txt,
segment/predictions.json; set.json (the set's images and categories, to map stems and classes
back); expected.json (each predict() result as Ultralytics' Results object holds it: the image
stem, class, confidence, box x1 y1 x2 y2 in pixels and, for segment, the polygon in pixels).

Usage: make_ultralytics_predictions.py VKDIFF OUT   (tests/fixtures/audit/ultralytics)
Made with ultralytics 8.4.190 and torch 2.15.0 (CPU), Python 3.11.7.
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("YOLO_OFFLINE", "1")
import torch  # noqa: E402
import ultralytics  # noqa: E402
from ultralytics import YOLO  # noqa: E402

vkdiff, out = sys.argv[1], Path(sys.argv[2])
work = Path(tempfile.mkdtemp())
subprocess.run([vkdiff, "dataset", "--render-only", "--out", str(work / "set"), "--seed", "11", "--crops", "0",
                "--count", "3", "--width", "320", "--height", "224"], check=True, capture_output=True)
subprocess.run([vkdiff, "dataset", "export", str(work / "set"), "--format", "yolo", "--out", str(work / "yolo"),
                "--val-fraction", "0.5", "--seed", "1", "--copy"], check=True, capture_output=True)
coco = json.loads((work / "set" / "annotations.json").read_text())
out.mkdir(parents=True, exist_ok=True)
(out / "set.json").write_text(json.dumps({
    "images": [{k: i[k] for k in ("id", "file_name", "width", "height")} for i in coco["images"]],
    "categories": [{"id": c["id"], "name": c["name"]} for c in coco["categories"]]}, indent=1))
images = sorted(str(p) for p in (work / "yolo" / "images").rglob("*.png"))
# val reads data.yaml's splits; point both at every image so that each is scored.
data = work / "yolo" / "data.yaml"
expected = {"ultralytics": ultralytics.__version__, "torch": torch.__version__, "detect": [], "segment": []}
cfg = Path(ultralytics.__file__).parent / "cfg" / "models" / "11"
for task, yaml in [("detect", "yolo11n.yaml"), ("segment", "yolo11n-seg.yaml")]:
    # The family's yaml with one class, named so that Ultralytics takes the n scale.
    text = (cfg / yaml.replace("n.yaml", ".yaml").replace("n-seg", "-seg")).read_text().replace("nc: 80", "nc: 1")
    (work / yaml).write_text(text)
    torch.manual_seed(0)
    model = YOLO(str(work / yaml), task=task)
    head = model.model.model[-1]
    if task == "segment":
        for part in [head.proto, *head.cv4]:
            last = [m for m in part.modules() if isinstance(m, torch.nn.Conv2d)][-1]
            torch.nn.init.normal_(last.weight, 0.0, 0.5)
    run = work / "runs" / task
    results = model.predict(images, save_txt=True, save_conf=True, conf=0.0, max_det=8, imgsz=320,
                            project=str(run), name="predict", exist_ok=True, save=False, verbose=False)
    for r in results:
        stem = Path(r.path).stem
        polygons = r.masks.xy if r.masks is not None else [None] * len(r.boxes)
        for box, conf, cls, poly in zip(r.boxes.xyxy.tolist(), r.boxes.conf.tolist(), r.boxes.cls.tolist(), polygons):
            if poly is not None and len(poly) < 3:
                continue  # save_txt leaves these out
            entry = {"stem": stem, "class": int(cls), "conf": conf, "xyxy": box}
            if poly is not None:
                entry["polygon"] = [float(v) for v in poly.reshape(-1)]
            expected[task].append(entry)
    shutil.copytree(run / "predict" / "labels", out / task / "labels", dirs_exist_ok=True)
    model.val(data=str(data), save_json=True, conf=0.0, max_det=8, imgsz=320, batch=1, plots=False,
              project=str(run), name="val", exist_ok=True, verbose=False)
    shutil.copy(run / "val" / "predictions.json", out / task / "predictions.json")
(out / "expected.json").write_text(json.dumps(expected))
print({t: len(expected[t]) for t in ("detect", "segment")}, sorted(p.name for p in (out / "detect" / "labels").iterdir()))
