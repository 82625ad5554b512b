#!/usr/bin/env python3
"""BOP scenes for `vkdiff dataset --scenes`, written by BlenderProc's own BOP writer.

BlenderProc's `bproc.writer.write_bop` (blenderproc 2.8.0 from the Python package registry, run
unchanged) writes every scene here, with Blender stood in for by tools/blender_stubs.py (the
scene's frames, the camera's lens and pose, the objects' poses and meshes; mathutils is
Blender's own math library). Each image is one write_bop call appending to its split, and its
`calc_mask_info_coco` step runs as in BlenderProc: bop_toolkit's code (thodan/bop_toolkit at
commit cea62d651c7e395b2e1962b9749e4e89693c6ac4, its master, which write_bop would pip-install
from git; here a checkout given as BOP_TOOLKIT, as bop_toolkit is not on the package registry)
with pyrender on EGL renders each gt's depth from
scene_gt.json and writes mask/, mask_visib/ (bop19 visibility against the depth written, delta
15 mm) and scene_gt_info.json.

From BlenderProc's and bop_toolkit's code: every scene_camera.json and scene_gt.json (poses from
the Blender objects' matrices, cam_K from the Blender lens, through BlenderProc's CameraUtility),
depth/ (BopWriterUtility.save_depth), rgb/ (cv2.imwrite), mask/, mask_visib/ and
scene_gt_info.json (calc_gt_masks, calc_gt_info), camera.json, and models/obj_*.ply and
models_info.json (inout.save_ply; calc_model_info.py's steps: misc.calc_3d_bbox,
misc.calc_pts_diameter, inout.save_json).
From this maker: the scenes themselves (the models' shapes, where each object and camera is),
the depth and colour images handed to write_bop in place of Blender's render (each object's
depth rendered with write_bop's own pyrender set-up, `_BopWriterUtility._pyrender_init`, from
the very pose write_bop writes; nearest wins over a tilted table, the top rows sky at depth 0;
flat colours); and, where write_bop cannot: scene 000001's images renamed from 0 and 1 to 2 and
10 (as BOP's test splits number theirs; JSON keys rewritten by the same save_json functions),
its rgb/ folder renamed gray/ (write_bop wrote the one-channel images given), scene_gt_coco.json
removed (vkdiff does not read it; it holds the run's clock and the ids before the renaming),
camera.json left out of bop/ (a split folder alone), the fault copies of bop-bad/ (rewritten
with BlenderProc's save_depth and bop_toolkit's save_im), and expected_keypoints.json (numpy,
tools/bop_keypoints.py). The maker checks that each written visible mask is exactly
where its gt is the nearest surface and each amodal mask where it covers.

Versions used for the committed fixtures: Python 3.11.7, blenderproc 2.8.0, mathutils 3.3.0
(Blender 3.3's; later releases need Python 3.13), pyrender 0.1.45, PyOpenGL 3.1.0 on Mesa's EGL
(llvmpipe), trimesh 5.2.0, numpy 2.4.6, opencv-python 5.1.0, pypng 0.20220715.0, imageio 2.38.2,
scipy 1.17.1, scikit-image 0.26.0, pycocotools 2.0.11. A rerun writes the same bytes.
Setup and rerun (Debian: apt-get install libegl-mesa0 libeigen3-dev, for EGL and for building
mathutils from source):
  /tmp/ref/bin/pip install blenderproc==2.8.0 mathutils==3.3.0 pyrender trimesh opencv-python \
      pypng imageio scipy scikit-image pycocotools
  BOP_TOOLKIT=<checkout of thodan/bop_toolkit> /tmp/ref/bin/python tools/make_bop_fixtures.py \
      [--out tests/fixtures/scenes]

Writes under --out:
  bop/: a split of two scenes, 96×72. 000000/ (images 0 and 1; rgb/ PNGs, depth_scale 0.1,
      cam_R_w2c/cam_t_w2c given) and 000001/ (images 2 and 10, so that image ids sort as
      numbers; gray/ PNGs, depth_scale 1.0, no world pose). Objects of obj_ids 1 (an ellipsoid)
      and 2 (a bar) touch, occlude each other and are cut by the frame's edge; one gt is hidden
      behind another (its visible mask empty); the top rows are sky (depth 0), a table fills the
      rest. bop/categories.json names obj_id 1 only (obj_id 2 falls back to obj_000002); a scene
      folder given alone (--scenes bop/000001) has none beside it, so both are named by id.
  bop-dataset/: a BOP dataset's root: train_pbr/000000/ (scene 0 as above), camera.json,
      models/ (obj_000001.ply, obj_000002.ply, models_info.json: each obj_id's box, mm), and
      expected_keypoints.json: per scene/image/gt, the nine box keypoints (the eight corners, x
      slowest, then the centre) projected here with numpy, each x, y, v (2 seen, 1 behind the
      depth seen at its pixel, 0 outside the image: 0, 0, 0).
  bop-bad/<fault>/000000/: scene 000000 broken one way each: missing-mask (a mask_visib file
      removed), depth-size (image 1's depth 95×72), overlap (two visible masks share pixels).
"""
import argparse
import json
import math
import multiprocessing
import os
import pathlib
import shutil
import sys
import tempfile

