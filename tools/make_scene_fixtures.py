#!/usr/bin/env python3
"""Scenes rendered "elsewhere" for `vkdiff dataset --scenes`: scene folders as a renderer of one's
own writes them (OpenEXR through the OpenEXR library, PNGs through Pillow), and BlenderProc frames
as BlenderProc's `write_hdf5` writes them (h5py, gzip datasets, the attribute maps as a JSON byte
string), drawn here with numpy: an orchard of apples, leaves and branches that touch and occlude,
a sky at infinite depth, objects cut by the frame's edges.

Versions used to write the committed fixtures: Python 3.11, numpy 2.4.6, Pillow 12.1.0,
OpenEXR 3.5.3, h5py 3.16.0.
Setup and rerun:
  python3 -m venv /tmp/ref && /tmp/ref/bin/pip install numpy pillow OpenEXR h5py
  /tmp/ref/bin/python tools/make_scene_fixtures.py [--out tests/fixtures/scenes]

Writes under --out:
  folders/<name>/: depth.exr (or depth.png + depth.json), instances.png (16-bit, or 8-bit),
      categories.json, and in some shaded.png and prompt.txt; frames of two sizes.
  blenderproc/0.hdf5, 1.hdf5: `colors`, `depth` (background 1e10, as BlenderProc writes it),
      `instance_segmaps` (int32: the instance idx), `instance_attribute_maps` (idx, category_id,
      name; the ground plane is category 0, background) and `blender_proc_version`;
      categories.json beside them with the category names.
  blenderproc-bad/<fault>/0.hdf5: frames broken one way each (a dataset missing, shapes that
      disagree, an idx listed twice, attributes that are not JSON, a stereo pair in one file, a
      file cut short), for the refusals (`--only-broken` writes these alone).
  expected.json: what each scene holds, for the tests: its size, and each instance id with its
      category and pixel count.
  normals/: scenes that carry the renderer's own normals (`--only-normals` writes these alone):
      blenderproc/0.hdf5, 1.hdf5 (the frames of blenderproc/ with a `normals` dataset as
      bproc.renderer.enable_normals_output and write_hdf5 give it: H×W×3 float32, gzip, Blender's
      camera axes, each component c stored as (c + 1) / 2, 0.5 where nothing was hit; frame 1
      with a patch of 0.5, normals unknown), folders/orchard-n/ (a scene folder with normals.exr:
      float channels X, Y, Z, Blender's camera axes, zero in the sky, NaN in a patch), and
      blenderproc-bad/normals-shape/0.hdf5 (a stereo pair's normals, 2×H×W×3, in a frame of one
      view).
"""
import argparse
import json
import pathlib
import shutil

import h5py
import numpy as np
import OpenEXR
from PIL import Image

CATEGORIES = [
    {"id": 1, "name": "apple", "supercategory": "fruit"},
    {"id": 2, "name": "leaf", "supercategory": "plant"},
    {"id": 3, "name": "branch", "supercategory": "plant"},
]
SKY = np.inf


