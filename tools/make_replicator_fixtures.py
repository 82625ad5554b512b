#!/usr/bin/env python3
"""Replicator scenes for `vkdiff dataset --scenes`, written as Omniverse Replicator's BasicWriter
writes them.

Replicator (omni.replicator.core) does not install here (it ships with Omniverse / Isaac Sim, not
on the Python package registry), so this script writes the files the way BasicWriter does, read
from its source: omni.replicator.core's scripts/writers_default/basicwriter.py, BasicWriter
`__version__ = "0.0.2"` (the 2025 Apache-2.0 release; a public copy read through the project's
code search). What it follows from there:
  - names: `<annotator>_<frame>` with the frame number zero-padded to `frame_padding` (4 by
    default) and no sequence prefix (no on_time trigger): rgb_0000.png,
    distance_to_image_plane_0000.npy, instance_segmentation_0000.png,
    instance_segmentation_mapping_0000.json, instance_segmentation_semantics_mapping_0000.json,
    camera_params_0000.json, all in the output folder (one render product);
  - rgb: the LdrColor annotator's H×W×4 uint8 array written as an image (RGBA PNG);
  - distance_to_image_plane: the H×W float32 array through np.save (metres; inf where no
    geometry is hit);
  - instance_segmentation with colorize_instance_segmentation=True (the default): the uint32
    ids viewed as H×W×4 uint8 (RGBA PNG); idToLabels (colour key "(R, G, B, A)" → prim path) and
    idToSemantics (colour key → {"class": …}) each written as JSON with every key made a str;
    the reserved entries are BACKGROUND (0, 0, 0, 0) and UNLABELLED (0, 0, 0, 255), in both maps;
  - camera_params: the annotator's dict, numpy arrays made lists, written as JSON
    (cameraProjection and cameraViewTransform: 4×4 flattened, row-vector convention;
    renderProductResolution [W, H]; cameraModel; metersPerSceneUnit; the lens fields);
  - bounding_box_3d (_write_bounding_box_data with bbox_type "3d"): the annotator's structured
    rows through np.save (bounding_box_3d_N.npy), its idToLabels (semanticId → {"class": …})
    and its primPaths (one per row) each through json.dumps (bounding_box_3d_labels_N.json,
    bounding_box_3d_prim_paths_N.json). The rows' dtype and the transform's convention, and
    where they were read, are in tools/replicator_boxes.py.
  Images go through Pillow (Image.fromarray(...).save), .npy through np.save, JSON through
  json.dumps with its defaults, as BasicWriter's functional writers do.
The pixels are drawn here with numpy (ellipses and bars at planar depths, nearest wins); each 3D
box is placed around its drawing (about as wide and tall, its front at the drawn depth, turned),
and the prim's transform carries a scale (centimetres, uneven, a mirror) for some.

Versions used for the committed fixtures: Python 3.11, numpy 2.4.6, Pillow 13.0.0.
Setup and rerun:
  /tmp/ref/bin/pip install numpy pillow
  /tmp/ref/bin/python tools/make_replicator_fixtures.py [--out tests/fixtures/scenes]

Writes under --out:
  replicator/: frames 0000, 0001 and 0002, 80×60, of classes `apple` and `leaf` (prims under
      /World), touching, occluding and cut-off instances, an unlabelled box (UNLABELLED), a sky at
      inf depth (BACKGROUND), a table (UNLABELLED); frames 0000 and 0001 have camera_params (0001
      with an off-centre principal point), 0002 none; frame 0003 is incomplete (its semantics
      mapping not yet written), as BasicWriter leaves a run that is stopped while it writes. Every
      frame has its 3D boxes, the rows in another order than the instances: a row for a prim
      hidden behind another (no instance), none for Leaf_03; the frame without camera_params has
      boxes but no view to pose them.
  replicator-expected.json: what vkdiff should make of each whole frame's rows whose prim is an
      instance, by frame and prim, computed from the rows as saved (float32) with numpy's 4×4
      products: `pose` (object → camera, OpenCV axes, metres; the object's frame is the prim's
      with its scale taken out and a mirror folded into x; null without camera_params),
      `bbox_3d` (metres) and the nine box keypoints, projected through the prim's transform, the
      view and cameraProjection (v 2 where the depth at the pixel floor(u + 0.5), floor(v + 0.5)
      is at least 99 % of the corner's, 1 where nearer, 0 outside or behind), to 1/100 pixel.
  replicator-bad/<fault>/: the frames broken one way each: missing-semantics (frame 0001's
      semantics mapping missing, a frame after it complete), depth-size (frame 0001's depth
      79×60), depth-dtype (frame 0000's depth int32), depth-3d (frame 0000's depth H×W×1),
      unknown-colour (a colour of frame 0000's PNG not in its mapping), mixed (a BlenderProc
      .hdf5 name beside the frames), missing-box (frame 0001's bounding_box_3d_0001.npy missing),
      box-dtype (frame 0000's rows with a float64 transform).
"""
import argparse
import json
import pathlib
import shutil

