#!/usr/bin/env python3
"""BOP scenes for `vkdiff dataset --scenes`, written as BOP's own writers write them.

bop_toolkit (thodan/bop_toolkit) is not on the Python package registry (BlenderProc installs it
from git), so this script writes the files the way its writers do, read from their source:
  - bop_toolkit_lib/inout.py, thodan/bop_toolkit at commit 1454e87118109c0715fbd1f0623451429d25b53f:
    save_json (a dict written one sorted key per line, each value json.dumps(sort_keys=True)),
    save_scene_camera / save_scene_gt (matrices flattened row-major to lists), save_depth (np.round
    to uint16, 16-bit greyscale PNG through PyPNG), save_im (imageio, PNG compression 3);
  - blenderproc/python/writer/BopWriterUtility.py, DLR-RM/BlenderProc at commit
    02a5c92839c8bbf18d5c593a76f44660c44921cc: the layout (<scene:06d>/scene_camera.json,
    scene_gt.json, rgb/<im:06d>.png, depth/<im:06d>.png, mask/ and mask_visib/<im:06d>_<gt:06d>.png
    with 255 inside), depth in mm / depth_scale, scene_camera entries cam_K, depth_scale,
    cam_R_w2c, cam_t_w2c (mm), scene_gt entries obj_id, cam_R_m2c, cam_t_m2c (mm), gt id = index.
The pixels are drawn here with numpy (ellipses and bars at planar depths, nearest wins); the
visible mask of a gt is where it is nearest, its amodal mask where it covers.

Versions used for the committed fixtures: Python 3.11, numpy 2.4.6, pypng 0.20220715.0,
imageio 2.38.2, Pillow 13.0.0.
Setup and rerun:
  /tmp/ref/bin/pip install numpy pillow pypng imageio
  /tmp/ref/bin/python tools/make_bop_fixtures.py [--out tests/fixtures/scenes]

Writes under --out:
  bop/: a split of two scenes, 96×72. 000000/ (images 0 and 1; rgb/ PNGs as PBR renders are
      written, depth_scale 0.1, cam_R_w2c/cam_t_w2c given) and 000001/ (images 2 and 10, so that
      image ids sort as numbers; gray/ PNGs, depth_scale 1.0, no world pose). Objects of obj_ids
      1 and 2 touch, occlude each other and are cut by the frame's edge; one gt is hidden behind
      another (its visible mask empty); the top rows are sky (depth 0), a table fills the rest.
      bop/categories.json names obj_id 1 only (obj_id 2 falls back to obj_000002); a scene folder
      given alone (--scenes bop/000001) has none beside it, so both are named by id.
  bop-dataset/: a BOP dataset's root: train_pbr/000000/ (scene 0 as above) and
      models/models_info.json (each obj_id's box, mm, as the toolkit's calc_model_info writes
      min_x/y/z and size_x/y/z), and expected_keypoints.json: per scene/image/gt, the nine box
      keypoints (the eight corners, x slowest, then the centre) projected here with numpy, each
      x, y, v (2 seen, 1 behind the depth seen at its pixel, 0 outside the image: 0, 0, 0).
  bop-bad/<fault>/000000/: scene 000000 broken one way each: missing-mask (a mask_visib file
      removed), depth-size (image 1's depth 95×72), overlap (two visible masks share pixels).
"""
import argparse
import json
import pathlib
import shutil

import imageio.v2 as imageio
import numpy as np
import png

WIDTH, HEIGHT = 96, 72


def write_json(path, content):
    """A dict as BOP's save_json writes it: `{`, one `  "key": value` line per key in sorted key
    order (values serialised with sorted keys), `}`, no trailing newline."""
    lines = [f'  "{k}": {json.dumps(v, sort_keys=True)}' for k, v in sorted(content.items())]
    path.write_text("{\n" + ",\n".join(lines) + "\n}")


def write_depth(path, depth):
    """Depth in depth_scale steps: rounded to uint16, a 16-bit grey PNG through PyPNG."""
    values = np.round(depth).astype(np.uint16)
    writer = png.Writer(values.shape[1], values.shape[0], greyscale=True, bitdepth=16)
    with open(path, "wb") as f:
        writer.write(f, values.reshape(-1, values.shape[1]))


def write_image(path, pixels):
    imageio.imwrite(path, pixels, compression=3)


def rotation(angles):
    """A rotation matrix from three angles (radians) about x, y and z."""
    a, b, c = angles
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    return rz @ ry @ rx