def draw(width, height, seed, shapes):
    """Paints `shapes` (kind, category, centre, size, depth) far to near: depth and instance ids,
    with the ground plane behind everything below the horizon and sky (infinite depth) above."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:height, :width].astype(np.float64)
    horizon = height // 4
    depth = np.where(yy < horizon, SKY, 3.0 + 4.0 * (height - yy) / height).astype(np.float32)
    ids = np.zeros((height, width), np.uint16)
    colors = np.zeros((height, width, 3), np.uint8)
    colors[:] = np.where((yy < horizon)[..., None], [150, 190, 235], [90, 70, 50]).astype(np.uint8)
    order = sorted(range(len(shapes)), key=lambda k: -shapes[k][4])
    categories = {}
    for k in order:
        kind, category, (cx, cy), (rx, ry), z = shapes[k]
        if kind == "ellipse":
            inside = ((xx - cx) / rx) ** 2 + ((yy - cy) / ry) ** 2 <= 1
        else:  # a bar: a branch
            inside = (abs(xx - cx) <= rx) & (abs(yy - cy) <= ry)
        inside &= depth > z
        instance = 3 * k + 2  # ids with gaps, as renderers number objects
        ids[inside] = instance
        depth[inside] = z + rng.uniform(0, 0.01, inside.sum()).astype(np.float32)
        colors[inside] = {1: [200, 30, 40], 2: [40, 150, 50], 3: [110, 80, 40]}[category]
        categories[instance] = category
    return depth, ids, colors, categories


def normals_of(width, height, shapes, ids):
    """The surface normal under each pixel of a scene `draw` painted, in Blender's camera axes (x
    right, y up, z toward the viewer): the ground tilted up toward the camera, apples as spheres,
    leaves as planes tilted each its own way, branches as cylinders lying along x; zero in the
    sky. Uses no random numbers, so the scenes drawn are the same with or without it."""
    yy, xx = np.mgrid[:height, :width].astype(np.float64)
    n = np.zeros((height, width, 3))
    n[yy >= height // 4] = (0.0, np.cos(np.radians(35)), np.sin(np.radians(35)))
    for k, (kind, category, (cx, cy), (rx, ry), _) in enumerate(shapes):
        inside = ids == 3 * k + 2
        dx, dy = (xx - cx) / rx, (yy - cy) / ry
        if kind == "bar":
            dx = np.zeros_like(dx)
        if category == 2:
            t = 0.7 * k
            v = np.broadcast_to((0.45 * np.sin(t), 0.35 * np.cos(t), 0.8), n.shape)
        else:
            v = np.stack([dx, -dy, np.sqrt(np.clip(1 - dx * dx - dy * dy, 0, 1))], axis=2)
        n[inside] = v[inside]
    length = np.sqrt((n ** 2).sum(axis=2, keepdims=True))
    return np.where(length > 0, n / np.where(length > 0, length, 1), 0)


def orchard_shapes(width, height, seed, count):
    rng = np.random.default_rng(seed)
    shapes = [("bar", 3, (width * 0.5, height * 0.55), (width * 0.45, 3.0), 1.9)]
    for _ in range(count):
        category = int(rng.choice([1, 1, 2]))
        r = rng.uniform(6, 14) if category == 1 else rng.uniform(4, 8)
        shapes.append(("ellipse", category, (rng.uniform(-5, width + 5), rng.uniform(height * 0.2, height + 5)),
                       (r, r if category == 1 else 2.2 * r), rng.uniform(1.0, 2.5)))
    return shapes


def orchard(width, height, seed, count):
    return draw(width, height, seed, orchard_shapes(width, height, seed, count))


def write_exr(path, depth, channel):
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {channel: depth.astype(np.float32)}).write(str(path))


def summary(ids, categories):
    present = {int(i): int((ids == i).sum()) for i in np.unique(ids) if i != 0}
    return {str(i): {"category_id": categories[i], "pixels": n} for i, n in sorted(present.items())}


def folders(out, expected):
    root = out / "folders"
    specs = [
        # name, width, height, seed, objects, depth as, instances bits, shaded, prompt
        ("orchard-a", 160, 128, 1, 14, "exr Z", 16, True, "ripe red apples among green leaves on a branch"),
        ("orchard-b", 160, 128, 2, 18, "exr ViewLayer.Depth.Z", 8, False, None),
        ("orchard-c", 192, 144, 3, 22, "png", 16, True, None),
    ]
    for name, w, h, seed, n, depth_as, bits, shaded, prompt in specs:
        d = root / name
        d.mkdir(parents=True)
        depth, ids, colors, categories = orchard(w, h, seed, n)
        if depth_as == "png":
            scale = 0.001  # millimetres; 0 is background
            Image.fromarray(np.where(np.isinf(depth), 0, np.round(depth / scale)).astype(np.uint16)).save(d / "depth.png")
            (d / "depth.json").write_text(json.dumps({"scale": scale, "offset": 0.0}) + "\n")
        else:
            write_exr(d / "depth.exr", depth, depth_as.split(" ")[1])
        Image.fromarray(ids.astype(np.uint8) if bits == 8 else ids).save(d / "instances.png")
        (d / "categories.json").write_text(json.dumps(
            {"categories": CATEGORIES, "instances": {str(i): c for i, c in sorted(categories.items())}}, indent=1) + "\n")
        if shaded:
            Image.fromarray(colors).save(d / "shaded.png")
        if prompt:
            (d / "prompt.txt").write_text(prompt + "\n")
        expected["folders"][name] = {"width": w, "height": h, "instances": summary(ids, categories)}


def blenderproc_frame(seed):
    """A BlenderProc frame's outputs, as bproc.renderer.render() gives them, and its scene."""
    shapes = orchard_shapes(144, 112, seed, 16)
    depth, ids, colors, categories = draw(144, 112, seed, shapes)
    ground = 1  # BlenderProc's ground plane: an object of category 0
    segmap = ids.astype(np.int32)
    segmap[(segmap == 0) & np.isfinite(depth)] = ground
    # enable_normals_output's encoding: each camera-space component c as (c + 1) / 2, so the
    # background, where the Normal pass is zero, is 0.5.
    normals = (normals_of(144, 112, shapes, ids) * 0.5 + 0.5).astype(np.float32)
    depth = np.where(np.isinf(depth), 1e10, depth).astype(np.float32)  # its far value
    attributes = [{"idx": 0, "category_id": 0, "name": "World"}, {"idx": ground, "category_id": 0, "name": "Plane"}]
    attributes += [{"idx": int(i), "category_id": c, "name": f"{['', 'Apple', 'Leaf', 'Branch'][c]}.{i:03d}"}
                   for i, c in sorted(categories.items())]
    data = {"colors": colors, "depth": depth, "instance_segmaps": segmap, "instance_attribute_maps": attributes}
    return data, normals, ids, categories