import numpy as np
from PIL import Image

import replicator_boxes as boxes

WIDTH, HEIGHT = 80, 60
METRES_PER_UNIT = 1.0
BACKGROUND = (0, 0, 0, 0)
UNLABELLED = (0, 0, 0, 255)


def key(colour):
    """A colour as BasicWriter's mapping keys spell it: str() of the RGBA tuple."""
    return str(tuple(int(c) for c in colour))


def write_json(path, data):
    path.write_text(json.dumps(data))


def write_image(path, pixels):
    Image.fromarray(pixels).save(path)


# Per frame: the objects, each (prim path or None for an unlabelled prim, class, colour, shape,
# centre px, radii px, planar depth m).
FRAMES = [
    [
        ("/World/Apple_01", "apple", (230, 25, 75, 255), "ellipse", (22, 34), (10, 9), 2.0),
        ("/World/Apple_02", "apple", (60, 180, 75, 255), "ellipse", (41, 34), (9, 9), 2.05),  # touches
        ("/World/Leaf_01", "leaf", (255, 225, 25, 255), "bar", (34, 44), (20, 3), 1.8),  # occludes both
        ("/World/Apple_03", "apple", (0, 130, 200, 255), "ellipse", (76, 24), (12, 10), 2.3),  # cut off
        (None, None, UNLABELLED, "bar", (60, 48), (6, 5), 2.1),  # an unlabelled box
    ],
    [
        ("/World/Leaf_02", "leaf", (245, 130, 48, 255), "ellipse", (6, 52), (14, 12), 1.6),  # cut off twice
        ("/World/Apple_04", "apple", (145, 30, 180, 255), "ellipse", (40, 26), (9, 8), 2.2),
        ("/World/Leaf_03", "leaf", (70, 240, 240, 255), "bar", (58, 14), (4, 16), 2.1),  # cut by the top
    ],
    [
        ("/World/Apple_05", "apple", (240, 50, 230, 255), "ellipse", (30, 30), (12, 10), 2.4),
        ("/World/Apple_06", "apple", (210, 245, 60, 255), "ellipse", (38, 34), (9, 8), 2.2),  # occludes it
    ],
]

# Camera: focal length and horizontal aperture (mm), aperture offset (mm), world pose.
LENS = [(24.0, 20.955, (0.0, 0.0)), (24.0, 20.955, (0.6, -0.4)), None]


def lens_of(frame):
    """A frame's lens; frames that write no camera_params are still drawn through frame 0's lens
    (their boxes are placed with it)."""
    return LENS[frame] if frame < len(LENS) and LENS[frame] is not None else LENS[0]