import numpy as np
import trimesh

import blender_stubs
import bop_keypoints

WIDTH, HEIGHT = 96, 72
SKY_ROWS = 10

# obj_id → its model, mm: an ellipsoid of semi-axes 80, 60, 40, and a 300 × 40 × 30 bar.
MODELS = {
    1: lambda: trimesh.creation.uv_sphere(radius=1.0, count=[10, 12]).apply_scale([80.0, 60.0, 40.0]),
    2: lambda: trimesh.creation.box(extents=[300.0, 40.0, 30.0]),
}

# Per scene: depth_scale, the K asked of the camera, the render folder, and per image id the
# camera's pose in Blender's world (location m, XYZ Euler degrees; written only where `world`)
# and its objects: (obj_id, centre pixel, depth mm, XYZ Euler degrees of the model in the camera).
SCENES = {
    0: dict(depth_scale=0.1, K=[[80.0, 0.0, 47.5], [0.0, 80.0, 35.5], [0.0, 0.0, 1.0]], world=True, render="rgb",
            images={
                0: (((0.12, -0.55, 0.48), (52, 0, 12)), [
                    (1, (30, 38), 600, (10, 20, 0)),
                    (1, (47, 38), 700, (-15, 10, 30)),  # touches the first, behind it
                    (2, (45, 46), 500, (0, 0, 3)),  # occludes both
                    (2, (90, 30), 700, (0, 0, 35)),  # cut by the right edge
                ]),
                1: (((0.30, -0.45, 0.50), (48, 0, 33)), [
                    (2, (10, 62), 500, (0, 0, -30)),  # cut by the left and bottom edges
                    (1, (50, 30), 600, (30, 0, 20)),
                    (1, (50, 30), 780, (30, 0, 20)),  # hidden behind the one above
                    (2, (72, 16), 640, (0, 0, 85)),  # cut by the top, over the sky
                ]),
            }),
    1: dict(depth_scale=1.0, K=[[90.0, 0.0, 48.0], [0.0, 88.0, 36.0], [0.0, 0.0, 1.0]], world=False, render="gray",
            images={
                2: (((0.0, 0.0, 1.0), (0, 0, 0)), [
                    (2, (38, 36), 700, (0, 0, 0)),
                    (1, (62, 36), 600, (0, 30, 0)),  # touches the bar, in front
                    (1, (88, 64), 720, (20, 0, 45)),  # cut by the corner
                ]),
                10: (((0.0, 0.0, 1.0), (0, 0, 0)), [
                    (1, (20, 30), 600, (0, 0, 0)),
                    (2, (28, 34), 520, (0, 0, -20)),  # occludes it
                ]),
            }),
}
# Flat colours whose greys differ too: sky 192, table 100, obj_id 1 137, obj_id 2 70.
COLOURS = {"sky": (150, 190, 235), "table": (120, 100, 80), 1: (240, 90, 80), 2: (20, 40, 150)}