def write_hdf5(path, data):
    """As blenderproc/python/writer/WriterUtility.py writes each output: arrays as gzip datasets,
    lists of dicts as one JSON byte string, then its version."""
    with h5py.File(path, "w") as f:
        for key, value in data.items():
            if isinstance(value, np.ndarray):
                f.create_dataset(key, data=value, compression="gzip")
            else:
                f.create_dataset(key, data=np.bytes_(json.dumps(value)))
        f.create_dataset("blender_proc_version", data=np.bytes_("2.8.0"))


def blenderproc(out, expected):
    root = out / "blenderproc"
    root.mkdir(parents=True)
    for frame, seed in enumerate([4, 5]):
        data, _, ids, categories = blenderproc_frame(seed)
        write_hdf5(root / f"{frame}.hdf5", data)
        expected["blenderproc"][f"{frame}.hdf5"] = {"width": 144, "height": 112, "instances": summary(ids, categories)}
    (root / "categories.json").write_text(json.dumps({"categories": CATEGORIES}, indent=1) + "\n")


def with_normals(out):
    """Scenes that carry the renderer's normals: BlenderProc frames, a scene folder, a broken frame."""
    root = out / "normals"
    if root.exists():
        shutil.rmtree(root)
    (root / "blenderproc").mkdir(parents=True)
    for frame, seed in enumerate([4, 5]):
        data, normals, _, _ = blenderproc_frame(seed)
        if frame == 1:
            normals[60:80, 20:70] = 0.5  # no normal: the depth's are used there
        write_hdf5(root / "blenderproc" / f"{frame}.hdf5", dict(data, normals=normals))
    (root / "blenderproc/categories.json").write_text(json.dumps({"categories": CATEGORIES}, indent=1) + "\n")
    d = root / "folders/orchard-n"
    d.mkdir(parents=True)
    shapes = orchard_shapes(160, 128, 6, 16)
    depth, ids, _, categories = draw(160, 128, 6, shapes)
    n = normals_of(160, 128, shapes, ids).astype(np.float32)
    n[70:90, 100:150] = np.nan  # unknown: the depth's are used there
    write_exr(d / "depth.exr", depth, "Z")
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {c: np.ascontiguousarray(n[..., k]) for k, c in enumerate("XYZ")}).write(str(d / "normals.exr"))
    Image.fromarray(ids).save(d / "instances.png")
    (d / "categories.json").write_text(json.dumps(
        {"categories": CATEGORIES, "instances": {str(i): c for i, c in sorted(categories.items())}}, indent=1) + "\n")
    bad = root / "blenderproc-bad/normals-shape"
    bad.mkdir(parents=True)
    data, normals, _, _ = blenderproc_frame(9)
    write_hdf5(bad / "0.hdf5", dict(data, normals=np.stack([normals, normals])))