# The 3D boxes (bounding_box_3d=True), per frame in the rows' order: prim -> (the prim's scale, a
# negative entry mirroring; its turn in the camera's frame, a rotation vector in rad). Rows are matched to instances by
# prim path: Apple_07 (hidden behind Apple_01, no instance) has a row, Leaf_03 none.
BOXES = [
    {
        "/World/Apple_07": ((1.0, 1.0, 1.0), (0.1, 0.2, 0.0)),
        "/World/Leaf_01": ((2.0, 1.0, 0.5), (0.0, 0.3, 0.6)),
        "/World/Apple_03": ((1.0, 1.0, 1.0), (0.4, -0.2, 0.1)),  # cut off: corners outside
        "/World/Apple_01": ((1.0, 1.0, 1.0), (0.3, 0.5, -0.2)),
        "/World/Apple_02": ((0.01, 0.01, 0.01), (-0.3, 0.2, 0.4)),  # an asset in centimetres
    },
    {
        "/World/Apple_04": ((-1.0, 1.0, 1.0), (0.2, -0.4, 0.3)),  # mirrored
        "/World/Leaf_02": ((1.0, 1.0, 1.0), (-0.2, 0.1, 0.5)),
    },
    {
        "/World/Apple_06": ((1.0, 1.0, 1.0), (0.0, 0.0, 0.2)),
        "/World/Apple_05": ((0.5, 0.5, 0.5), (0.1, 0.1, 0.1)),
    },
]
HIDDEN = [("/World/Apple_07", "apple", None, "ellipse", (22, 34), (5, 4), 2.6)]
SEMANTIC_IDS = {"apple": 3, "leaf": 5}

GRID = np.mgrid[:HEIGHT, :WIDTH].astype(np.float64)


def shape(kind, centre, radii):
    """The pixels an object covers, hidden or not."""
    (yy, xx), (cx, cy), (rx, ry) = GRID, centre, radii
    if kind == "ellipse":
        return ((xx - cx) / rx) ** 2 + ((yy - cy) / ry) ** 2 <= 1
    return (abs(xx - cx) <= rx) & (abs(yy - cy) <= ry)


def draw(objects):
    """Planar depth (m; inf in the sky), the RGBA instance image, each prim's colour, a render."""
    yy, xx = GRID
    sky = yy < 8
    depth = np.where(sky, np.inf, 2.6 - 0.005 * yy).astype(np.float32)
    instance = np.zeros((HEIGHT, WIDTH, 4), np.uint8)
    instance[~sky] = UNLABELLED  # the table carries no semantics
    rgb = np.zeros((HEIGHT, WIDTH, 4), np.uint8)
    rgb[:] = np.where(sky[..., None], [150, 190, 235, 255], [120, 100, 80, 255])
    for _, cls, colour, kind, centre, radii, z in objects:
        inside = shape(kind, centre, radii)
        closer = inside & (depth > z)
        depth[closer] = z + 0.001 * (xx[closer] % 3)
        instance[closer] = colour
        shade = {"apple": [200, 40, 40, 255], "leaf": [40, 160, 60, 255], None: [90, 90, 90, 255]}[cls]
        rgb[closer] = shade
    return depth, instance, rgb


