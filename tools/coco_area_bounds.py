"""A COCO scene on the bounds of pycocotools' area ranges, for make_coco_eval_fixtures.py.

pycocotools' ranges are closed on both ends: small [0, 32²], medium [32², 96²], large [96², 1e5²];
a ground truth is ignored in a range when `area < lo or area > hi` (its `area` field, not its
mask's pixel count), and so is an unmatched detection by its own area (`loadRes`: the box's w·h
when results carry boxes, else the mask's pixel count). So an object of area exactly 1024 is in
small and medium, one of 9216 in medium and large. The scene puts ground truth and unmatched
detections exactly on both bounds and one pixel either side; two ground-truth fields say 1024
and 9216 over masks of 1023 and 9215 pixels; a second category has small objects only.
Rectangles, so that a box and its mask agree.
"""
import numpy as np
from pycocotools import mask as mask_utils

H, W = 240, 320

# (image, x, y, w, h, area field): on the bounds, on them by the field only, and off them.
GROUND_TRUTH = [
    (1, 10, 10, 32, 32, 1024),
    (1, 60, 10, 33, 31, 1024),  # 1023 pixels
    (1, 10, 100, 96, 96, 9216),
    (1, 150, 100, 97, 95, 9216),  # 9215 pixels
    (2, 10, 10, 30, 30, 900),
    (2, 60, 10, 40, 40, 1600),
    (2, 150, 60, 100, 100, 10000),
]

# (image, x, y, w, h, score): detections of the ground truth above, exact or shifted (IoU
# from 0.65 to 1), then false positives nowhere near it on the bounds and beside them.
DETECTIONS = [
    (1, 10, 10, 32, 32, 0.9),
    (1, 63, 12, 33, 31, 0.8),
    (1, 18, 104, 96, 96, 0.7),
    (1, 150, 100, 97, 95, 0.6),
    (2, 12, 11, 30, 30, 0.75),
    (2, 65, 14, 40, 40, 0.5),
    (2, 150, 60, 100, 100, 0.45),
    (1, 14, 13, 32, 32, 0.35),  # a second, worse detection of the first object
    (1, 280, 10, 16, 64, 0.85),  # 1024
    (3, 10, 10, 32, 32, 0.55),  # 1024
    (3, 100, 10, 96, 96, 0.65),  # 9216
    (2, 260, 20, 48, 192, 0.4),  # 9216
    (3, 10, 100, 33, 31, 0.3),  # 1023
    (3, 60, 100, 25, 41, 0.58),  # 1025
    (3, 100, 120, 97, 95, 0.2),  # 9215
    (3, 210, 120, 93, 99, 0.25),  # 9207
]

# A second category with small objects only: its medium and large precision and recall are
# undefined (-1), which every mean over categories must leave out.
STEMS = [(2, 200, 10, 20, 20, 400)]
STEM_DETECTIONS = [(2, 201, 11, 20, 20, 0.7), (3, 250, 200, 10, 10, 0.5)]


def rectangle(x, y, w, h):
    m = np.zeros((H, W), np.uint8, order="F")
    m[y:y + h, x:x + w] = 1
    return mask_utils.encode(m)


def scene():
    """Ground truth (with masks and boxes), segm-only results and bbox-only results."""
    images = [{"id": i, "height": H, "width": W, "file_name": f"{i}.png"} for i in (1, 2, 3)]
    anns = []
    objects = [(1, *o) for o in GROUND_TRUTH] + [(2, *o) for o in STEMS]
    for aid, (cat, img, x, y, w, h, area) in enumerate(objects, 1):
        rle = rectangle(x, y, w, h)
        anns.append({"id": aid, "image_id": img, "category_id": cat, "iscrowd": 0, "area": float(area),
                     "bbox": [float(x), float(y), float(w), float(h)],
                     "segmentation": {"size": [H, W], "counts": rle["counts"].decode()}})
    gt = {"info": {"description": "vkdiff eval fixture: COCO area-range bounds"}, "images": images,
          "annotations": anns, "categories": [{"id": 1, "name": "cap"}, {"id": 2, "name": "stem"}]}
    detections = [(1, *d) for d in DETECTIONS] + [(2, *d) for d in STEM_DETECTIONS]
    segm = [{"image_id": img, "category_id": cat, "score": score,
             "segmentation": {"size": [H, W], "counts": rectangle(x, y, w, h)["counts"].decode()}}
            for cat, img, x, y, w, h, score in detections]
    bbox = [{"image_id": img, "category_id": cat, "score": score, "bbox": [float(x), float(y), float(w), float(h)]}
            for cat, img, x, y, w, h, score in detections]
    return gt, segm, bbox