def blenderproc_bad(out):
    """One folder per way a BlenderProc frame can be broken, each holding a 0.hdf5 written as
    BlenderProc writes its files, but for the one fault, and a copy of a good frame cut short."""
    root = out / "blenderproc-bad"
    if root.exists():
        shutil.rmtree(root)
    depth, ids, colors, categories = orchard(48, 40, 9, 4)
    depth = np.where(np.isinf(depth), 1e10, depth).astype(np.float32)
    good = [{"idx": 0, "category_id": 0, "name": "World"}]
    good += [{"idx": int(i), "category_id": c} for i, c in sorted(categories.items())]
    twice = good + [good[-1]]
    cases = {
        "no-segmaps": {"depth": depth, "instance_attribute_maps": good},
        "no-depth": {"instance_segmaps": ids.astype(np.int32), "instance_attribute_maps": good},
        "depth-shape": {"depth": depth[:-1], "instance_segmaps": ids.astype(np.int32), "instance_attribute_maps": good},
        "idx-twice": {"depth": depth, "instance_segmaps": ids.astype(np.int32), "instance_attribute_maps": twice},
        "attributes-not-json": {"depth": depth, "instance_segmaps": ids.astype(np.int32),
                                "instance_attribute_maps": "{idx: 1"},
        "stereo": {"depth": depth, "instance_segmaps": np.stack([ids, ids]).astype(np.int32),
                   "instance_attribute_maps": good},
    }
    for name, datasets in cases.items():
        (root / name).mkdir(parents=True)
        with h5py.File(root / name / "0.hdf5", "w") as f:
            for key, value in datasets.items():
                if isinstance(value, np.ndarray):
                    f.create_dataset(key, data=value, compression="gzip")
                else:
                    text = value if isinstance(value, str) else json.dumps(value)
                    f.create_dataset(key, data=np.bytes_(text))
    whole = (root / "idx-twice" / "0.hdf5").read_bytes()
    (root / "truncated").mkdir()
    (root / "truncated" / "0.hdf5").write_bytes(whole[: len(whole) // 2])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="tests/fixtures/scenes")
    ap.add_argument("--only-broken", action="store_true", help="write blenderproc-bad/ alone")
    ap.add_argument("--only-normals", action="store_true", help="write normals/ alone")
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    if args.only_broken:
        blenderproc_bad(out)
        return
    if args.only_normals:
        with_normals(out)
        return
    if out.exists():
        shutil.rmtree(out)
    expected = {"categories": CATEGORIES, "folders": {}, "blenderproc": {}}
    folders(out, expected)
    blenderproc(out, expected)
    blenderproc_bad(out)
    with_normals(out)
    (out / "expected.json").write_text(json.dumps(expected, indent=1) + "\n")
    print("wrote", out)


if __name__ == "__main__":
    main()
