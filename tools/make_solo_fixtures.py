#!/usr/bin/env python3
"""Unity Perception SOLO datasets for `vkdiff dataset --scenes`, written as Perception's SOLO
endpoint writes them.

Unity does not install here, so this script writes the files the way com.unity.perception does,
read from its source: Unity-Technologies/com.unity.perception at commit
7e3d4c95aa078cf959cd4febf3051cfb812f4bcd (package.json "version": "1.0.0-preview.1"), checked
against the SOLO sample in Unity-Technologies/pysolotools at commit
7536cea09f676add68a0b781591125cfb9926c82 (tests/data/solo, written by Perception 0.10) and read
back with pysolotools 0.3.17 (PyPI). What it follows from there (paths under
com.unity.perception/Runtime/GroundTruth/):
  - layout (Consumers/Solo/SoloEndpoint.cs, SoloMessageBuilder.cs): sequence.<K>/ per scenario
    iteration; per step M, step<M>.frame_data.json (unpadded) written after every file it names;
    files `step<M>.<key>.<ext>` with key the sensor id for the RGB capture (step0.camera.png) and
    `<sensor id>.<annotation id>` for image annotations (step0.camera.instance segmentation.png,
    step0.camera.Depth.exr); metadata.json, annotation_definitions.json, metric_definitions.json and
    sensor_definitions.json at the root, written when the simulation ends. JSON through
    Newtonsoft, Formatting.Indented (two spaces), keys in the order the ToMessage methods add them,
    nested arrays last;
  - the capture (DataModel/Sensor.cs, RgbSensor.cs, PerceptionCamera.cs RegisterNewCapture):
    position (world, metres), rotation as a quaternion written x, y, z, w
    (MessageBuilderUtils.ToFloatVector(Quaternion)), dimension [W, H] as floats, projection
    "Perspective" (UnityCameraSensor; "Isometric" when orthographic), and matrix: the upper-left
    3×3 of Camera.projectionMatrix (UnityCameraSensor.Matrix4X4ToMatrix3X3) written column by
    column, c0.x, c0.y, c0.z, c1.x, … (SoloMessageBuilder.AddTensor, "matrix");
  - InstanceSegmentationAnnotation: an 8-bit RGBA PNG, each labelled object in the colour
    Utilities/InstanceIdToColorMapping.cs gives its instance id (golden-ratio hues, alpha 255),
    everything else (no object, or an object without a Labeling) instance index 0, whose colour
    is (0, 0, 0, 255) (LabelManager: instanceSegmentationColors[0]); `instances` lists
    {instanceId, labelId, labelName, color} of the rendered objects whose label the labeler's
    IdLabelConfig holds (StartingLabelId.One: ids from 1);
  - DepthAnnotation (Labelers/Depth, Sensors/Channels/DepthChannel.cs, Shaders/Depth.shader): an
    R32G32B32A32 float EXR, ZIP-compressed (ImageEncoding/ImageEncoder.cs: CompressZIP |
    OutputAsFloat), channels R, G, B, A = (camera-space z in metres, 0, 0, 1) where geometry is
    drawn, (0, 0, 0, 0) elsewhere (the channel's clear colour); measurementStrategy "Depth", or
    "Range" (Shaders/Range.shader: the distance to the camera in R);
  - NormalAnnotation (Labelers/Normal, Sensors/Channels/VertexNormalsChannel.cs,
    ComputeShaders/WorldToSensorNormals.compute): RGBA float EXR, the world normal turned into
    the camera transform's frame, each component c written (c + 1) / 2, then z as 1 − z; the
    background (0, 0, 0, 1);
  - BoundingBox3DAnnotation (Labelers/BoundingBox3D/BoundingBox3DLabeler.cs): per visible labelled
    object, translation = the centre of its meshes' bounds (in its own frame) in the camera
    transform's frame (x right, y up, z forward; left-handed), size = the bounds' size times the
    object's scale, rotation = Quaternion.Inverse(camera.rotation) * object.rotation (x, y, z, w);
  - BoundingBox2DAnnotation and SemanticSegmentationAnnotation as their ToMessage methods write
    them (the reader does not use them; they are here because a dataset has them).
The scenes are drawn here with numpy as a renderer would: every pixel centre is unprojected
through the inverse of Unity's 4×4 projection (OpenGL's clip space, NDC [−1, 1] spanning the
pixel edges, rows written top first), cast into the world and hit against oriented boxes (the
nearest wins); quaternions are applied as Unity's Quaternion * Vector3 applies them. EXRs are
written with the OpenEXR library (RGBA FLOAT, ZIP), PNGs with Pillow, JSON with json.dumps
(indent 2; floats rounded to float32's nine digits, as the C# floats are).

Versions used for the committed fixtures: Python 3.11, numpy 2.4.6, Pillow 13.0.0, OpenEXR 3.5.3.
Setup and rerun:
  /tmp/ref/bin/pip install numpy pillow OpenEXR
  /tmp/ref/bin/python tools/make_solo_fixtures.py [--out tests/fixtures/scenes]
Read back with Unity's own reader (by hand; pysolotools pins pandas~=1.4.3, which does not build
on Python 3.11, so it goes in a venv of its own without its pins; its FramesIterator assumes every
sequence has totalFrames / totalSequences steps, as the fixture's do):
  python3 -m venv /tmp/solo_venv && /tmp/solo_venv/bin/pip install --no-deps pysolotools==0.3.17
  /tmp/solo_venv/bin/pip install "dataclasses-json~=0.5.7" pandas numpy pillow tqdm
  /tmp/solo_venv/bin/python -c "from pysolotools.consumers import Solo
  for f in Solo('tests/fixtures/scenes/solo').frames(): print(f.sequence, f.step, len(f.captures))"
  (2026-12-05: all four steps, five RGBCameraCaptures, each annotation parsed as its typed class.)

Writes under --out:
  solo/: a SOLO dataset, 48×40, labels Crate (labelId 1), Cube (2, never seen) and Box (3), an
      unlabelled floor and an empty sky: sequence.0/step0 (touching, occluding and cut-off
      objects, normals, Depth), sequence.0/step1 (the camera moved, an off-centre principal point:
      the matrix's c2.x, c2.y), sequence.1/step0 (two cameras, `camera` with Range depth, and
      `camera2`, whose instance image leaves the sky (0, 0, 0, 0)), sequence.1/step1 (the camera
      moved); the root's JSON files, as a finished simulation writes them.
  solo-stopped/: the same as a run stopped while writing sequence.1/step1 leaves it: that step's
      images written, its frame_data.json not, and none of the root's JSON files.
  solo-bad/<fault>/: the dataset (sequence.0 only, but for label-clash) broken one way each: missing-png (sequence.0/step1's instance
      PNG removed), wrong-size (sequence.0/step0's instance PNG 47×40), unknown-colour (a pixel of
      sequence.0/step0's instance PNG in a colour its instances do not list), bad-json
      (sequence.0/step1's frame_data.json cut short), no-depth (sequence.0/step0 without its
      DepthAnnotation), label-clash (labelId 1 named `Crate` in one step and `Barrel` in
      another), mixed (a BlenderProc .hdf5 name beside the sequences).
"""
import argparse
import colorsys
import json
import math
import pathlib
import shutil

