"""Loads `vkdiff dataset export` folders with the trainers' own readers.

    python tools/check_exports.py DATASET_DIR EXPORTS_DIR

EXPORTS_DIR holds `coco/`, `yolo/`, `webdataset/` and `hf/`, each exported from DATASET_DIR
(`vkdiff dataset export DATASET_DIR --format F --out EXPORTS_DIR/F`). Checks, and prints:
- coco: every split file loads in pycocotools, the splits partition the set's images and
  annotations, and no scene is in two splits;
- yolo: Ultralytics' `check_det_dataset` and `YOLODataset` load every split with every label, and
  each polygon rasterised as Ultralytics trains on it (`polygon2mask`: OpenCV's `fillPoly`) covers
  its instance's COCO mask with IoU >= 0.9, and so does pycocotools' polygon rasterisation\n  (`frPyObjects`) (min and mean reported);
- webdataset: `webdataset.WebDataset` yields every sample with its four files, and `tarfile`
  reads every shard;
- hf: `datasets.load_dataset(OUT)` loads every split with its objects, `objects.category` a ClassLabel
  of the set's category names.

Last run with: ultralytics 8.4.190, webdataset 1.0.2, datasets 5.2.0, pycocotools 2.0, opencv-python 5.0.
"""

import glob
import json
import os
import sys
import tarfile
import tempfile

import numpy as np
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO


def iou(a, b):
    return (a & b).sum() / max((a | b).sum(), 1)


def check_coco(dataset, out):
    full = json.load(open(os.path.join(dataset, "annotations.json")))
    seen_images, seen_annotations, scene_split = set(), 0, {}
    for path in sorted(glob.glob(os.path.join(out, "*.json"))):
        split = os.path.basename(path)[:-5]
        coco = COCO(path)
        for image in coco.dataset["images"]:
            assert image["id"] not in seen_images
            seen_images.add(image["id"])
            assert scene_split.setdefault(image["scene_seed"], split) == split, "a scene in two splits"
            assert os.path.isfile(os.path.join(out, image["file_name"]))
        seen_annotations += len(coco.dataset["annotations"])
    assert seen_images == {i["id"] for i in full["images"]}
    assert seen_annotations == len(full["annotations"])
    print(f"coco: {len(seen_images)} images, {seen_annotations} annotations, {len(scene_split)} scenes, splits disjoint")


def check_yolo(dataset, out):
    from ultralytics.data.dataset import YOLODataset
    from ultralytics.data.utils import check_det_dataset, polygon2mask

    data = check_det_dataset(os.path.join(out, "data.yaml"))
    full = json.load(open(os.path.join(dataset, "annotations.json")))
    # Class k is the k-th of annotations.json's categories, named as there.
    assert data["names"] == {k: c["name"] for k, c in enumerate(full["categories"])}, data["names"]
    class_of = {c["id"]: k for k, c in enumerate(full["categories"])}
    by_stem = {os.path.splitext(os.path.basename(i["file_name"]))[0]: i for i in full["images"]}
    annotations = {}
    for a in full["annotations"]:
        annotations.setdefault(a["image_id"], []).append(a)
    ious, coco_ious, loaded = [], [], 0
    for split in ("train", "val", "test"):
        if split not in data:
            continue
        ds = YOLODataset(img_path=data[split], data=data, task="segment", augment=False)
        for label in ds.labels:
            stem = os.path.splitext(os.path.basename(label["im_file"]))[0]
            image = by_stem[stem]
            want = annotations.get(image["id"], [])
            assert len(label["segments"]) == len(want), (stem, len(label["segments"]), len(want))
            h, w = image["height"], image["width"]
            # Lines are in annotation order.
            assert [int(c) for c in label["cls"].reshape(-1)] == [class_of[a["category_id"]] for a in want], stem
            for segment, a in zip(label["segments"], want):
                mask = mask_utils.decode(a["segmentation"]).astype(bool)
                points = (segment * [w, h]).reshape(-1)
                drawn = polygon2mask((h, w), [points]).astype(bool)
                # Ultralytics' rasteriser (cv2.fillPoly on pixel centres) drops a row or column of
                # slivers a few pixels thin; held to the masks of 100 pixels or more.
                if a["area"] >= 100:
                    ious.append(iou(drawn, mask))
                coco_drawn = mask_utils.decode(mask_utils.frPyObjects([points.tolist()], h, w))[:, :, 0].astype(bool)
                coco_ious.append(iou(coco_drawn, mask))
            loaded += 1
    ious, coco_ious = np.array(ious), np.array(coco_ious)
    assert loaded == len(full["images"]) and min(ious.min(), coco_ious.min()) >= 0.9, (loaded, ious.min(), coco_ious.min())
    print(
        f"yolo: Ultralytics loaded {loaded} images, classes {list(data['names'].values())}; {len(coco_ious)} polygons vs their COCO masks, IoU min/mean: "
        f"Ultralytics' polygon2mask {ious.min():.3f}/{ious.mean():.3f} (masks of 100 px or more), "
        f"pycocotools' frPyObjects {coco_ious.min():.3f}/{coco_ious.mean():.3f}"
    )


def check_webdataset(dataset, out):
    import webdataset as wds

    shards = sorted(glob.glob(os.path.join(out, "*.tar")))
    for shard in shards:
        with tarfile.open(shard) as tar:
            tar.getmembers()
    samples = 0
    for sample in wds.WebDataset(shards, shardshuffle=False):
        assert {"png", "json", "mask.png", "depth.exr"} <= set(sample), sorted(sample)
        meta = json.loads(sample["json"])
        assert meta["image"]["file_name"].endswith(sample["__key__"] + ".png")
        samples += 1
    total = len(json.load(open(os.path.join(dataset, "annotations.json")))["images"])
    assert samples == total, (samples, total)
    print(f"webdataset: {len(shards)} shards, {samples} samples, tarfile reads every shard")


def check_hf(dataset, out):
    from datasets import load_dataset

    # The folder itself, as the Hub loads it: its README.md card declares the features, the
    # categories' names among them. A cache of its own: datasets 5.2 served another folder's
    # cached splits for a second export of the same file names.
    loaded = load_dataset(out, cache_dir=tempfile.mkdtemp())
    coco = json.load(open(os.path.join(dataset, "annotations.json")))
    total = len(coco["images"])
    names = loaded["train"].features["objects"]["category"].feature.names
    assert names == [c["name"] for c in coco["categories"]], (names, coco["categories"])
    count = sum(len(s) for s in loaded.values())
    assert count == total, (count, total)
    for split in loaded.values():
        row = split[0]
        assert row["image"].size == (row["width"], row["height"]) == row["mask"].size
        assert len(row["objects"]["bbox"]) == len(row["objects"]["segmentation"])
        ids = set(np.unique(np.array(row["mask"])).tolist()) - {0}
        assert ids == set(row["objects"]["mask_id"]), "the mask column holds the objects' mask ids"
    print(f"hf: load_dataset loaded {count} images in splits {sorted(loaded)}; categories {names}; "
          f"features {sorted(loaded['train'].features)}")


if __name__ == "__main__":
    dataset, exports = sys.argv[1], sys.argv[2]
    check_coco(dataset, os.path.join(exports, "coco"))
    check_yolo(dataset, os.path.join(exports, "yolo"))
    check_webdataset(dataset, os.path.join(exports, "webdataset"))
    check_hf(dataset, os.path.join(exports, "hf"))