def draw(objects):
    """Planar depth (mm; 0 in the sky), each object's amodal and visible masks, and a render."""
    yy, xx = np.mgrid[:HEIGHT, :WIDTH].astype(np.float64)
    sky = yy < 10
    depth = np.where(sky, 0.0, 900.0 + 2.0 * (HEIGHT - yy))
    nearest = np.full((HEIGHT, WIDTH), -1)
    amodal = []
    for k, (_, kind, (cx, cy), (rx, ry), z) in enumerate(objects):
        if kind == "ellipse":
            inside = ((xx - cx) / rx) ** 2 + ((yy - cy) / ry) ** 2 <= 1
        else:
            inside = (abs(xx - cx) <= rx) & (abs(yy - cy) <= ry)
        amodal.append(inside)
        closer = inside & ((depth == 0) | (depth > z))
        depth[closer] = z + (xx[closer] % 3)
        nearest[closer] = k
    visible = [nearest == k for k in range(len(objects))]
    rgb = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
    rgb[:] = np.where(sky[..., None], [150, 190, 235], [120, 100, 80])
    for k, (obj_id, *_rest) in enumerate(objects):
        rgb[visible[k]] = {1: [200, 40, 40], 2: [40, 60, 200]}[obj_id]
    return depth, amodal, visible, rgb


# Per scene: (depth_scale, K, world pose given, render folder, {im_id: objects}); an object is
# (obj_id, shape, centre px, radii px, depth mm).
SCENES = {
    0: (
        0.1,
        [[80.0, 0.0, 47.5], [0.0, 80.0, 35.5], [0.0, 0.0, 1.0]],
        True,
        "rgb",
        {
            0: [
                (1, "ellipse", (30, 40), (12, 10), 600.0),
                (1, "ellipse", (53, 40), (11, 10), 610.0),  # touches the first
                (2, "bar", (45, 52), (30, 4), 550.0),  # occludes both
                (2, "ellipse", (90, 30), (14, 12), 700.0),  # cut by the right edge
            ],
            1: [
                (2, "ellipse", (10, 60), (16, 14), 500.0),  # cut by the left and bottom edges
                (1, "ellipse", (50, 30), (10, 9), 650.0),
                (1, "ellipse", (50, 30), (6, 5), 800.0),  # hidden behind the one above
                (2, "bar", (70, 20), (6, 18), 640.0),  # cut by the top, over the sky
            ],
        },
    ),
    1: (
        1.0,
        [[90.0, 0.0, 48.0], [0.0, 88.0, 36.0], [0.0, 0.0, 1.0]],
        False,
        "gray",
        {
            2: [
                (2, "ellipse", (40, 36), (20, 12), 700.0),
                (1, "ellipse", (62, 36), (9, 9), 690.0),  # touches, a little in front
                (1, "bar", (85, 60), (12, 8), 720.0),  # cut by the corner
            ],
            10: [
                (1, "ellipse", (20, 30), (10, 12), 600.0),
                (2, "ellipse", (28, 34), (10, 8), 580.0),  # occludes it
            ],
        },
    ),
}


def write_scene(dir, scene_id):
    depth_scale, K, world, render, images = SCENES[scene_id]
    rng = np.random.default_rng(scene_id)
    for sub in ["depth", "mask", "mask_visib", render]:
        (dir / sub).mkdir(parents=True, exist_ok=True)
    cameras, gts = {}, {}
    for im_id, objects in images.items():
        depth, amodal, visible, rgb = draw(objects)
        camera = {"cam_K": np.array(K).flatten().tolist(), "depth_scale": depth_scale}
        if world:
            r_w2c = rotation(rng.uniform(-0.5, 0.5, 3))
            camera["cam_R_w2c"] = r_w2c.flatten().tolist()
            camera["cam_t_w2c"] = rng.uniform(-300, 300, 3).tolist()
        cameras[im_id] = camera
        gts[im_id] = []
        for gt_id, (obj_id, _, (cx, cy), _, z) in enumerate(objects):
            t = [(cx - K[0][2]) * z / K[0][0], (cy - K[1][2]) * z / K[1][1], z]
            r = rotation(rng.uniform(-np.pi, np.pi, 3))
            gts[im_id].append({"obj_id": obj_id, "cam_R_m2c": r.flatten().tolist(), "cam_t_m2c": t})
            write_image(dir / f"mask/{im_id:06d}_{gt_id:06d}.png", 255 * amodal[gt_id].astype(np.uint8))
            write_image(dir / f"mask_visib/{im_id:06d}_{gt_id:06d}.png", 255 * visible[gt_id].astype(np.uint8))
        write_depth(dir / f"depth/{im_id:06d}.png", depth / depth_scale)
        pixels = rgb if render == "rgb" else rgb.mean(axis=2).round().astype(np.uint8)
        write_image(dir / f"{render}/{im_id:06d}.png", pixels)
    write_json(dir / "scene_camera.json", cameras)
    write_json(dir / "scene_gt.json", gts)
    # scene_gt_info.json as the toolkit's calc_gt_info gives it (bounding boxes, pixel counts).
    info = {}
    for im_id, objects in images.items():
        _, amodal, visible, _ = draw(objects)
        info[im_id] = [gt_info(a, v) for a, v in zip(amodal, visible)]
    write_json(dir / "scene_gt_info.json", info)