import Imath
import numpy as np
import OpenEXR
from PIL import Image

WIDTH, HEIGHT = 48, 40
NEAR, FAR = 0.3, 1000.0
SKY = (0, 0, 0, 255)
PERCEPTION_VERSION = "1.0.0-preview.1"
SOLO = "type.unity.com/unity.solo."
LABELS = [(1, "Crate"), (2, "Cube"), (3, "Box")]
LABEL_COLOURS = {"Crate": (255, 120, 0, 255), "Cube": (0, 200, 255, 255), "Box": (120, 0, 255, 255)}


def f32(v):
    """A float as Newtonsoft writes a C# float: float32's value, nine significant digits."""
    return float(f"{float(np.float32(v)):.9g}")


def floats(values):
    return [f32(v) for v in values]


# --- Unity's quaternions (x, y, z, w), Hamilton products, as Quaternion * Vector3 rotates.


def axis_angle(axis, degrees):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    half = math.radians(degrees) / 2
    return np.array([*(axis * math.sin(half)), math.cos(half)])


def qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ])


def qinv(q):
    return np.array([-q[0], -q[1], -q[2], q[3]])


def qmatrix(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def rotation(*turns):
    """Turns applied in order (the first innermost), each (axis, degrees)."""
    q = np.array([0.0, 0.0, 0.0, 1.0])
    for axis, degrees in turns:
        q = qmul(axis_angle(axis, degrees), q)
    return q


# --- InstanceIdToColorMapping.GenerateHSLValueForId (ids 1..1024).


def instance_colour(instance_id):
    count = instance_id - 1
    golden = np.float32((1 + math.sqrt(5)) / 2)
    ratio = np.float32(count % 64) * golden
    hue = float(ratio - np.floor(ratio))
    value = 1 - (count // 64) / (1024 // 64 + 1)
    r, g, b = colorsys.hsv_to_rgb(hue, 1.0, value)
    return tuple(int(round(c * 255)) for c in (r, g, b)) + (255,)


class Box:
    """An object with a box mesh: pivot `position`, `rotation`, `scale`, and its mesh's bounds
    (`centre`, `size`) in its own frame; `label` None for an unlabelled object."""

    def __init__(self, instance_id, label, position, rotation, scale=(1, 1, 1), centre=(0, 0, 0), size=(1, 1, 1),
                 shade=(160, 160, 160)):
        self.instance_id, self.label = instance_id, label
        self.position, self.rotation = np.asarray(position, float), np.asarray(rotation, float)
        self.scale, self.centre, self.size = (np.asarray(v, float) for v in (scale, centre, size))
        self.shade = shade

    def world_centre(self):
        return self.position + qmatrix(self.rotation) @ (self.scale * self.centre)

    def half(self):
        return np.abs(self.scale * self.size) / 2


class Camera:
    def __init__(self, sensor, position, rotation, fov_y=60.0, shift=(0.0, 0.0), strategy="Depth", sky=SKY,
                 normals=True, rgb=True):
        self.sensor, self.position, self.rotation = sensor, np.asarray(position, float), np.asarray(rotation, float)
        m11 = 1 / math.tan(math.radians(fov_y) / 2)
        # Camera.projectionMatrix (OpenGL's convention), a lens shift in m02 and m12.
        self.projection = np.array([
            [m11 * HEIGHT / WIDTH, 0, shift[0], 0],
            [0, m11, shift[1], 0],
            [0, 0, -(FAR + NEAR) / (FAR - NEAR), -2 * FAR * NEAR / (FAR - NEAR)],
            [0, 0, -1, 0],
        ])
        self.strategy, self.sky, self.normals, self.rgb = strategy, sky, normals, rgb

    def matrix(self):
        """The 3×3 as SOLO writes it: c0.x, c0.y, c0.z, c1.x, … (column by column)."""
        return floats(self.projection[:3, :3].T.reshape(-1))

    def rays(self):
        """Each pixel centre's ray (rows from the top), in the camera transform's frame."""
        inverse = np.linalg.inv(self.projection)
        rays = np.zeros((HEIGHT, WIDTH, 3))
        for row in range(HEIGHT):
            for col in range(WIDTH):
                x = 2 * (col + 0.5) / WIDTH - 1
                y = 2 * (HEIGHT - row - 0.5) / HEIGHT - 1
                near, far = (inverse @ np.array([x, y, z, 1.0]) for z in (-1.0, 1.0))
                near, far = near[:3] / near[3], far[:3] / far[3]
                d = far - near
                rays[row, col] = [d[0], d[1], -d[2]]  # view space looks along −z; the transform's z is forward
        return rays / np.linalg.norm(rays, axis=2, keepdims=True)


def render(camera, objects):
    """Per pixel: the nearest object (index, or −1), its hit point in the camera's frame and its
    world normal."""
    rays = camera.rays()
    turn = qmatrix(camera.rotation)
    hit = np.full((HEIGHT, WIDTH), -1)
    t_best = np.full((HEIGHT, WIDTH), np.inf)
    normal = np.zeros((HEIGHT, WIDTH, 3))
    for k, obj in enumerate(objects):
        axes = qmatrix(obj.rotation)
        half = obj.half()
        for row in range(HEIGHT):
            for col in range(WIDTH):
                o = axes.T @ (camera.position - obj.world_centre())
                d = axes.T @ (turn @ rays[row, col])
                with np.errstate(divide="ignore", invalid="ignore"):
                    t1, t2 = (-half - o) / d, (half - o) / d
                lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
                lo = np.where(np.isnan(lo), -np.inf, lo)
                hi = np.where(np.isnan(hi), np.inf, hi)
                t_in, t_out = lo.max(), hi.min()
                if t_in <= t_out and t_in > 0 and t_in < t_best[row, col]:
                    t_best[row, col] = t_in
                    hit[row, col] = k
                    face = int(np.argmax(lo))
                    n = np.zeros(3)
                    n[face] = -np.sign(d[face])
                    normal[row, col] = axes @ n
    points = rays * t_best[..., None]
    points[hit < 0] = 0
    return hit, points, normal


def write_json(path, data):
    path.write_text(json.dumps(data, indent=2))


def write_png(path, pixels):
    Image.fromarray(np.asarray(pixels, np.uint8), "RGBA").save(path)


def write_exr(path, rgba):
    header = OpenEXR.Header(rgba.shape[1], rgba.shape[0])
    header["compression"] = Imath.Compression(Imath.Compression.ZIP_COMPRESSION)
    channel = Imath.Channel(Imath.PixelType(Imath.PixelType.FLOAT))
    header["channels"] = {c: channel for c in "RGBA"}
    exr = OpenEXR.OutputFile(str(path), header)
    exr.writePixels({c: rgba[..., i].astype(np.float32).tobytes() for i, c in enumerate("RGBA")})
    exr.close()


def capture(folder, step, camera, objects):
    """Writes a camera's files of a step; its capture record."""
    hit, points, normal = render(camera, objects)
    labelled = [k for k, o in enumerate(objects) if o.label]
    seen = [k for k in labelled if (hit == k).any()]
    key = camera.sensor

    instance = np.zeros((HEIGHT, WIDTH, 4), np.uint8)
    instance[:] = SKY
    semantic = np.zeros((HEIGHT, WIDTH, 4), np.uint8)
    semantic[:] = SKY
    rgb = np.zeros((HEIGHT, WIDTH, 4), np.uint8)
    rgb[:] = (140, 190, 235, 255)
    depth = np.zeros((HEIGHT, WIDTH, 4), np.float32)
    normals = np.zeros((HEIGHT, WIDTH, 4), np.float32)
    normals[..., 3] = 1
    to_camera = qmatrix(qinv(camera.rotation))
    for k, obj in enumerate(objects):
        mask = hit == k
        if obj.label:
            instance[mask] = instance_colour(obj.instance_id)
            semantic[mask] = LABEL_COLOURS[obj.label]
        lit = np.clip(0.55 + 0.45 * normal[mask] @ np.array([0.3, 0.8, -0.5]), 0.2, 1.0)
        rgb[mask, :3] = (np.array(obj.shade)[None, :] * lit[:, None]).astype(np.uint8)
        z = points[mask, 2] if camera.strategy == "Depth" else np.linalg.norm(points[mask], axis=1)
        depth[mask] = np.stack([z, 0 * z, 0 * z, 1 + 0 * z], axis=1)
        sensor = (to_camera @ normal[mask].T).T
        encoded = (sensor + 1) / 2
        encoded[:, 2] = 1 - encoded[:, 2]
        normals[mask, :3] = encoded
    sky = hit < 0
    instance[sky] = camera.sky
    # Objects without a Labeling are drawn as instance 0.
    for k, obj in enumerate(objects):
        if not obj.label:
            instance[hit == k] = SKY

    names = {
        "rgb": f"step{step}.{key}.png",
        "instances": f"step{step}.{key}.instance segmentation.png",
        "semantic": f"step{step}.{key}.semantic segmentation.png",
        "depth": f"step{step}.{key}.Depth.exr",
        "normals": f"step{step}.{key}.Normal.exr",
    }
    write_png(folder / names["rgb"], rgb)
    write_png(folder / names["instances"], instance)
    write_png(folder / names["semantic"], semantic)
    write_exr(folder / names["depth"], depth)
    if camera.normals:
        write_exr(folder / names["normals"], normals)

    dimension = [float(WIDTH), float(HEIGHT)]
    label_id = {name: i for i, name in LABELS}
    boxes_2d, boxes_3d, entries = [], [], []
    # The order RenderedObjectInfo lists them in is the GPU's; not sorted.
    for k in sorted(seen, key=lambda k: (objects[k].instance_id * 7) % 5):
        obj = objects[k]
        rows, cols = np.nonzero(hit == k)
        common = {"instanceId": obj.instance_id, "labelId": label_id[obj.label], "labelName": obj.label}
        entries.append({**common, "color": list(instance_colour(obj.instance_id))})
        boxes_2d.append({
            **common,
            "origin": [float(cols.min()), float(rows.min())],
            "dimension": [float(cols.max() - cols.min() + 1), float(rows.max() - rows.min() + 1)],
        })
        boxes_3d.append({
            **common,
            "translation": floats(to_camera @ (obj.world_centre() - camera.position)),
            "size": floats(np.abs(obj.scale * obj.size)),
            "rotation": floats(qmul(qinv(camera.rotation), obj.rotation)),
            "velocity": [0.0, 0.0, 0.0],
            "acceleration": [0.0, 0.0, 0.0],
        })
    annotations = [
        {
            "@type": SOLO + "BoundingBox2DAnnotation", "id": "bounding box", "sensorId": key,
            "description": "Produces 2D bounding box annotations for all visible objects that bear a label defined "
                           "in this labeler's associated label configuration.",
            "values": boxes_2d,
        },
        {
            "@type": SOLO + "BoundingBox3DAnnotation", "id": "bounding box 3D", "sensorId": key,
            "description": "Produces 3D bounding box ground truth data for all visible objects that bear a label "
                           "defined in this labeler's associated label configuration.",
            "values": boxes_3d,
        },
        {
            "@type": SOLO + "DepthAnnotation", "id": "Depth", "sensorId": key,
            "description": "Generates a 32-bit depth image in EXR format where each pixel contains the actual "
                           "distance in Unity units (usually meters) from the camera to the object in the scene.",
            "measurementStrategy": camera.strategy, "imageFormat": "Exr", "dimension": dimension,
            "filename": names["depth"],
        },
        {
            "@type": SOLO + "InstanceSegmentationAnnotation", "id": "instance segmentation", "sensorId": key,
            "description": "Produces an instance segmentation image for each frame. The image will render the pixels "
                           "of each labeled object in a distinct color.",
            "imageFormat": "Png", "dimension": dimension, "filename": names["instances"], "instances": entries,
        },
        {
            "@type": SOLO + "SemanticSegmentationAnnotation", "id": "semantic segmentation", "sensorId": key,
            "description": "Generates a semantic segmentation image for each captured frame.",
            "imageFormat": "Png", "dimension": dimension, "filename": names["semantic"],
            "instances": [
                {"labelName": name, "pixelValue": list(LABEL_COLOURS[name])}
                for name in sorted({objects[k].label for k in seen})
            ],
        },
    ]
    if camera.normals:
        annotations.append({
            "@type": SOLO + "NormalAnnotation", "id": "Normal", "sensorId": key,
            "description": "Produces an image capturing the vertex normals of objects within the frame.",
            "imageFormat": "Exr", "dimension": dimension, "filename": names["normals"],
        })
    return {
        "@type": SOLO + "RGBCamera",
        "id": key,
        "description": "The main camera" if key == "camera" else "A second camera",
        "position": floats(camera.position),
        "rotation": floats(camera.rotation),
        "velocity": [0.0, 0.0, 0.0],
        "acceleration": [0.0, 0.0, 0.0],
        "filename": names["rgb"],
        "imageFormat": "Png",
        "dimension": dimension,
        "projection": "Perspective",
        "matrix": camera.matrix(),
        "annotations": annotations,
    }


def floor():
    return Box(900, None, (0, -0.05, 2), rotation(), size=(30, 0.1, 30), shade=(110, 140, 90))


def scenes():
    """(sequence, step, frame, [cameras], [objects]) of the dataset."""
    down = rotation(((1, 0, 0), 12))
    crate = dict(shade=(190, 140, 80))
    box = dict(shade=(90, 110, 200))
    first = [
        floor(),
        # Two crates side by side: their images touch.
        Box(1, "Crate", (-0.75, 0.0, 1.0), rotation(), centre=(0, 0.5, 0), size=(0.8, 1, 0.8), **crate),
        Box(2, "Crate", (0.05, 0.0, 1.0), rotation(), centre=(0, 0.5, 0), size=(0.8, 1, 0.8), **crate),
        # A box in front, turned and stretched: it hides parts of both.
        Box(3, "Box", (-0.3, 0.35, -0.4), rotation(((0, 1, 0), 30), ((1, 0, 0), 10)), scale=(1.2, 0.6, 0.8),
            size=(0.5, 0.5, 0.5), **box),
        # A crate cut by the right edge of the image.
        Box(4, "Crate", (2.15, 0.0, 1.4), rotation(((0, 1, 0), -25)), centre=(0, 0.5, 0), size=(0.9, 1, 0.9), **crate),
    ]
    yield 0, 0, 3, [Camera("camera", (0.0, 1.4, -3.0), down)], first
    moved = rotation(((1, 0, 0), 9), ((0, 1, 0), -10))
    yield 0, 1, 4, [Camera("camera", (0.4, 1.3, -2.8), moved, fov_y=55, shift=(0.12, -0.08))], first
    second = [
        floor(),
        Box(5, "Box", (-0.4, 0.3, 0.8), rotation(((0, 1, 0), 45)), size=(0.6, 0.6, 0.6), **box),
        Box(6, "Crate", (0.35, 0.0, 1.2), rotation(((0, 1, 0), 10)), centre=(0, 0.5, 0), scale=(1, 1.3, 1),
            size=(0.7, 1, 0.7), **crate),
        Box(7, "Box", (0.1, 0.2, 0.2), rotation(((1, 0, 0), 20), ((0, 0, 1), 15)), size=(0.4, 0.4, 0.4), **box),
    ]
    cameras = [
        Camera("camera", (0.0, 1.2, -2.5), rotation(((1, 0, 0), 10)), strategy="Range"),
        Camera("camera2", (-2.2, 1.5, -1.6), rotation(((1, 0, 0), 15), ((0, 1, 0), 40)), fov_y=50,
               sky=(0, 0, 0, 0), normals=False),
    ]
    yield 1, 0, 9, cameras, second
    yield 1, 1, 10, [Camera("camera", (0.3, 1.1, -2.2), rotation(((1, 0, 0), 8), ((0, 1, 0), -6)))], second


def write_dataset(out):
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    frames = 0
    for sequence, step, frame, cameras, objects in scenes():
        folder = out / f"sequence.{sequence}"
        folder.mkdir(exist_ok=True)
        captures = [capture(folder, step, camera, objects) for camera in cameras]
        data = {
            "frame": frame, "sequence": sequence, "step": step, "timestamp": f32(step * 0.0166),
            "captures": captures,
            "metrics": [{
                "@type": SOLO + "GenericMetric", "id": "scenario_iteration", "sensorId": "", "annotationId": "",
                "description": "Iteration information for dataset sequences", "value": sequence,
            }],
        }
        write_json(folder / f"step{step}.frame_data.json", data)
        frames += 1

    write_json(out / "metadata.json", {
        "unityVersion": "2021.3.11f1", "perceptionVersion": PERCEPTION_VERSION, "renderPipeline": "HDRP",
        "simulationStartTime": "12/1/2026 10:00:00 AM", "scenarioRandomSeed": 539662031,
        "scenarioActiveRandomizers": [], "totalFrames": frames, "totalSequences": 2, "sensors": ["camera", "camera2"],
        "metricCollectors": ["scenario_iteration"], "simulationEndTime": "12/1/2026 10:00:05 AM",
        "annotators": [
            {"name": name, "type": SOLO + kind}
            for name, kind in [("bounding box", "BoundingBox2DAnnotation"), ("bounding box 3D", "BoundingBox3DAnnotation"),
                               ("Depth", "DepthAnnotation"), ("instance segmentation", "InstanceSegmentationAnnotation"),
                               ("semantic segmentation", "SemanticSegmentationAnnotation"), ("Normal", "NormalAnnotation")]
        ],
    })
    spec = [{"label_id": i, "label_name": name} for i, name in LABELS]
    write_json(out / "annotation_definitions.json", {"annotationDefinitions": [
        {"@type": SOLO + "BoundingBox2DAnnotation", "id": "bounding box", "description": "2D boxes", "spec": spec},
        {"@type": SOLO + "BoundingBox3DAnnotation", "id": "bounding box 3D", "description": "3D boxes", "spec": spec},
        {"@type": SOLO + "DepthAnnotation", "id": "Depth", "description": "Depth"},
        {"@type": SOLO + "InstanceSegmentationAnnotation", "id": "instance segmentation",
         "description": "Instance segmentation", "spec": spec},
        {"@type": SOLO + "SemanticSegmentationAnnotation", "id": "semantic segmentation",
         "description": "Semantic segmentation",
         "spec": [{"label_name": name, "pixel_value": list(LABEL_COLOURS[name])} for _, name in LABELS]},
        {"@type": SOLO + "NormalAnnotation", "id": "Normal", "description": "Normals"},
    ]})
    write_json(out / "metric_definitions.json", {"metricDefinitions": [
        {"@type": SOLO + "GenericMetric", "id": "scenario_iteration",
         "description": "Iteration information for dataset sequences"},
    ]})
    write_json(out / "sensor_definitions.json", {"sensorDefinitions": [
        {"@type": SOLO + "RGBCamera", "id": sensor, "modality": "camera", "description": description,
         "firstCaptureFrame": 0.0, "captureTriggerMode": "Scheduled", "simulationDeltaTime": 0.0166,
         "framesBetweenCaptures": 0, "manualSensorsAffectTiming": False}
        for sensor, description in [("camera", "The main camera"), ("camera2", "A second camera")]
    ]})


def write_stopped(good, out):
    """The dataset as a run stopped while writing sequence.1/step1 leaves it: that step's images
    written, its frame_data.json not; the root's JSON files not written (SimulationCompleted
    writes them)."""
    shutil.rmtree(out, ignore_errors=True)
    shutil.copytree(good, out)
    for name in ["metadata.json", "annotation_definitions.json", "metric_definitions.json", "sensor_definitions.json"]:
        (out / name).unlink()
    (out / "sequence.1" / "step1.frame_data.json").unlink()


def frame_data(dataset, sequence, step):
    path = dataset / f"sequence.{sequence}" / f"step{step}.frame_data.json"
    return path, json.loads(path.read_text())


def write_bad(good, out):
    shutil.rmtree(out, ignore_errors=True)

    def copy(fault, sequences=("sequence.0",)):
        """The dataset's root files and `sequences`: what the fault needs."""
        target = out / fault
        shutil.copytree(good, target, ignore=lambda d, names: [n for n in names if n.startswith("sequence.")
                                                                and pathlib.Path(d) == good and n not in sequences])
        return target

    (copy("missing-png") / "sequence.0" / "step1.camera.instance segmentation.png").unlink()

    path = copy("wrong-size") / "sequence.0" / "step0.camera.instance segmentation.png"
    pixels = np.array(Image.open(path))
    write_png(path, pixels[:, :WIDTH - 1])

    path = copy("unknown-colour") / "sequence.0" / "step0.camera.instance segmentation.png"
    pixels = np.array(Image.open(path))
    pixels[30, 5] = (1, 2, 3, 255)
    write_png(path, pixels)

    path = copy("bad-json") / "sequence.0" / "step1.frame_data.json"
    path.write_text(path.read_text()[:200])

    path, data = frame_data(copy("no-depth"), 0, 0)
    capture_ = data["captures"][0]
    capture_["annotations"] = [a for a in capture_["annotations"] if not a["@type"].endswith("DepthAnnotation")]
    write_json(path, data)

    path, data = frame_data(copy("label-clash", ("sequence.0", "sequence.1")), 1, 0)
    for c in data["captures"]:
        for a in c["annotations"]:
            for v in a.get("instances", []) + a.get("values", []):
                if v.get("labelName") == "Crate":
                    v["labelName"] = "Barrel"
    write_json(path, data)

    (copy("mixed") / "0.hdf5").write_bytes(b"")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="tests/fixtures/scenes", type=pathlib.Path)
    args = parser.parse_args()
    write_dataset(args.out / "solo")
    write_stopped(args.out / "solo", args.out / "solo-stopped")
    write_bad(args.out / "solo", args.out / "solo-bad")


if __name__ == "__main__":
    main()
