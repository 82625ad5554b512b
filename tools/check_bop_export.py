"""The BOP export's check for tools/check_exports.py (see its docstring): the export read with
bop_toolkit's own readers and held to the set it came from. BOP_TOOLKIT names a checkout of
thodan/bop_toolkit (not on the Python package registry).
"""

import glob
import json
import os
import sys
import tempfile

import imageio.v3 as iio
import Imath
import numpy as np
import OpenEXR
from pycocotools import mask as mask_utils


def read_exr_depth(path):
    exr = OpenEXR.InputFile(path)
    window = exr.header()["dataWindow"]
    width, height = window.max.x - window.min.x + 1, window.max.y - window.min.y + 1
    z = exr.channel("Z", Imath.PixelType(Imath.PixelType.FLOAT))
    return np.frombuffer(z, dtype=np.float32).reshape(height, width).astype(np.float64)


def box_corners(info):
    """models_info.json's box as the set's box keypoints: 8 corners (x slowest, min before max),
    then the centre, mm."""
    lo = np.array([info["min_x"], info["min_y"], info["min_z"]])
    hi = lo + [info["size_x"], info["size_y"], info["size_z"]]
    corners = [[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    return np.array(corners + [list((lo + hi) / 2)])


def gt_info(visible, whole, depth, misc):
    """calc_gt_info's fields from the visible and whole masks and the depth (mm)."""
    size = (visible.shape[1], visible.shape[0])

    def box(mask):
        ys, xs = mask.nonzero()
        return [int(e) for e in misc.calc_2d_bbox(xs, ys, size)] if len(xs) else [-1, -1, -1, -1]

    all_, visib = int(whole.sum()), int(visible.sum())
    return {"bbox_obj": box(whole), "bbox_visib": box(visible), "px_count_all": all_,
            "px_count_valid": int((depth[whole] > 0).sum()), "px_count_visib": visib,
            "visib_fract": visib / float(all_) if all_ else 0.0}


def check_bop(dataset, out):
    sys.path.insert(0, os.environ["BOP_TOOLKIT"])
    from bop_toolkit_lib import inout, misc
    from bop_toolkit_lib.dataset import bop_scenewise

    full = json.load(open(os.path.join(dataset, "annotations.json")))
    anns = {}
    for a in full["annotations"]:
        anns.setdefault(a["image_id"], []).append(a)
    # The export's rgb/ files are the set's images (linked or copied): found by their bytes.
    by_bytes = {open(os.path.join(dataset, i["file_name"]), "rb").read(): i for i in full["images"]}
    models_path = os.path.join(out, "models/models_info.json")
    models = inout.load_json(models_path, keys_to_int=True) if os.path.exists(models_path) else {}
    files = [models_path] if models else []
    seen, gts, empty, keypoints, worst_kp, worst_depth, worst_t = set(), 0, 0, 0, 0.0, 0.0, 0.0
    for scene in sorted(glob.glob(os.path.join(out, "*", "[0-9]" * 6))):
        files += [os.path.join(scene, f"{f}.json") for f in ("scene_camera", "scene_gt", "scene_gt_info")]
        infos = bop_scenewise.read_scene_infos(scene, read_image_ids=True)
        listed = inout.load_scene_gt(os.path.join(scene, "scene_gt.json"))
        for im_id in infos["image_ids"]:
            # load_image_data cannot stack the masks of an image without gts (a crop with none).
            any_gt = len(listed[im_id]) > 0
            data = bop_scenewise.load_image_data(scene, im_id, load_rgb=False, load_depth=True, load_mask_visib=any_gt,
                                                 load_mask=infos["has_mask"] and any_gt, load_gt=True, load_gt_info=True)
            image = by_bytes[open(os.path.join(scene, f"rgb/{im_id:06d}.png"), "rb").read()]
            seen.add(image["id"])
            camera, want = data["camera"], anns.get(image["id"], [])
            K = np.array(image["camera"]["K"])
            assert (camera["cam_K"] == K).all(), (scene, im_id)
            if image["camera"]["T_world_camera_opencv"] is not None:
                T = np.array(image["camera"]["T_world_camera_opencv"])
                assert np.abs(camera["cam_R_w2c"] - T[:3, :3].T).max() < 1e-12
                assert np.abs(camera["cam_t_w2c"].ravel() + T[:3, :3].T @ T[:3, 3] * 1000).max() < 1e-9
            metres = read_exr_depth(os.path.join(dataset, image["depth_file"]))
            has_depth = np.isfinite(metres) & (metres > 0)
            depth = data["im_depth"]
            assert ((depth > 0) == has_depth).all(), (scene, im_id)
            error = np.abs(depth[has_depth] - metres[has_depth] * 1000)
            assert error.max(initial=0) <= camera["depth_scale"] / 2 * (1 + 1e-6), (scene, im_id, error.max())
            worst_depth = max(worst_depth, error.max(initial=0))
            ids = iio.imread(os.path.join(dataset, image["mask_file"]))
            assert len(data["gt"]) == len(want) == len(data["gt_info"])
            empty += not any_gt
            for gt_id, (gt, info, a) in enumerate(zip(data["gt"], data["gt_info"], want)):
                visible = data["mask_visib"][gt_id] > 0
                assert (visible == mask_utils.decode(a["segmentation"]).astype(bool)).all()
                assert (visible == (ids == a["mask_id"])).all()
                whole = visible
                if "amodal_segmentation" in a:
                    whole = mask_utils.decode(a["amodal_segmentation"]).astype(bool)
                if infos["has_mask"]:
                    assert ((data["mask"][gt_id] > 0) == whole).all()
                assert gt["obj_id"] == a["category_id"]
                R, t = np.array(a["pose"]["R"]), np.array(a["pose"]["t"])
                assert (gt["cam_R_m2c"] == R).all()
                worst_t = max(worst_t, np.abs(gt["cam_t_m2c"].ravel() / 1000 - t).max())
                expected = gt_info(visible, whole, depth, misc)
                assert dict(info) == expected, (scene, im_id, gt_id, info, expected)
                if gt["obj_id"] in models and "keypoints" in a:
                    projected = misc.project_pts(box_corners(models[gt["obj_id"]]), K, gt["cam_R_m2c"], gt["cam_t_m2c"])
                    for (x, y, v), p in zip(np.array(a["keypoints"]).reshape(-1, 3), projected):
                        if v > 0:
                            worst_kp = max(worst_kp, np.abs(p - [x, y]).max())
                            keypoints += 1
                gts += 1
    assert seen == {i["id"] for i in full["images"]} and gts == len(full["annotations"]), (len(seen), gts)
    assert worst_kp <= 0.005 + 1e-9 and worst_t < 1e-12, (worst_kp, worst_t)
    # Each JSON file is what bop_toolkit's own writer makes of its content.
    for path in files:
        again = os.path.join(tempfile.mkdtemp(), "again.json")
        inout.save_json(again, inout.load_json(path, keys_to_int=True))
        assert open(again, "rb").read() == open(path, "rb").read(), path
    print(f"bop: bop_toolkit read {len(seen)} images ({empty} without gts), {gts} gts: masks, cameras and poses the set's "
          f"(t within {worst_t:.1e} m), depth within {worst_depth:.3f} mm, scene_gt_info as calc_gt_info computes it; "
          f"{keypoints} box keypoints at their project_pts projections (largest difference {worst_kp:.4f} px); "
          f"{len(files)} JSON files byte for byte as inout.save_json writes them")
