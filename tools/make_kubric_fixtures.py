#!/usr/bin/env python3
"""Kubric sequences for `vkdiff dataset --scenes`, written by Kubric's own code.

Kubric (google-research/kubric) is imported from PyPI's kubric-nightly 2023.12.27, whose
kubric/ package is the same as google-research/kubric at commit
0ee21e2a723b2131123d67e55d1f65b6d0e6cf0f but for copyright years and one import in utils.py.
Blender (bpy) does not install here, so the one step Blender does, rendering the passes, is done
here with numpy; everything after it is Kubric's own code, called as challenges/movi/
movi_def_worker.py calls it:
  - the passes as Blender hands them to Kubric (kubric/renderer/blender_utils.py,
    get_render_layers_from_exr): "depth" = Cycles' Z pass (camera-space z, the distance to the
    camera *plane*; 1e10 where no surface is hit), "normal" = Cycles' Normal pass (world space,
    0 where nothing is hit), "segmentation_indices" = the Cryptomatte object ids
    (blender_utils.mm3hash of each asset's uid; 0 for the world);
  - Kubric's post-processors turn them into the layers (blender_utils.process_depth: the Z pass
    times camera.z_to_depth's factor, i.e. the distance along the ray; process_normal: uint16
    (n + 1) · 65535 / 2; process_segementation: each asset's index in scene.assets + 1), stacked
    over the frames as Blender.postprocess stacks them; "rgba" is what Blender's PNG would be
    (uint8, a Lambert shading here);
  - then movi_def_worker.py's post-processing, line for line: kb.compute_visibility, the
    visible foreground assets sorted by visibility, kb.adjust_segmentation_idxs (instance k of
    the segmentation is metadata.json's instances[k - 1]; background assets 0),
    kb.write_image_dict (rgba_NNNNN.png via write_png, depth_NNNNN.tiff via write_tiff: float32
    H×W×1 through imageio/tifffile, segmentation_NNNNN.png via write_palette_png with
    plotting.hls_palette, normal_NNNNN.png 16-bit RGB), kb.post_processing.compute_bboxes, and
    kb.write_json of metadata.json ({"flags", "metadata": kb.get_scene_metadata, "camera":
    kb.get_camera_info, "instances": kb.get_instance_info}) and events.json.
The passes are ray-cast with Blender's camera model as Kubric sets it up (blender.py: sensor_fit
HORIZONTAL, lens = focal_length, sensor_width; square pixels): the pixel centre (i + ½, j + ½) of a
W×H image lies at x = ((i + ½)/W − ½)·sensor_width, y = −((j + ½)/H − ½)·sensor_height mm on the
sensor, the ray (x/f, y/f, −1) in Blender's camera frame (x right, y up, looking along −z),
turned into the world by the camera's quaternion (w, x, y, z, pyquaternion's order) and hit
against each object's box (its bounds × scale, turned by its quaternion, at its position): the
nearest wins. Every object here is a box, so the reader's test can put each pixel back on its
box. kb.FileBasedObject stands in for Google Scanned Objects assets (asset_id and the manifest's
metadata: category, description; the worker's scale) and for KuBasic's ("cube", no category);
kb.Cube for an object without an asset_id.

tensorflow is stubbed (file_io's gopen uses tf.io.gfile.GFile; here the built-in open, with a
module spec so that etils' epath takes local paths), and blender_utils.py is loaded from its file
with bpy stubbed (only its post-processors and mm3hash are called), as one would run just
Kubric's file writers.

Versions used for the committed fixtures: Python 3.11, kubric-nightly 2023.12.27, numpy 2.4.6,
imageio 2.38.2, tifffile 2026.3.3, pypng 0.20220715.0, pyquaternion 0.9.9, traitlets 5.16.1,
etils 1.15.0, absl-py 2.5.1, munch 4.0.0, scikit-learn 1.9.1, trimesh 5.2.0, OpenEXR 3.5.3.
Setup and rerun:
  /tmp/ref/bin/pip install --no-deps kubric-nightly==2023.12.27
  /tmp/ref/bin/pip install numpy imageio tifffile pypng pyquaternion traitlets munch \
      "etils[epath]" absl-py scikit-learn trimesh OpenEXR
  /tmp/ref/bin/python tools/make_kubric_fixtures.py [--out tests/fixtures/scenes]

Writes under --out:
  kubric/: two Kubric output folders (sequences), 48×40:
      video_0: 3 frames, a moving camera, Google-Scanned-Objects-like assets of categories
          Shoe, Toys (two, touching), Bag (cut off by the image's edge), Hat (in view in frame 0
          only) and one under the floor (never seen, so not in instances), one moving and
          turning between frames, some scaled unevenly and with off-centre bounds; a floor
          (background asset: segmentation 0, finite depth) and an empty sky; normals written;
      video_1: 2 frames, a fixed camera (no keyframes), a KuBasic "cube" (no category) and a
          kb.Cube (no asset_id) occluding it; no normals.
  kubric-expected/: what numpy makes of them for the tests: <seq>/z_NNNNN.npy (the Z pass the
      frame was rendered from, float32, 1e10 sky), <seq>/planar_NNNNN.npy (the TIFF's depth made
      planar through the pixel K with numpy: d / sqrt(1 + ((u − cx)/fx)² + ((v − cy)/fy)²),
      float64 then float32), and project.json (camera.project_point of fixed world points, per
      sequence and frame: Kubric's own projection, normalised image coordinates).
  kubric-stopped/: video_1 whole, and video_2 as a run stopped before metadata.json leaves it
      (its frames written, no metadata.json).
  kubric-bad/<fault>/: video_1 (the folder given is the sequence) broken one way each:
      missing-tiff (depth_00001.tiff removed), wrong-size (segmentation_00000.png 47×40),
      bad-metadata (metadata.json cut short), unknown-index (a pixel of segmentation_00000.png
      at index 3, two instances listed), frame-count (the camera's positions for one frame, two
      frames said), float-depth (depth_00000.tiff written from uint16 data), mixed (a kubric
      sequence folder beside a BlenderProc .hdf5 name).
"""
import argparse
import colorsys
import importlib.machinery
import importlib.util
import json
import pathlib
import shutil
import sys
import types