def camera_params(frame):
    """The camera_params annotator's dict for a frame, as BasicWriter writes it."""
    focal, aperture_w, (off_x, off_y) = lens_of(frame)
    aperture_h = aperture_w * HEIGHT / WIDTH
    near, far = 0.01, 1000000.0
    # USD's projection, row-vector convention (transposed OpenGL): the aperture offset shifts the
    # image centre; far is infinite in Replicator's reversed-z matrix.
    projection = np.zeros((4, 4))
    projection[0, 0] = 2 * focal / aperture_w
    projection[1, 1] = 2 * focal / aperture_h
    projection[2, 0] = 2 * off_x / aperture_w
    projection[2, 1] = 2 * off_y / aperture_h
    projection[2, 2] = 0.0
    projection[2, 3] = -1.0
    projection[3, 2] = near
    # The camera in the world (USD camera axes: x right, y up, looking along −z), the view
    # transform its inverse, row-vector convention (translation in the last row).
    rng = np.random.default_rng(frame)
    a, b, c = rng.uniform(-0.4, 0.4, 3)
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    world_from_camera = np.eye(4)
    world_from_camera[:3, :3] = rz @ ry @ rx
    world_from_camera[:3, 3] = rng.uniform(-3, 3, 3)
    view = np.linalg.inv(world_from_camera).T
    params = {
        "cameraAperture": np.array([aperture_w, aperture_h]),
        "cameraApertureOffset": np.array([off_x, off_y]),
        "cameraFisheyeLensP": [],
        "cameraFisheyeLensS": [],
        "cameraFisheyeMaxFOV": 0.0,
        "cameraFisheyeNominalHeight": 0,
        "cameraFisheyeNominalWidth": 0,
        "cameraFisheyeOpticalCentre": np.array([0.0, 0.0]),
        "cameraFisheyePolynomial": np.array([0.0, 0.0, 0.0, 0.0, 0.0]),
        "cameraFocalLength": focal,
        "cameraFocusDistance": 400.0,
        "cameraFStop": 0.0,
        "cameraModel": "pinhole",
        "cameraNearFar": np.array([near, far]),
        "cameraProjection": projection.flatten(),
        "cameraViewTransform": view.flatten(),
        "metersPerSceneUnit": METRES_PER_UNIT,
        "renderProductResolution": np.array([WIDTH, HEIGHT]),
    }
    # BasicWriter's _write_camera_params: ndarrays to lists, the rest as given.
    return {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in params.items()}


def write_boxes(dir, name, objects, placed, camera, instance, depth):
    """bounding_box_3d_N.npy, _labels_N.json and _prim_paths_N.json, as BasicWriter's
    _write_bounding_box_data writes them (np.save of the rows; json.dumps of idToLabels and of
    primPaths); what vkdiff should make of the rows whose prim is an instance, by prim."""
    projection, view, has_camera = camera
    rows, prims = [], []
    for prim, (scale, turn) in placed.items():
        obj = next(o for o in objects + HIDDEN if o[0] == prim)
        lo, hi, transform = boxes.place(obj, scale, turn, projection, view, (WIDTH, HEIGHT))
        covered = shape(*obj[3:6]).sum()
        seen = (instance == obj[2]).all(axis=-1).sum() if obj[2] is not None else 0
        rows.append(boxes.row(SEMANTIC_IDS[obj[1]], lo, hi, transform, 1.0 - seen / covered))
        prims.append(prim)
    np.save(dir / f"bounding_box_3d_{name}.npy", np.array(rows, dtype=boxes.BOX_DTYPE))
    labels = {i: {"class": c} for c, i in SEMANTIC_IDS.items() if any(o[1] == c for o in objects + HIDDEN)}
    write_json(dir / f"bounding_box_3d_labels_{name}.json", labels)
    write_json(dir / f"bounding_box_3d_prim_paths_{name}.json", prims)
    # What vkdiff should read, from the rows as saved (float32).
    expected = {}
    mapped = json.loads((dir / f"instance_segmentation_mapping_{name}.json").read_text()).values()
    for row, prim in zip(np.load(dir / f"bounding_box_3d_{name}.npy"), prims):
        if prim not in mapped:
            continue
        pose, bbox = boxes.expected_pose_and_box(row, view, METRES_PER_UNIT)
        keypoints = [[0.0, 0.0, 0]] * 9
        if has_camera:
            keypoints = boxes.expected_keypoints(row, bbox, projection, view, depth, METRES_PER_UNIT)
        expected[prim] = {"pose": pose if has_camera else None, "bbox_3d": bbox, "keypoints": keypoints}
    return expected


