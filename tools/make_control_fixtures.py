#!/usr/bin/env python3
"""The controls a scene's labels give, computed with numpy alone from the scene fixtures' files
(tests/fixtures/scenes: scene folders and BlenderProc frames, with touching, occluding and cut-off
instances, a ground plane of category 0 and a sky at infinity), for vkdiff's edges, segmentation
and normals to be held to (scenes/tests/controls.rs). Independent of vkdiff's code: the depth and
instance maps are read with the OpenEXR library, Pillow and h5py, and each control is written from
its definition (docs/controls.md).

Versions used to write the committed fixtures: Python 3.11, numpy 2.4.6, Pillow 12.1.0,
OpenEXR 3.5.3, h5py 3.16.0, mmsegmentation 1.2.2 and controlnet_aux 0.0.10 (the ADE20K palette,
read as source text).
  /tmp/ref/bin/pip install numpy pillow OpenEXR h5py && pip install --no-deps mmsegmentation controlnet_aux
  /tmp/ref/bin/python tools/make_control_fixtures.py

Writes tests/fixtures/controls/<format>/<scene>/{edges,normals,segmentation,segmentation_ade}.png
(segmentation_ade with the categories renamed as ADE20K classes: leaf → plant, branch → tree) and
index.json (the settings); and tests/fixtures/controls/normals/<format>/<scene>/normals.png with its
index.json, the normals of the scenes that carry the renderer's own (tests/fixtures/scenes/normals:
BlenderProc's `normals` dataset, a scene folder's normals.exr), from those normals where known and
from the depth elsewhere (`--only-normals` writes these alone; they were written with Pillow
13.0.0, the rest as above)."""
import ast
import colorsys
import importlib.util
import json
import pathlib
import sys
from importlib.metadata import version

import h5py
import numpy as np
import OpenEXR
from PIL import Image

ROOT = pathlib.Path(__file__).resolve().parent.parent
SCENES = ROOT / "tests/fixtures/scenes"
OUT = ROOT / "tests/fixtures/controls"
JUMP = 0.05  # relative depth jump that makes a boundary
FAR = 1e4  # depth at or past this is background (vkdiff's --far default)
ADE_NAMES = {"leaf": "plant", "branch": "tree"}


def ade20k():
    """{class name: RGB} from mmsegmentation's ADE20KDataset, its palette checked against
    controlnet_aux's ade_palette()."""
    def source(package, relative):
        return pathlib.Path(importlib.util.find_spec(package).submodule_search_locations[0]) / relative

    meta = None
    for node in ast.walk(ast.parse(source("mmseg", "datasets/ade.py").read_text())):
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "METAINFO" for t in node.targets):
            meta = {k.arg: ast.literal_eval(k.value) for k in node.value.keywords}
    aux = next(n for n in ast.parse(source("controlnet_aux", "util.py").read_text()).body
               if isinstance(n, ast.FunctionDef) and n.name == "ade_palette")
    assert meta["palette"] == ast.literal_eval(aux.body[-1].value)
    return {name.strip(): tuple(rgb) for name, rgb in zip(meta["classes"], meta["palette"])}


def sequence_colour(k):
    """Hues a golden-ratio turn apart, saturation 0.7, value 0.95."""
    r, g, b = colorsys.hsv_to_rgb((k * 0.618033988749895) % 1.0, 0.7, 0.95)
    return tuple(int(np.floor(c * 255 + 0.5)) for c in (r, g, b))


def colours(categories, palette):
    out, unmatched = {}, 0
    for c in categories:
        key = c["name"].strip().lower().replace("_", " ").replace("-", " ")
        if key in palette:
            out[c["id"]] = palette[key]
        else:
            out[c["id"]] = sequence_colour(unmatched)
            unmatched += 1
    return out


def pairs(shape):
    """(p, q) slices of every pixel with its neighbour at each of the four sides."""
    h, w = shape
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        p = (slice(max(0, -dy), h - max(0, dy)), slice(max(0, -dx), w - max(0, dx)))
        q = (slice(max(0, dy), h - max(0, -dy)), slice(max(0, dx), w - max(0, -dx)))
        yield p, q


def edges(ids, z):
    out = np.zeros(ids.shape, bool)
    for p, q in pairs(ids.shape):
        a, b = z[p], z[q]
        with np.errstate(invalid="ignore", divide="ignore"):
            jump = np.where(a == b, 0.0, np.where(np.isinf(a) | np.isinf(b), np.inf, np.abs(a - b) / np.minimum(a, b)))
        boundary = (ids[p] != ids[q]) | (jump > JUMP)
        front = (a < b) | ((a == b) & (ids[p] > ids[q]))
        out[p] |= boundary & front
    return np.repeat((out * 255).astype(np.uint8)[..., None], 3, axis=2)