def write_models(models_dir):
    """Each model as BOP ships it (PLY, mm, bop_toolkit's save_ply), models_info.json as
    bop_toolkit's scripts/calc_model_info.py computes it, and each model loaded back."""
    from bop_toolkit_lib import inout, misc

    models_dir.mkdir(parents=True)
    info, loaded = {}, {}
    for obj_id, make in MODELS.items():
        mesh = make()
        path = models_dir / f"obj_{obj_id:06d}.ply"
        inout.save_ply(path, {"pts": np.asarray(mesh.vertices), "faces": np.asarray(mesh.faces)})
        model = inout.load_ply(path)
        pts = model["pts"]
        bbox = misc.calc_3d_bbox(pts[:, 0], pts[:, 1], pts[:, 2])
        keys = ["min_x", "min_y", "min_z", "size_x", "size_y", "size_z"]
        info[obj_id] = {**{k: float(v) for k, v in zip(keys, bbox)}, "diameter": float(misc.calc_pts_diameter(pts))}
        loaded[obj_id] = model
    inout.save_json(models_dir / "models_info.json", info)
    return loaded


def euler(degrees):
    """A rotation (4 × 4) from XYZ Euler angles in degrees, by Blender's mathutils."""
    import mathutils

    return mathutils.Euler([math.radians(a) for a in degrees]).to_matrix().to_4x4()  # XYZ: its default


def stage(scene_spec, im_id, meshes):
    """A fresh Blender scene holding image im_id's camera and objects; the MeshObjects."""
    import mathutils
    from blenderproc.python.camera import CameraUtility
    from blenderproc.python.types.MeshObjectUtility import MeshObject

    scene = blender_stubs.new_scene(WIDTH, HEIGHT)
    K = scene_spec["K"]
    CameraUtility.set_intrinsics_from_K_matrix(K, WIDTH, HEIGHT)
    (location, angles), objects = scene_spec["images"][im_id]
    cam2world = mathutils.Matrix.Translation(location) @ euler(angles)
    CameraUtility.add_camera_pose(cam2world, frame=0)
    opencv_to_blender = mathutils.Matrix.Diagonal((1.0, -1.0, -1.0, 1.0))
    placed = []
    for k, (obj_id, (u, v), z, angles) in enumerate(objects):
        t = [(u - K[0][2]) * z / K[0][0] / 1000.0, (v - K[1][2]) * z / K[1][1] / 1000.0, z / 1000.0]
        model2camera = mathutils.Matrix.Translation(t) @ euler(angles)
        obj = MeshObject(blender_stubs.BlenderObject(f"obj_{obj_id:06d}.{k:03d}", meshes[obj_id]))
        obj.set_cp("category_id", obj_id)
        obj.set_local2world_mat(cam2world @ opencv_to_blender @ model2camera)
        scene.objects.append(obj.blender_obj)
        placed.append(obj)
    scene.frame_set(0)
    return placed


def render_depth(K, gt):
    """One gt's depth (m, 0 off it) as write_bop's calc_gt_masks renders it: its pyrender set-up
    (`_pyrender_init`, run as this pool's initializer), camera and pose conversion."""
    import pyrender
    from blenderproc.python.writer import BopWriterUtility as writer

    K = np.array(K).reshape(3, 3)
    scene = pyrender.Scene()
    scene.add(pyrender.IntrinsicsCamera(fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], znear=0.1, zfar=100000))
    t = np.array(gt["cam_t_m2c"])
    t /= 1000.0
    pose = writer.bop_pose_to_pyrender_coordinate_system(cam_R_m2c=np.array(gt["cam_R_m2c"]).reshape(3, 3), cam_t_m2c=t)
    scene.add(writer.dataset_objects[gt["obj_id"]], pose=pose)
    return writer.renderer.render(scene=scene)[1]