import numpy as np

# --- tensorflow stubbed as file_io needs it (tf.io.gfile.GFile) --------------------------------
tf = types.ModuleType("tensorflow")
tf.__spec__ = importlib.machinery.ModuleSpec("tensorflow", None)
tf.io = types.SimpleNamespace(gfile=types.SimpleNamespace(GFile=open))
sys.modules["tensorflow"] = tf

import kubric as kb  # noqa: E402
import pyquaternion as pyquat  # noqa: E402

# --- kubric/renderer/blender_utils.py from its file, bpy stubbed --------------------------------
bpy = types.ModuleType("bpy")
bpy.types = types.SimpleNamespace(Object=object)
sys.modules["bpy"] = bpy
_spec = importlib.util.spec_from_file_location(
    "kubric_blender_utils", pathlib.Path(kb.__file__).parent / "renderer" / "blender_utils.py")
blender_utils = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(blender_utils)

WIDTH, HEIGHT = 48, 40
BLENDER_BACKGROUND_Z = 1e10  # blender_utils.get_render_layers_from_exr: "1e10 is used for background"
LIGHT = np.array([0.4, -0.3, 0.85]) / np.linalg.norm([0.4, -0.3, 0.85])


def quat(axis, degrees):
    """pyquaternion's (w, x, y, z) tuple, as Kubric stores quaternions."""
    return tuple(pyquat.Quaternion(axis=axis, degrees=degrees))


def flags_for(name, frames, seed):
    parser = kb.ArgumentParser()
    parser.set_defaults(frame_end=frames, frame_rate=12, resolution=f"{WIDTH}x{HEIGHT}")
    return parser.parse_args(["--seed", str(seed), "--scratch_dir", "scratch", "--job-dir", f"output/{name}"])


def gso(asset_id, category, bounds, scale, description):
    """A Google-Scanned-Objects-like asset as AssetSource.create makes it (the manifest's metadata
    added) with the worker's `scale` beside."""
    obj = kb.FileBasedObject(asset_id=asset_id, bounds=bounds, scale=scale, render_filename=None,
                             simulation_filename=None)
    obj.metadata.update({"category": category, "description": description, "nr_faces": 1200,
                         "nr_vertices": 602, "scale": float(np.max(scale))})
    return obj


def floor():
    return kb.Cube(name="floor", scale=(3.0, 2.5, 0.5), position=(0.0, 0.0, -0.5), static=True, background=True)


