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
    renderProductResolution [W, H]; cameraModel; metersPerSceneUnit; the lens fields).
  Images go through Pillow (Image.fromarray(...).save), .npy through np.save, JSON through
  json.dumps with its defaults, as BasicWriter's functional writers do.
The pixels are drawn here with numpy (ellipses and bars at planar depths, nearest wins).

Versions used for the committed fixtures: Python 3.11, numpy 2.4.6, Pillow 13.0.0.
Setup and rerun:
  /tmp/ref/bin/pip install numpy pillow
  /tmp/ref/bin/python tools/make_replicator_fixtures.py [--out tests/fixtures/scenes]

Writes under --out:
  replicator/: frames 0000, 0001 and 0002, 80×60, of classes `apple` and `leaf` (prims under
      /World), touching, occluding and cut-off instances, an unlabelled box (UNLABELLED), a sky at
      inf depth (BACKGROUND), a table (UNLABELLED); frames 0000 and 0001 have camera_params (0001
      with an off-centre principal point), 0002 none; frame 0003 is incomplete (its semantics
      mapping not yet written), as BasicWriter leaves a run that is stopped while it writes.
  replicator-bad/<fault>/: the frames broken one way each: missing-semantics (frame 0001's
      semantics mapping missing, a frame after it complete), depth-size (frame 0001's depth
      79×60), depth-dtype (frame 0000's depth int32), depth-3d (frame 0000's depth H×W×1),
      unknown-colour (a colour of frame 0000's PNG not in its mapping), mixed (a BlenderProc
      .hdf5 name beside the frames).
"""
import argparse
import json
import pathlib
import shutil

import numpy as np
from PIL import Image

WIDTH, HEIGHT = 80, 60
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


def draw(objects):
    """Planar depth (m; inf in the sky), the RGBA instance image, each prim's colour, a render."""
    yy, xx = np.mgrid[:HEIGHT, :WIDTH].astype(np.float64)
    sky = yy < 8
    depth = np.where(sky, np.inf, 2.6 - 0.005 * yy).astype(np.float32)
    instance = np.zeros((HEIGHT, WIDTH, 4), np.uint8)
    instance[~sky] = UNLABELLED  # the table carries no semantics
    rgb = np.zeros((HEIGHT, WIDTH, 4), np.uint8)
    rgb[:] = np.where(sky[..., None], [150, 190, 235, 255], [120, 100, 80, 255])
    for _, cls, colour, kind, (cx, cy), (rx, ry), z in objects:
        if kind == "ellipse":
            inside = ((xx - cx) / rx) ** 2 + ((yy - cy) / ry) ** 2 <= 1
        else:
            inside = (abs(xx - cx) <= rx) & (abs(yy - cy) <= ry)
        closer = inside & (depth > z)
        depth[closer] = z + 0.001 * (xx[closer] % 3)
        instance[closer] = colour
        shade = {"apple": [200, 40, 40, 255], "leaf": [40, 160, 60, 255], None: [90, 90, 90, 255]}[cls]
        rgb[closer] = shade
    return depth, instance, rgb


def camera_params(frame):
    """The camera_params annotator's dict for a frame, as BasicWriter writes it."""
    focal, aperture_w, (off_x, off_y) = LENS[frame]
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
        "metersPerSceneUnit": 1.0,
        "renderProductResolution": np.array([WIDTH, HEIGHT]),
    }
    # BasicWriter's _write_camera_params: ndarrays to lists, the rest as given.
    return {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in params.items()}


def write_frame(dir, frame, objects, semantics=True):
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
    if frame < len(LENS) and LENS[frame] is not None:
        write_json(dir / f"camera_params_{name}.json", camera_params(frame))
    # BasicWriter schedules the semantics mapping last: a frame is whole once it is there.
    if semantics:
        write_json(dir / f"instance_segmentation_semantics_mapping_{name}.json", classes)


def write_set(dir):
    shutil.rmtree(dir, ignore_errors=True)
    dir.mkdir(parents=True)
    for frame, objects in enumerate(FRAMES):
        write_frame(dir, frame, objects)
    write_frame(dir, len(FRAMES), FRAMES[0], semantics=False)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="tests/fixtures/scenes")
    out = pathlib.Path(parser.parse_args().out)
    write_set(out / "replicator")

    bad = out / "replicator-bad"
    shutil.rmtree(bad, ignore_errors=True)
    for fault in ["missing-semantics", "depth-size", "depth-dtype", "depth-3d", "unknown-colour", "mixed"]:
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
        elif fault == "unknown-colour":
            instance = np.array(Image.open(dir / "instance_segmentation_0000.png"))
            instance[30:33, 5:8] = (1, 2, 3, 255)
            write_image(dir / "instance_segmentation_0000.png", instance)
        else:
            (dir / "0.hdf5").write_bytes(b"")


if __name__ == "__main__":
    main()
