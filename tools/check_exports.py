"""Loads `vkdiff dataset export` folders with the trainers' own readers.

    python tools/check_exports.py DATASET_DIR EXPORTS_DIR

EXPORTS_DIR holds any of `coco/`, `yolo/`, `yolo-pose/`, `webdataset/`, `hf/` and `bop/`, each
exported from DATASET_DIR (`vkdiff dataset export DATASET_DIR --format F --out EXPORTS_DIR/F`);
each one there is checked, and the figures printed:
- coco: every split file loads in pycocotools, the splits partition the set's images and
  annotations, and no scene is in two splits; `loadAnns` and `loadImgs` give back each
  annotation and image entry as annotations.json holds it (keypoints, poses, 3D boxes, amodal
  masks, cameras and all), `loadCats` the categories with their keypoints and skeletons;
- yolo: Ultralytics' `check_det_dataset` and `YOLODataset` load every split with every label, and
  each polygon rasterised as Ultralytics trains on it (`polygon2mask`: OpenCV's `fillPoly`) covers
  its instance's COCO mask with IoU >= 0.9, and so does pycocotools' polygon rasterisation
  (`frPyObjects`) (min and mean reported);
- yolo-pose: `YOLODataset(task="pose")` on `check_det_dataset`'s data loads every label; each
  box is its COCO bbox and each keypoint the set's (x, y to the labels' 6 decimals, v exactly;
  categories with fewer keypoints padded 0 0 0); built for training with Ultralytics' default
  hyperparameters it turns fliplr and flipud off itself, as data.yaml has no flip_idx;
- webdataset: `webdataset.WebDataset` yields every sample with its four files, and `tarfile`
  reads every shard;
- hf: `datasets.load_dataset(OUT)` loads every split with its objects, `objects.category` a ClassLabel
  of the set's category names;
- bop: read with bop_toolkit's own readers (`bop_toolkit_lib.dataset.bop_scenewise.load_image_data`,
  `inout`): each JSON file is byte for byte what `inout.save_json` writes of its content; each
  image's cam_K, world pose, depth (to half a depth step), visible and amodal masks (exactly)
  and poses are the set's; scene_gt_info.json is what calc_gt_info's formulas (`misc.calc_2d_bbox`)
  give from those masks and that depth; and each seen or hidden box keypoint of the set is the
  projection (`misc.project_pts`) of its models_info.json box corner by cam_K and the gt's pose.
  bop_toolkit is not on the Python package registry: give a checkout of thodan/bop_toolkit as
  BOP_TOOLKIT (its bop_toolkit_lib needs numpy, scipy, imageio, pypng); OpenEXR reads the depth.

Last run with: ultralytics 8.4.190, webdataset 1.0.2, datasets 5.2.0, pycocotools 2.0, opencv-python 5.0.

The geometric checks (coco's labels, yolo-pose, bop) last ran on 2026-12-05 with ultralytics
8.4.190, pycocotools 2.0.11, opencv-python 5.1.0, numpy 2.4.6, scipy 1.17.1, imageio 2.38.2,
OpenEXR 3.5.3 and bop_toolkit at commit cea62d6fb (thodan/bop_toolkit), Python 3.11, on
render-only sets (`vkdiff dataset --render-only --scenes SRC --out SET [crops]`, every export
with `--val-fraction 0.3`) of tests/fixtures/scenes/bop-dataset/train_pbr whole (2 images, 7
instances) and in three 48² crops `--seed 3` (6 images, 14), tests/fixtures/scenes/bop whole (4,
12) and in four 40² crops `--seed 5` (16 images, one without instances, 32), and a 640×480
`vkdiff scene --seed 5` folder given three keypoints per mushroom in six 160² crops `--seed 2`
(136 instances). Figures: every COCO annotation, image and category given back whole; YOLO pose
keypoints within 8.2e-5 px of the set's and boxes within 3.4e-5 px, v equal, flips off in
training; BOP masks, cameras and poses equal, depth within 0.000 mm, scene_gt_info equal to
calc_gt_info's formulas, 140 box keypoints within 0.0048 px of project_pts, all 38 JSON files byte
for byte as save_json writes them.
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

from check_bop_export import check_bop


def iou(a, b):
    return (a & b).sum() / max((a | b).sum(), 1)


def check_coco(dataset, out):
    full = json.load(open(os.path.join(dataset, "annotations.json")))
    seen_images, seen_annotations, scene_split = set(), 0, {}
    images = {i["id"]: i for i in full["images"]}
    annotations = {a["id"]: a for a in full["annotations"]}
    geometric = ("keypoints", "pose", "bbox_3d", "amodal_segmentation")
    labelled = {f: 0 for f in geometric}
    for path in sorted(glob.glob(os.path.join(out, "*.json"))):
        split = os.path.basename(path)[:-5]
        coco = COCO(path)
        for image in coco.dataset["images"]:
            assert image["id"] not in seen_images
            seen_images.add(image["id"])
            assert scene_split.setdefault(image["scene_seed"], split) == split, "a scene in two splits"
            assert os.path.isfile(os.path.join(out, image["file_name"]))
        # pycocotools' own indexes give each entry back whole, the geometric labels with it.
        assert coco.loadImgs(coco.getImgIds()) == [images[i] for i in coco.getImgIds()]
        for a in coco.loadAnns(coco.getAnnIds()):
            assert a == annotations[a["id"]], a["id"]
            for f in geometric:
                labelled[f] += f in a
        assert coco.loadCats(coco.getCatIds()) == full["categories"]
        seen_annotations += len(coco.dataset["annotations"])
    assert seen_images == {i["id"] for i in full["images"]}
    assert seen_annotations == len(full["annotations"])
    cameras = sum("camera" in i for i in full["images"])
    print(f"coco: {len(seen_images)} images, {seen_annotations} annotations, {len(scene_split)} scenes, splits disjoint; "
          f"loadAnns/loadImgs/loadCats give back every entry: annotations with {labelled}, {cameras} image cameras")


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
    # A set with no scene in val validates on train: each folder once.
    for path in dict.fromkeys(data[s] for s in ("train", "val", "test") if s in data):
        ds = YOLODataset(img_path=path, data=data, task="segment", augment=False)
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


def check_yolo_pose(dataset, out):
    from ultralytics.cfg import get_cfg
    from ultralytics.data.dataset import YOLODataset
    from ultralytics.data.utils import check_det_dataset

    data = check_det_dataset(os.path.join(out, "data.yaml"))
    k_most, dims = data["kpt_shape"]
    assert dims == 3 and "flip_idx" not in data, data
    full = json.load(open(os.path.join(dataset, "annotations.json")))
    class_of = {c["id"]: k for k, c in enumerate(full["categories"])}
    by_stem = {os.path.splitext(os.path.basename(i["file_name"]))[0]: i for i in full["images"]}
    annotations = {}
    for a in full["annotations"]:
        annotations.setdefault(a["image_id"], []).append(a)
    loaded, instances, points, worst, worst_box = 0, 0, {0: 0, 1: 0, 2: 0}, 0.0, 0.0
    for path in dict.fromkeys(data[s] for s in ("train", "val", "test") if s in data):
        ds = YOLODataset(img_path=path, data=data, task="pose", augment=False)
        for label in ds.labels:
            image = by_stem[os.path.splitext(os.path.basename(label["im_file"]))[0]]
            want, (w, h) = annotations.get(image["id"], []), (image["width"], image["height"])
            assert [int(c) for c in label["cls"].reshape(-1)] == [class_of[a["category_id"]] for a in want]
            for box, kpts, a in zip(label["bboxes"], label["keypoints"], want):
                x, y, bw, bh = a["bbox"]
                worst_box = max(worst_box, np.abs(box * [w, h, w, h] - [x + bw / 2, y + bh / 2, bw, bh]).max())
                kp = np.zeros((k_most, 3))
                kp[: len(a.get("keypoints", [])) // 3] = np.array(a.get("keypoints", [])).reshape(-1, 3)
                assert (kpts[:, 2] == kp[:, 2]).all(), (image["id"], kpts, kp)
                # Written within the image: a keypoint less than half a pixel past its edge sits on it.
                xy = np.clip(kp[:, :2], 0, [w, h]) / [w, h]
                worst = max(worst, (np.abs(kpts[:, :2] - xy) * [w, h]).max())
                for v in kp[:, 2]:
                    points[int(v)] += 1
                instances += 1
            loaded += 1
    assert loaded == len(full["images"]) and instances == len(full["annotations"]), (loaded, instances)
    assert worst <= 1e-6 * max(max(i["width"], i["height"]) for i in full["images"]) + 1e-4, worst
    hyp = get_cfg()
    assert hyp.fliplr > 0
    training = YOLODataset(img_path=data["train"], data=data, task="pose", augment=True, hyp=hyp)
    flips = [t.p for t in training.transforms.transforms if type(t).__name__ == "RandomFlip"]
    assert len(flips) == 2 and not any(flips), "without flip_idx Ultralytics turns flips off"
    print(f"yolo-pose: Ultralytics loaded {loaded} images, {instances} instances, kpt_shape {data['kpt_shape']}; "
          f"keypoints by v {points}, largest difference from the set's {worst:.2e} px (box {worst_box:.2e} px); "
          f"fliplr and flipud turned off for training")


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


CHECKS = {"coco": check_coco, "yolo": check_yolo, "yolo-pose": check_yolo_pose, "webdataset": check_webdataset,
          "hf": check_hf, "bop": check_bop}

if __name__ == "__main__":
    dataset, exports = sys.argv[1], sys.argv[2]
    present = [f for f in CHECKS if os.path.isdir(os.path.join(exports, f))]
    assert present, f"{exports} holds none of {list(CHECKS)}"
    for format in present:
        CHECKS[format](dataset, os.path.join(exports, format))