def sequence_0():
    flags = flags_for("video_0", 3, 17)
    scene = kb.Scene.from_flags(flags)
    scene.metadata["seed"] = flags.seed
    scene.camera = kb.PerspectiveCamera(focal_length=35.0, sensor_width=32.0)
    for frame, position in zip(range(1, 4), [(3.4, -2.9, 1.6), (3.3, -2.2, 1.8), (3.0, -1.4, 2.0)]):
        scene.camera.position = position
        scene.camera.look_at((0.0, 0.0, 0.35))
        scene.camera.keyframe_insert("position", frame)
        scene.camera.keyframe_insert("quaternion", frame)
    scene += floor()
    shoe = gso("Reebok_sneaker", "Shoe", ((-0.5, -0.2, -0.15), (0.6, 0.25, 0.25)), (1.0, 1.0, 1.4), "A sneaker")
    for frame, (position, q) in enumerate(
            [((0.3, -0.9, 0.3), quat([0, 0, 1], 20)), ((0.2, -0.7, 0.35), quat([0.3, 0.2, 1], 45)),
             ((0.1, -0.5, 0.4), quat([0.3, 0.2, 1], 80))], start=1):
        shoe.position, shoe.quaternion = position, q
        shoe.keyframe_insert("position", frame)
        shoe.keyframe_insert("quaternion", frame)
    scene += shoe
    truck = gso("Toy_truck", "Toys", ((-0.3, -0.3, -0.3), (0.3, 0.3, 0.3)), (1.0, 1.5, 1.0), "A toy truck")
    truck.position = (-0.5, 0.2, 0.3)
    scene += truck
    toy = gso("Toy_blocks", "Toys", ((-0.25, -0.25, -0.25), (0.25, 0.25, 0.25)), (1.2, 1.2, 1.2), "Blocks")
    toy.position, toy.quaternion = (-0.5, 0.95, 0.3), quat([0, 0, 1], 0)  # touches the truck at y = 0.65
    scene += toy
    bag = gso("Tote_bag", "Bag", ((-0.4, -0.2, 0.0), (0.4, 0.2, 0.9)), (1.0, 1.0, 1.0), "A bag")
    bag.position, bag.quaternion = (1.3, 1.2, 0.0), quat([0, 0, 1], -30)
    scene += bag
    hat = gso("Sun_hat", "Hat", ((-0.25, -0.25, 0.0), (0.25, 0.25, 0.2)), (1.0, 1.0, 1.0), "A hat")
    hat.position = (0.1, -2.1, 0.0)
    scene += hat
    hidden = gso("Buried_box", "Toys", ((-0.2, -0.2, -0.2), (0.2, 0.2, 0.2)), (1.0, 1.0, 1.0), "Under the floor")
    hidden.position = (0.0, 0.0, -1.5)
    scene += hidden
    return "video_0", flags, scene, ("rgba", "depth", "segmentation", "normal")


def sequence_1():
    flags = flags_for("video_1", 2, 4)
    scene = kb.Scene.from_flags(flags)
    scene.metadata["seed"] = flags.seed
    scene.metadata["background"] = "clevr"
    scene.camera = kb.PerspectiveCamera(focal_length=30.0, sensor_width=36.0, position=(0.5, -5.0, 1.6),
                                        look_at=(0.0, 0.0, 0.4))
    scene += floor()
    cube = kb.FileBasedObject(asset_id="cube", bounds=((-1, -1, -1), (1, 1, 1)), scale=(0.4, 0.4, 0.4),
                              render_filename=None, simulation_filename=None)
    cube.metadata = {"shape": "cube", "size": 0.4, "size_label": "small", "material": "rubber",
                     "color": (0.2, 0.4, 0.9), "color_label": "blue"}
    for frame, position in zip([1, 2], [(0.2, 0.3, 0.4), (0.35, 0.3, 0.4)]):
        cube.position = position
        cube.quaternion = quat([0, 0, 1], 15 * frame)
        cube.keyframe_insert("position", frame)
        cube.keyframe_insert("quaternion", frame)
    scene += cube
    plain = kb.Cube(scale=(0.3, 0.2, 0.5), position=(0.0, -1.2, 0.5), quaternion=quat([1, 0, 0], 10))
    scene += plain
    return "video_1", flags, scene, ("rgba", "depth", "segmentation")


# --- the passes, as Blender would hand them to Kubric -----------------------------------------------


def rays(camera):
    """Per pixel, the ray (x/f, y/f, −1) in Blender's camera frame."""
    sensor_height = camera.sensor_height
    i = (np.arange(WIDTH) + 0.5) / WIDTH - 0.5
    j = (np.arange(HEIGHT) + 0.5) / HEIGHT - 0.5
    x = i[None, :] * camera.sensor_width / camera.focal_length
    y = -j[:, None] * sensor_height / camera.focal_length
    return np.stack(np.broadcast_arrays(x, y, -np.ones_like(x * y)), axis=-1)