def bbox(mask):
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return [-1, -1, -1, -1]
    return [int(xs.min()), int(ys.min()), int(xs.max() - xs.min() + 1), int(ys.max() - ys.min() + 1)]


def gt_info(amodal, visible):
    all_, visib = int(amodal.sum()), int(visible.sum())
    return {
        "bbox_obj": bbox(amodal),
        "bbox_visib": bbox(visible),
        "px_count_all": all_,
        "px_count_valid": all_,
        "px_count_visib": visib,
        "visib_fract": visib / all_ if all_ else 0.0,
    }


# obj_id → (min xyz, size xyz), mm.
MODELS = {1: ([-30.0, -20.0, -10.0], [60.0, 40.0, 20.0]), 2: ([-150.0, -8.0, -6.0], [300.0, 16.0, 12.0])}


def box_points(obj_id):
    """The box's corners (x slowest, then y, then z; min before max) and its centre, mm."""
    lo, size = np.array(MODELS[obj_id][0]), np.array(MODELS[obj_id][1])
    hi = lo + size
    corners = [[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    return np.array(corners + [list((lo + hi) / 2)])


def round_hundredth(c):
    """To 1/100 pixel, halves away from zero."""
    return float(np.sign(c) * np.floor(abs(c) * 100 + 0.5) / 100)


def expected_keypoints(scene_dir):
    """Each gt's box keypoints, projected with cam_K; seen unless the depth at its pixel (metres,
    0 = nothing) is nearer than 99 % of its own."""
    cameras = json.loads((scene_dir / "scene_camera.json").read_text())
    gts = json.loads((scene_dir / "scene_gt.json").read_text())
    out = {}
    for im_id, camera in cameras.items():
        K = np.array(camera["cam_K"]).reshape(3, 3)
        depth = imageio.imread(scene_dir / f"depth/{int(im_id):06d}.png").astype(np.float64)
        depth = np.where(depth == 0, np.inf, depth * camera["depth_scale"] / 1000.0)
        out[im_id] = []
        for gt in gts[im_id]:
            R = np.array(gt["cam_R_m2c"]).reshape(3, 3)
            t = np.array(gt["cam_t_m2c"]) / 1000.0
            points = []
            for p in box_points(gt["obj_id"]) / 1000.0:
                x, y, z = R @ p + t
                u, v = K[0, 0] * x / z + K[0, 2], K[1, 1] * y / z + K[1, 2]
                col, row = int(np.floor(u + 0.5)), int(np.floor(v + 0.5))
                if z <= 0 or not (0 <= col < WIDTH and 0 <= row < HEIGHT):
                    points.append([0.0, 0.0, 0])
                    continue
                seen = depth[row, col] >= z * 0.99
                points.append([round_hundredth(u), round_hundredth(v), 2 if seen else 1])
            out[im_id].append(points)
    return out


def write_dataset(root):
    shutil.rmtree(root, ignore_errors=True)
    write_scene(root / "train_pbr/000000", 0)
    info = {
        obj_id: {"diameter": float(np.linalg.norm(size)), **{f"min_{a}": m for a, m in zip("xyz", lo)},
                 **{f"size_{a}": s for a, s in zip("xyz", size)}}
        for obj_id, (lo, size) in MODELS.items()
    }
    (root / "models").mkdir()
    write_json(root / "models/models_info.json", info)
    expected = {"000000": expected_keypoints(root / "train_pbr/000000")}
    (root / "expected_keypoints.json").write_text(json.dumps(expected) + "\n")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="tests/fixtures/scenes")
    out = pathlib.Path(parser.parse_args().out)
    split = out / "bop"
    shutil.rmtree(split, ignore_errors=True)
    for scene_id in SCENES:
        write_scene(split / f"{scene_id:06d}", scene_id)
    categories = {"categories": [{"id": 1, "name": "duck", "supercategory": "toy"}]}
    (split / "categories.json").write_text(json.dumps(categories, indent=2) + "\n")

    write_dataset(out / "bop-dataset")

    bad = out / "bop-bad"
    shutil.rmtree(bad, ignore_errors=True)
    for fault in ["missing-mask", "depth-size", "overlap"]:
        scene = bad / fault / "000000"
        write_scene(scene, 0)
        if fault == "missing-mask":
            (scene / "mask_visib/000001_000002.png").unlink()
        elif fault == "depth-size":
            depth = imageio.imread(scene / "depth/000001.png")
            write_depth(scene / "depth/000001.png", depth[:, :-1].astype(np.float64))
        else:
            # gt 1's visible mask grown onto gt 0's pixels.
            first = imageio.imread(scene / "mask_visib/000000_000000.png")
            second = imageio.imread(scene / "mask_visib/000000_000001.png")
            write_image(scene / "mask_visib/000000_000001.png", np.maximum(first, second))


if __name__ == "__main__":
    main()