def normals(ids, z):
    h, w = ids.shape
    f = 50.0 / 36.0 * max(w, h)  # Blender's default camera: the fixtures carry none
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    zd = z.astype(np.float64)
    with np.errstate(invalid="ignore"):
        P = np.stack([(xs - cx) / f * zd, (ys - cy) / f * zd, zd], axis=2)

    def same(a, b, ia, ib):
        with np.errstate(invalid="ignore"):
            return (ia == ib) & np.isfinite(a) & np.isfinite(b) & (np.abs(a - b) <= JUMP * np.minimum(a, b))

    def tangent(axis):
        n = ids.shape[axis]
        take = lambda arr, s: arr[s, :] if axis == 0 else arr[:, s]
        before = np.zeros(ids.shape, bool)
        after = np.zeros(ids.shape, bool)
        idx = lambda s: (s, slice(None)) if axis == 0 else (slice(None), s)
        before[idx(slice(1, n))] = same(take(z, slice(1, n)), take(z, slice(0, n - 1)),
                                        take(ids, slice(1, n)), take(ids, slice(0, n - 1)))
        after[idx(slice(0, n - 1))] = same(take(z, slice(0, n - 1)), take(z, slice(1, n)),
                                           take(ids, slice(0, n - 1)), take(ids, slice(1, n)))
        prev = np.roll(P, 1, axis=axis)  # wrapped rows and columns are never chosen
        nxt = np.roll(P, -1, axis=axis)
        with np.errstate(invalid="ignore"):  # differences at infinity, never chosen
            t = np.where((before & after)[..., None], nxt - prev,
                         np.where(after[..., None], nxt - P, np.where(before[..., None], P - prev, np.nan)))
        return t, before | after

    tx, okx = tangent(1)
    ty, oky = tangent(0)
    e = np.cross(tx, ty)
    length = np.sqrt((e ** 2).sum(axis=2))
    good = okx & oky & np.isfinite(z) & (length > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.clip((e / length[..., None] + 1.0) * 0.5 * 255.0, 0, 255)
    out = np.empty((h, w, 3), np.uint8)
    out[...] = (127, 127, 255)
    out[good] = c[good].astype(np.uint8)
    return out


def given_normals(ids, z, c):
    """The normals control of a scene that carries the renderer's normals `c` (H×W×3, Blender's
    camera axes: x right, y up, z toward the viewer, as float32): where the depth is finite and the
    normal finite and not zero, (left, up, toward the viewer) = (-c_x, c_y, c_z) made unit length,
    each component stored as floor((e + 1) / 2 * 255); elsewhere the depth's normals."""
    out = normals(ids, z)
    e = np.stack([-c[..., 0], c[..., 1], c[..., 2]], axis=2).astype(np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        length = np.sqrt(e[..., 0] * e[..., 0] + e[..., 1] * e[..., 1] + e[..., 2] * e[..., 2])
        known = np.isfinite(z) & np.isfinite(e).all(axis=2) & (length > 0)
        colour = np.clip((e / length[..., None] + 1.0) * 0.5 * 255.0, 0, 255)
    out[known] = colour[known].astype(np.uint8)
    return out


def write_given_normals():
    """controls/normals/: the scenes of scenes/normals, read as BlenderProc and a scene folder
    store their normals."""
    root = SCENES / "normals"
    for scene in sorted((root / "folders").iterdir()):
        meta = json.loads((scene / "categories.json").read_text())
        category_of = {int(k): v for k, v in meta["instances"].items()}
        labels = np.asarray(Image.open(scene / "instances.png")).astype(np.int64)
        ids, z = labelled(labels, read_exr_depth(scene / "depth.exr"), category_of)
        with OpenEXR.File(str(scene / "normals.exr")) as f:
            c = np.stack([np.asarray(f.channels()[k].pixels, np.float32) for k in "XYZ"], axis=2)
        out = OUT / "normals/folders" / scene.name
        out.mkdir(parents=True, exist_ok=True)
        Image.fromarray(given_normals(ids, z, c)).save(out / "normals.png")
    for frame in sorted((root / "blenderproc").glob("*.hdf5")):
        with h5py.File(frame) as f:
            labels = np.asarray(f["instance_segmaps"]).astype(np.int64)
            depth = np.asarray(f["depth"])
            attributes = json.loads(np.asarray(f["instance_attribute_maps"]).item())
            stored = np.asarray(f["normals"], np.float32)
        # enable_normals_output stores each component c as (c + 1) / 2; vkdiff undoes it in f32.
        c = np.float32(2) * stored - np.float32(1)
        ids, z = labelled(labels, depth, {a["idx"]: a["category_id"] for a in attributes})
        out = OUT / "normals/blenderproc" / frame.stem
        out.mkdir(parents=True, exist_ok=True)
        Image.fromarray(given_normals(ids, z, c)).save(out / "normals.png")
    index = {"depth_jump": JUMP, "far": FAR, "camera": "Blender's default: 50 mm lens, 36 mm sensor on the longer side",
             "versions": {p: version(p) for p in ("numpy", "Pillow", "OpenEXR", "h5py")}}
    (OUT / "normals/index.json").write_text(json.dumps(index, indent=1) + "\n")


def segmentation(ids, category_of_id, colour_of):
    out = np.zeros(ids.shape + (3,), np.uint8)
    for i in np.unique(ids):
        if i != 0:
            out[ids == i] = colour_of[category_of_id[int(i)]]
    return out


def labelled(labels, depth, category_of):
    """The scene as vkdiff's readers give it: depth past FAR, non-finite or non-positive is +inf,
    instances of category 0 are background."""
    z = depth.astype(np.float32)
    z = np.where(~np.isfinite(z) | (z <= 0) | (z >= FAR), np.float32(np.inf), z)
    keep = np.vectorize(lambda l: l != 0 and category_of[int(l)] != 0)(labels) if labels.size else labels
    return np.where(keep, labels, 0), z


def write(out_dir, ids, z, category_of, categories, palette):
    out_dir.mkdir(parents=True, exist_ok=True)
    Image.fromarray(edges(ids, z)).save(out_dir / "edges.png")
    Image.fromarray(normals(ids, z)).save(out_dir / "normals.png")
    Image.fromarray(segmentation(ids, category_of, colours(categories, palette))).save(out_dir / "segmentation.png")
    renamed = [dict(c, name=ADE_NAMES.get(c["name"], c["name"])) for c in categories]
    Image.fromarray(segmentation(ids, category_of, colours(renamed, palette))).save(out_dir / "segmentation_ade.png")


def read_exr_depth(path):
    with OpenEXR.File(str(path)) as f:
        channels = f.channels()
        name = "Z" if "Z" in channels else next(iter(channels))
        return np.asarray(channels[name].pixels, np.float32)


def main():
    if "--only-normals" in sys.argv[1:]:
        write_given_normals()
        print("wrote", OUT / "normals")
        return
    palette = ade20k()
    for scene in sorted((SCENES / "folders").iterdir()):
        meta = json.loads((scene / "categories.json").read_text())
        category_of = {int(k): v for k, v in meta["instances"].items()}
        labels = np.asarray(Image.open(scene / "instances.png")).astype(np.int64)
        if (scene / "depth.exr").exists():
            depth = read_exr_depth(scene / "depth.exr")
        else:
            scale = json.loads((scene / "depth.json").read_text())
            raw = np.asarray(Image.open(scene / "depth.png")).astype(np.float64)
            depth = np.where(raw == 0, np.inf, raw * scale["scale"] + scale.get("offset", 0.0))
        ids, z = labelled(labels, depth, category_of)
        write(OUT / "folders" / scene.name, ids, z, category_of, meta["categories"], palette)
    # The set's categories are every frame's, named by categories.json: colours are the set's.
    names = json.loads((SCENES / "blenderproc/categories.json").read_text())["categories"]
    frames = []
    for frame in sorted((SCENES / "blenderproc").glob("*.hdf5")):
        with h5py.File(frame) as f:
            labels = np.asarray(f["instance_segmaps"]).astype(np.int64)
            depth = np.asarray(f["depth"])
            attributes = json.loads(np.asarray(f["instance_attribute_maps"]).item())
        frames.append((frame.stem, labels, depth, {a["idx"]: a["category_id"] for a in attributes}))
    used = sorted({c for *_, category_of in frames for c in category_of.values() if c != 0})
    categories = [next((n for n in names if n["id"] == c), {"id": c, "name": f"category_{c}"}) for c in used]
    for stem, labels, depth, category_of in frames:
        ids, z = labelled(labels, depth, category_of)
        write(OUT / "blenderproc" / stem, ids, z, category_of, categories, palette)
    index = {"depth_jump": JUMP, "far": FAR, "camera": "Blender's default: 50 mm lens, 36 mm sensor on the longer side",
             "ade_names": ADE_NAMES,
             "versions": {p: version(p) for p in ("numpy", "Pillow", "OpenEXR", "h5py", "mmsegmentation", "controlnet_aux")}}
    (OUT / "index.json").write_text(json.dumps(index, indent=1) + "\n")
    write_given_normals()
    print("wrote", OUT)


main()