def hit_box(origin, directions, obj):
    """Ray parameter of the nearest entry into obj's box (inf where missed) and the world normal."""
    r = np.array(pyquat.Quaternion(*obj.quaternion).rotation_matrix)
    lo, hi = (np.array(obj.bounds, float) * np.array(obj.scale, float))
    o = r.T @ (np.asarray(origin, float) - np.asarray(obj.position, float))
    d = directions @ r  # rows: R^T d
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - o) / d, (hi - o) / d
    near, far = np.minimum(t1, t2), np.maximum(t1, t2)
    t_near, t_far = near.max(axis=-1), far.min(axis=-1)
    hit = (t_far >= t_near) & (t_near > 0)
    axis = near.argmax(axis=-1)
    sign = -np.sign(np.take_along_axis(d, axis[..., None], axis=-1))[..., 0]
    normal = r.T[axis] * sign[..., None]
    return np.where(hit, t_near, np.inf), normal


def render_frame(scene, frame, hues):
    camera = scene.camera
    with camera.at_frame(frame):
        origin = np.array(camera.position, float)
        r_cam = np.array(pyquat.Quaternion(*camera.quaternion).rotation_matrix)
        local = rays(camera)
        directions = local @ r_cam.T
    z = np.full((HEIGHT, WIDTH), np.inf)
    normal = np.zeros((HEIGHT, WIDTH, 3))
    crypto = np.zeros((HEIGHT, WIDTH, 2), np.uint32)
    colour = np.tile(np.array([0.55, 0.7, 0.95]), (HEIGHT, WIDTH, 1))
    for asset in scene.assets:
        if not isinstance(asset, kb.PhysicalObject):
            continue
        with asset.at_frame(frame):
            t, n = hit_box(origin, directions, asset)
        nearer = t < z
        z[nearer] = t[nearer]
        normal[nearer] = n[nearer]
        crypto[..., 0][nearer] = blender_utils.mm3hash(asset.uid)
        base = np.array(colorsys.hsv_to_rgb(hues.get(asset.uid, 0.0), 0.7 if asset.uid in hues else 0.0, 0.9))
        shade = 0.25 + 0.75 * np.clip(n @ LIGHT, 0, 1)
        colour[nearer] = base * shade[nearer][:, None]
    sky = ~np.isfinite(z)
    z[sky] = BLENDER_BACKGROUND_Z
    rgba = np.concatenate([np.round(colour * 255), np.full((HEIGHT, WIDTH, 1), 255)], axis=-1).astype(np.uint8)
    layers = {"depth": z.astype(np.float32)[..., None], "normal": normal.astype(np.float32),
              "segmentation_indices": crypto}
    return layers, rgba


def write_sequence(out, name, flags, scene, return_layers):
    """Blender.render's postprocess and movi_def_worker.py's lines after it."""
    foreground = [a for a in scene.assets if isinstance(a, kb.PhysicalObject) and not a.background]
    hues = {a.uid: k / max(1, len(foreground)) for k, a in enumerate(foreground)}
    post_processors = {"depth": blender_utils.process_depth, "normal": blender_utils.process_normal,
                       "segmentation": blender_utils.process_segementation}
    data_stack = {key: [] for key in return_layers}
    z_passes = []
    for frame in range(scene.frame_start, scene.frame_end + 1):
        layers, rgba = render_frame(scene, frame, hues)
        z_passes.append(layers["depth"][..., 0])
        with scene.camera.at_frame(frame):  # Blender renders each frame with its camera
            for key in return_layers:
                data_stack[key].append(rgba if key == "rgba" else post_processors[key](layers, scene))
    data_stack = {key: np.stack(v, axis=0) for key, v in data_stack.items()}
    output_dir = out / name

    # --- movi_def_worker.py, "# --- Postprocessing" on
    kb.compute_visibility(data_stack["segmentation"], scene.assets)
    visible_foreground_assets = [asset for asset in scene.foreground_assets
                                 if np.max(asset.metadata["visibility"]) > 0]
    visible_foreground_assets = sorted(  # sort assets by their visibility
        visible_foreground_assets,
        key=lambda asset: np.sum(asset.metadata["visibility"]),
        reverse=True)
    data_stack["segmentation"] = kb.adjust_segmentation_idxs(
        data_stack["segmentation"],
        scene.assets,
        visible_foreground_assets)
    scene.metadata["num_instances"] = len(visible_foreground_assets)
    kb.write_image_dict(data_stack, output_dir)
    kb.post_processing.compute_bboxes(data_stack["segmentation"],
                                      visible_foreground_assets)
    kb.write_json(filename=output_dir / "metadata.json", data={
        "flags": vars(flags),
        "metadata": kb.get_scene_metadata(scene),
        "camera": kb.get_camera_info(scene.camera),
        "instances": kb.get_instance_info(scene, visible_foreground_assets),
    })
    kb.write_json(filename=output_dir / "events.json", data={
        "collisions": kb.process_collisions([], scene, assets_subset=visible_foreground_assets),
    })
    return z_passes, data_stack