def compose(depths, obj_ids):
    """The frame Blender would render: nearest surface wins over a table tilted away (sky at the
    top, depth 0); the depth (m), which gt is seen at each pixel (-1 none), flat colours."""
    rows = np.arange(HEIGHT, dtype=np.float64)[:, None] * np.ones((1, WIDTH))
    depth = np.where(rows < SKY_ROWS, 0.0, (900.0 + 2.0 * (HEIGHT - rows)) / 1000.0)
    nearest = np.full((HEIGHT, WIDTH), -1)
    for k, d in enumerate(depths):
        closer = (d > 0) & ((depth == 0) | (d < depth))
        depth[closer] = d[closer]
        nearest[closer] = k
    rgb = np.where((rows < SKY_ROWS)[..., None], COLOURS["sky"], COLOURS["table"]).astype(np.uint8)
    for k, obj_id in enumerate(obj_ids):
        rgb[nearest == k] = COLOURS[obj_id]
    return depth, nearest, rgb


def write_split(out, dataset, scene_ids, meshes, pool):
    """Each image of the scenes through its own write_bop call, appending to out/dataset/train_pbr
    two images a chunk; per (scene, image): the gt seen at each pixel and each gt's silhouette."""
    from blenderproc.api import writer
    from blenderproc.python.writer.BopWriterUtility import _BopWriterUtility

    drawn = {}
    for scene_id in scene_ids:
        spec = SCENES[scene_id]
        for im_id in spec["images"]:
            objects = stage(spec, im_id, meshes)
            # The poses and K write_bop writes, which its calc_gt_masks renders from.
            gts = _BopWriterUtility.get_frame_gt(objects, 1000.0, 100.0)
            K = _BopWriterUtility.get_frame_camera(False)["cam_K"]
            depths = pool.starmap(render_depth, [(K, gt) for gt in gts])
            depth, nearest, rgb = compose(depths, [gt["obj_id"] for gt in gts])
            colour = rgb if spec["render"] == "rgb" else rgb.mean(axis=2, keepdims=True).round().astype(np.uint8)
            writer.write_bop(str(out), target_objects=objects, depths=[depth], colors=[colour],
                             color_file_format="PNG", dataset=dataset, depth_scale=spec["depth_scale"],
                             save_world2cam=spec["world"], annotation_unit="mm", frames_per_chunk=2,
                             calc_mask_info_coco=True, delta=0.015, num_worker=1)
            drawn[(scene_id, im_id)] = (nearest, [d > 0 for d in depths])
    return drawn


def check_masks(split, drawn):
    """Each visible mask written is exactly where its gt is the nearest surface, each amodal mask
    where it covers; the hidden gt has none."""
    import imageio.v2 as imageio

    hidden = 0
    for (scene_id, im_id), (nearest, silhouettes) in drawn.items():
        frame = list(SCENES[scene_id]["images"]).index(im_id)
        for k, silhouette in enumerate(silhouettes):
            name = f"{frame:06d}_{k:06d}.png"
            visible = imageio.imread(split / f"{scene_id:06d}/mask_visib/{name}") > 0
            whole = imageio.imread(split / f"{scene_id:06d}/mask/{name}") > 0
            if not (np.array_equal(visible, nearest == k) and np.array_equal(whole, silhouette)):
                sys.exit(f"scene {scene_id} image {im_id} gt {k}: write_bop's masks differ from the scene drawn")
            hidden += not visible.any()
    if hidden == 0:
        sys.exit("no gt is hidden")