def write_frame(dir, frame, objects, placed, semantics=True):
    """Frame `frame`'s files; what vkdiff should make of its 3D boxes."""
    name = f"{frame:04d}"
    depth, instance, rgb = draw(objects)
    write_image(dir / f"rgb_{name}.png", rgb)
    np.save(dir / f"distance_to_image_plane_{name}.npy", depth)
    write_image(dir / f"instance_segmentation_{name}.png", instance)
    shown = {tuple(c) for c in instance.reshape(-1, 4).tolist()}
    labels = {key(BACKGROUND): "BACKGROUND", key(UNLABELLED): "UNLABELLED"}
    classes = {key(BACKGROUND): {"class": "BACKGROUND"}, key(UNLABELLED): {"class": "UNLABELLED"}}
    for prim, cls, colour, *_ in objects:
        if prim is not None and tuple(colour) in shown:
            labels[key(colour)] = prim
            classes[key(colour)] = {"class": cls}
    write_json(dir / f"instance_segmentation_mapping_{name}.json", labels)
    has_camera = frame < len(LENS) and LENS[frame] is not None
    if has_camera:
        write_json(dir / f"camera_params_{name}.json", camera_params(frame))
    # A frame without camera_params still has its boxes placed through the camera it would have.
    params = camera_params(frame)
    projection, view = (np.array(params[k]).reshape(4, 4) for k in ("cameraProjection", "cameraViewTransform"))
    expected = write_boxes(dir, name, objects, placed, (projection, view, has_camera), instance, depth)
    # BasicWriter schedules the semantics mapping last: a frame is whole once it is there.
    if semantics:
        write_json(dir / f"instance_segmentation_semantics_mapping_{name}.json", classes)
    return expected


def write_set(dir):
    """The frames; what vkdiff should make of the whole frames' 3D boxes, by frame."""
    shutil.rmtree(dir, ignore_errors=True)
    dir.mkdir(parents=True)
    expected = {f"{k:04d}": write_frame(dir, k, objects, BOXES[k]) for k, objects in enumerate(FRAMES)}
    write_frame(dir, len(FRAMES), FRAMES[0], BOXES[0], semantics=False)
    return expected


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="tests/fixtures/scenes")
    out = pathlib.Path(parser.parse_args().out)
    expected = write_set(out / "replicator")
    (out / "replicator-expected.json").write_text(json.dumps(expected) + "\n")

    bad = out / "replicator-bad"
    shutil.rmtree(bad, ignore_errors=True)
    faults = ["missing-semantics", "depth-size", "depth-dtype", "depth-3d", "unknown-colour", "mixed"]
    for fault in faults + ["missing-box", "box-dtype"]:
        dir = bad / fault
        write_set(dir)
        for f in dir.glob("*_0003.*"):  # no incomplete last frame: the fault is the only one
            f.unlink()
        if fault == "missing-semantics":
            (dir / "instance_segmentation_semantics_mapping_0001.json").unlink()
        elif fault == "depth-size":
            depth = np.load(dir / "distance_to_image_plane_0001.npy")
            np.save(dir / "distance_to_image_plane_0001.npy", depth[:, :-1])
        elif fault == "depth-dtype":
            np.save(dir / "distance_to_image_plane_0000.npy", np.zeros((HEIGHT, WIDTH), np.int32))
        elif fault == "depth-3d":
            depth = np.load(dir / "distance_to_image_plane_0000.npy")
            np.save(dir / "distance_to_image_plane_0000.npy", depth[..., None])
        elif fault == "missing-box":
            (dir / "bounding_box_3d_0001.npy").unlink()
        elif fault == "box-dtype":
            # The transform saved as float64: not the annotator's rows.
            rows = np.load(dir / "bounding_box_3d_0000.npy")
            wrong = boxes.BOX_DTYPE.descr
            wrong[7] = ("transform", "<f8", (4, 4))
            np.save(dir / "bounding_box_3d_0000.npy", rows.astype(np.dtype(wrong)))
        elif fault == "unknown-colour":
            instance = np.array(Image.open(dir / "instance_segmentation_0000.png"))
            instance[30:33, 5:8] = (1, 2, 3, 255)
            write_image(dir / "instance_segmentation_0000.png", instance)
        else:
            (dir / "0.hdf5").write_bytes(b"")


if __name__ == "__main__":
    main()
