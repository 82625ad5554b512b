"""Each gt's nine box keypoints, computed with numpy from the files a BOP scene holds
(scene_camera.json, scene_gt.json, depth/, the dataset's models/models_info.json): what vkdiff's
BOP reader is held to in scenes/tests/bop.rs. Used by tools/make_bop_fixtures.py."""
import json

import imageio.v2 as imageio
import numpy as np


def box_points(model):
    """The box's corners (x slowest, then y, then z; min before max) and its centre, mm."""
    lo = np.array([model["min_x"], model["min_y"], model["min_z"]])
    hi = lo + np.array([model["size_x"], model["size_y"], model["size_z"]])
    corners = [[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    return np.array(corners + [list((lo + hi) / 2)])


def round_hundredth(c):
    """To 1/100 pixel, halves away from zero."""
    return float(np.sign(c) * np.floor(abs(c) * 100 + 0.5) / 100)


def expected_keypoints(scene_dir, models_dir):
    """Per image id, per gt: the box keypoints projected with cam_K, each [x, y, v]; seen (2)
    unless the depth at its pixel (metres, 0 = nothing) is nearer than 99 % of its own (1), and
    [0, 0, 0] outside the image."""
    models = json.loads((models_dir / "models_info.json").read_text())
    cameras = json.loads((scene_dir / "scene_camera.json").read_text())
    gts = json.loads((scene_dir / "scene_gt.json").read_text())
    out = {}
    for im_id, camera in cameras.items():
        K = np.array(camera["cam_K"]).reshape(3, 3)
        depth = imageio.imread(scene_dir / f"depth/{int(im_id):06d}.png").astype(np.float64)
        height, width = depth.shape
        depth = np.where(depth == 0, np.inf, depth * camera["depth_scale"] / 1000.0)
        out[im_id] = []
        for gt in gts[im_id]:
            R = np.array(gt["cam_R_m2c"]).reshape(3, 3)
            t = np.array(gt["cam_t_m2c"]) / 1000.0
            points = []
            for p in box_points(models[str(gt["obj_id"])]) / 1000.0:
                x, y, z = R @ p + t
                u, v = K[0, 0] * x / z + K[0, 2], K[1, 1] * y / z + K[1, 2]
                col, row = int(np.floor(u + 0.5)), int(np.floor(v + 0.5))
                if z <= 0 or not (0 <= col < width and 0 <= row < height):
                    points.append([0.0, 0.0, 0])
                    continue
                seen = depth[row, col] >= z * 0.99
                points.append([round_hundredth(u), round_hundredth(v), 2 if seen else 1])
            out[im_id].append(points)
    return out