def renumber(scene, new_ids):
    """Images 0, 1, … of a scene renamed new_ids[0], new_ids[1], …: files, and the JSON files'
    keys through the functions that wrote them."""
    from blenderproc.python.writer.BopWriterUtility import _BopWriterUtility
    from bop_toolkit_lib import inout

    for old, new in reversed(list(enumerate(new_ids))):
        for path in scene.glob(f"*/{old:06d}*.png"):
            path.rename(path.with_name(f"{new:06d}{path.name[6:]}"))
    for name, load, save in [("scene_camera.json", _BopWriterUtility.load_json, _BopWriterUtility.save_json),
                             ("scene_gt.json", _BopWriterUtility.load_json, _BopWriterUtility.save_json),
                             ("scene_gt_info.json", inout.load_json, inout.save_json)]:
        content = load(scene / name, keys_to_int=True)
        save(scene / name, {new_ids[old]: value for old, value in content.items()})


def write_faults(bad, scene):
    """Copies of `scene` broken one way each, with BOP's own writers."""
    import imageio.v2 as imageio
    from blenderproc.python.writer.BopWriterUtility import _BopWriterUtility
    from bop_toolkit_lib import inout

    for fault in ["missing-mask", "depth-size", "overlap"]:
        copy = bad / fault / "000000"
        shutil.copytree(scene, copy)
        if fault == "missing-mask":
            (copy / "mask_visib/000001_000002.png").unlink()
        elif fault == "depth-size":
            depth = imageio.imread(copy / "depth/000001.png")
            _BopWriterUtility.save_depth(str(copy / "depth/000001.png"), depth[:, :-1].astype(np.float64))
        else:
            # gt 1's visible mask grown onto gt 0's pixels.
            first = imageio.imread(copy / "mask_visib/000000_000000.png")
            second = imageio.imread(copy / "mask_visib/000000_000001.png")
            inout.save_im(copy / "mask_visib/000000_000001.png", np.maximum(first, second))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default="tests/fixtures/scenes")
    out = pathlib.Path(parser.parse_args().out)
    toolkit = os.environ.get("BOP_TOOLKIT")
    if not toolkit or not os.path.isdir(os.path.join(toolkit, "bop_toolkit_lib")):
        sys.exit("BOP_TOOLKIT must name a checkout of thodan/bop_toolkit (it holds bop_toolkit_lib/)")
    blender_stubs.install(toolkit)
    from blenderproc.python.types.MeshObjectUtility import MeshObject
    from blenderproc.python.writer.BopWriterUtility import _BopWriterUtility

    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        models = write_models(tmp / "bop-dataset/models")
        meshes = {i: blender_stubs.blender_mesh(m["pts"] / 1000.0, m["faces"]) for i, m in models.items()}
        # write_bop's meshes for its renderer, as it makes them; this pool renders the frames with them.
        trimeshes = {i: MeshObject(blender_stubs.BlenderObject(f"obj_{i:06d}", m)).mesh_as_trimesh()
                     for i, m in meshes.items()}
        with multiprocessing.Pool(1, _BopWriterUtility._pyrender_init, [WIDTH, HEIGHT, trimeshes]) as pool:
            for dataset, scene_ids in [("bop", [0, 1]), ("bop-dataset", [0])]:
                check_masks(tmp / dataset / "train_pbr", write_split(tmp, dataset, scene_ids, meshes, pool))
        for coco in tmp.glob("*/train_pbr/*/scene_gt_coco.json"):
            coco.unlink()

        split = tmp / "bop/train_pbr"
        renumber(split / "000001", list(SCENES[1]["images"]))
        (split / "000001/rgb").rename(split / "000001/gray")
        categories = {"categories": [{"id": 1, "name": "duck", "supercategory": "toy"}]}
        (split / "categories.json").write_text(json.dumps(categories, indent=2) + "\n")
        write_faults(tmp / "bop-bad", split / "000000")
        dataset = tmp / "bop-dataset"
        expected = {"000000": bop_keypoints.expected_keypoints(dataset / "train_pbr/000000", dataset / "models")}
        (dataset / "expected_keypoints.json").write_text(json.dumps(expected) + "\n")

        for name, made in [("bop", split), ("bop-dataset", dataset), ("bop-bad", tmp / "bop-bad")]:
            shutil.rmtree(out / name, ignore_errors=True)
            shutil.copytree(made, out / name)


if __name__ == "__main__":
    main()