def write_expected(expected, name, scene, z_passes):
    folder = expected / name
    folder.mkdir(parents=True)
    metadata = json.loads((expected.parent / "kubric" / name / "metadata.json").read_text())
    k = np.array(metadata["camera"]["K"], float)
    w, h = metadata["metadata"]["resolution"]
    # K in pixels (OpenCV's: pixel centres at integers): K·diag(1, −1, −1) scaled by W, H.
    fx, fy = k[0, 0] * w, -k[1, 1] * h
    cx, cy = -k[0, 2] * w - 0.5, -k[1, 2] * h - 0.5
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    along = np.sqrt(1 + ((u - cx) / fx) ** 2 + ((v - cy) / fy) ** 2)
    for f, z in enumerate(z_passes):
        depth = kb.read_tiff(expected.parent / "kubric" / name / f"depth_{f:05d}.tiff")[..., 0]
        np.save(folder / f"planar_{f:05d}.npy", (depth.astype(float) / along).astype(np.float32))
        np.save(folder / f"z_{f:05d}.npy", z.astype(np.float32))
    points = [[0.0, 0.0, 0.0], [1.0, -0.5, 0.3], [-0.8, 1.2, 0.9], [2.0, 2.0, 0.0]]
    projected = []
    for f, frame in enumerate(range(scene.frame_start, scene.frame_end + 1)):
        projected.append([[float(c) for c in scene.camera.project_point(np.array(p), frame=frame)[:2]]
                          for p in points])
    return {"points": points, "frames": projected}


def write_stopped(out, good):
    folder = out / "kubric-stopped"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    shutil.copytree(good / "video_1", folder / "video_1")
    shutil.copytree(good / "video_1", folder / "video_2")
    (folder / "video_2" / "metadata.json").unlink()
    (folder / "video_2" / "events.json").unlink()


def write_bad(out, good):
    bad = out / "kubric-bad"
    shutil.rmtree(bad, ignore_errors=True)
    source = good / "video_1"

    def copy(fault):
        folder = bad / fault
        shutil.copytree(source, folder)
        return folder

    (copy("missing-tiff") / "depth_00001.tiff").unlink()
    folder = copy("wrong-size")
    seg = kb.read_png(folder / "segmentation_00000.png")
    kb.write_palette_png(seg[:, :47], folder / "segmentation_00000.png", palette=kb.plotting.hls_palette(3))
    folder = copy("bad-metadata")
    text = (folder / "metadata.json").read_text()
    (folder / "metadata.json").write_text(text[: len(text) // 2])
    folder = copy("unknown-index")
    seg = kb.read_png(folder / "segmentation_00000.png")
    seg[30, 5, 0] = 3
    kb.write_palette_png(seg, folder / "segmentation_00000.png", palette=kb.plotting.hls_palette(4))
    folder = copy("frame-count")
    metadata = kb.file_io.read_json(folder / "metadata.json")
    metadata["camera"]["positions"] = metadata["camera"]["positions"][:1]
    kb.write_json(metadata, folder / "metadata.json")
    folder = copy("float-depth")
    depth = kb.read_tiff(folder / "depth_00000.tiff")
    kb.write_tiff(np.clip(depth, 0, 65535).astype(np.uint16), folder / "depth_00000.tiff")
    folder = bad / "mixed"
    shutil.copytree(source, folder / "video_1")
    (folder / "0.hdf5").write_bytes(b"\x89HDF\r\n\x1a\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="tests/fixtures/scenes", type=pathlib.Path)
    args = parser.parse_args()
    good, expected = args.out / "kubric", args.out / "kubric-expected"
    for folder in (good, expected):
        shutil.rmtree(folder, ignore_errors=True)
    good.mkdir(parents=True)
    projections = {}
    for make in (sequence_0, sequence_1):
        name, flags, scene, layers = make()
        z_passes, data = write_sequence(good, name, flags, scene, layers)
        projections[name] = write_expected(expected, name, scene, z_passes)
        seg = data["segmentation"]
        instances = json.loads((good / name / "metadata.json").read_text())["instances"]
        print(name, [i.get("asset_id") for i in instances],
              "pixels per index", [np.bincount(s.ravel(), minlength=4).tolist() for s in seg])
    (expected / "project.json").write_text(json.dumps(projections, indent=2) + "\n")
    write_stopped(args.out, good)
    write_bad(args.out, good)


if __name__ == "__main__":
    main()
