"""The 3D boxes of make_replicator_fixtures.py: rows as Replicator's bounding_box_3d annotator
gives them, placed around the drawn instances, and what vkdiff should make of them, computed here
with numpy alone.

Followed (read through the project's code, docs and pages search):
  - the row's dtype: omni.replicator.core's annotator definitions (the 2025 Apache-2.0 release),
    `bounding_box_3d_fast` and `bounding_box_3d` `output_data_type`: semanticId <u4; x_min,
    y_min, z_min, x_max, y_max, z_max <f4 (the prim's extent in its own frame, stage units);
    transform <f4 (4, 4); occlusionRatio <f4 (0 fully seen, 1 fully hidden). Older releases (the
    forum thread below, Replicator's "Annotators Information" page,
    docs.omniverse.nvidia.com/.../ext_replicator/annotators_details.html) had an instanceId
    first and no occlusionRatio; BasicWriter 0.0.2 saves the rows above;
  - the transform: the prim's local-to-world matrix in USD's row-vector convention, translation in
    the last row: the annotator's own example (a cone at x = 100 has [100, 0, 0, 1] as its last
    row); NVIDIA's answer in forums.developer.nvidia.com/t/mathematical-definition-of-3d-
    bounding-boxes-annotator-nvidia-omniverse-isaac-sim/223416 ("the transform matrix from
    object space to world space", corners then through cameraViewTransform and
    cameraProjection as row vectors); Isaac Sim's PoseWriter
    (source/extensions/isaacsim.replicator.writers/python/scripts/writers/pose_writer.py,
    __version__ 0.2.0): "Local space to world transform (row-major)", a box corner to the
    camera as corner @ transform @ cameraViewTransform. (The definitions' docstring of
    `bounding_box_3d_360` says "world to local", against its own example; PoseWriter's
    location_camera_frame multiplies the two matrices the other way round, which differs from
    its own corners in general: the corners' order is the one followed.) The prim's scale is in
    the transform (PoseWriter: the extent is "before scale").
"""
import numpy as np

BOX_DTYPE = np.dtype(
    [
        ("semanticId", "<u4"),
        ("x_min", "<f4"),
        ("y_min", "<f4"),
        ("z_min", "<f4"),
        ("x_max", "<f4"),
        ("y_max", "<f4"),
        ("z_max", "<f4"),
        ("transform", "<f4", (4, 4)),
        ("occlusionRatio", "<f4"),
    ]
)

# USD's camera axes (y up, looking along -z) to OpenCV's (y down, z forward) and back.
FLIP = np.diag([1.0, -1.0, -1.0])


def rotation(vector):
    """The rotation by |vector| radians about vector's direction (Rodrigues' formula)."""
    angle = np.linalg.norm(vector)
    k = np.asarray(vector, np.float64) / angle
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def place(obj, scale, turn, projection, view, size):
    """A box row's extent and transform for a drawn object (centre px, radii px, planar depth m):
    a box about as wide and tall as its drawing, its front face at the drawn depth, turned by
    the rotation vector `turn` (rad) in the camera's frame, its origin off its centre; the prim's `scale` (a negative
    entry mirrors) applied before its pose."""
    _, _, _, _, (cx, cy), (rx, ry), z = obj
    width, height = size
    fx, fy = projection[0, 0] * width / 2, projection[1, 1] * height / 2
    px, py = width / 2 * (1 - projection[2, 0]) - 0.5, height / 2 * (1 + projection[2, 1]) - 0.5
    hx, hy = rx * z / fx, ry * z / fy
    hz = min(hx, hy)
    lo, hi = np.array([-0.7 * hx, -0.5 * hy, -0.8 * hz]), np.array([1.3 * hx, 1.5 * hy, 1.2 * hz])
    turned = rotation(turn)
    centre = np.array([(cx - px) * z / fx, (cy - py) * z / fy, z + hz])
    object_to_camera = np.eye(4)
    object_to_camera[:3, :3] = turned
    object_to_camera[:3, 3] = centre - turned @ ((lo + hi) / 2)
    camera_usd_from_opencv = np.eye(4)
    camera_usd_from_opencv[:3, :3] = FLIP
    world_from_object = np.linalg.inv(view.T) @ camera_usd_from_opencv @ object_to_camera
    scale = np.array(scale, np.float64)
    local_to_world = (world_from_object @ np.diag([*scale, 1.0])).T
    local = np.sort(np.stack([lo / scale, hi / scale]), axis=0)
    return local[0], local[1], local_to_world


def row(semantic_id, lo, hi, transform, occlusion):
    return (semantic_id, *lo, *hi, transform, occlusion)


def unscaled(row_):
    """The row's transform with the prim's scale taken out (a mirror folded into x), and that
    scale: object point q = scale * local point."""
    transform = row_["transform"].astype(np.float64)
    scale = np.linalg.norm(transform[:3, :3], axis=1)
    if np.linalg.det(transform[:3, :3]) < 0:
        scale[0] = -scale[0]
    out = transform.copy()
    out[:3, :3] /= scale[:, None]
    return out, scale


def expected_pose_and_box(row_, view, metres):
    """pose (object -> camera, OpenCV, metres) and bbox_3d (metres), with 4x4 products."""
    transform, scale = unscaled(row_)
    local_lo = np.array([row_["x_min"], row_["y_min"], row_["z_min"]], np.float64)
    local_hi = np.array([row_["x_max"], row_["y_max"], row_["z_max"]], np.float64)
    object_to_camera = transform @ view  # row vectors: object -> world -> camera
    r = FLIP @ object_to_camera[:3, :3].T
    t = FLIP @ object_to_camera[3, :3] * metres
    lo = np.minimum(scale * local_lo, scale * local_hi) * metres
    hi = np.maximum(scale * local_lo, scale * local_hi) * metres
    return {"R": r.tolist(), "t": t.tolist()}, {"min": lo.tolist(), "max": hi.tolist()}


def round_hundredth(c):
    """To 1/100 pixel, halves away from zero, as annotations.json writes keypoints."""
    return float(np.sign(c) * np.floor(abs(c) * 100 + 0.5) / 100)


def expected_keypoints(row_, bbox, projection, view, depth, metres):
    """The box's corners (x slowest, min before max, in the object's frame) and centre, each
    taken back to the prim's own coordinates, through its transform, the view and the
    projection to pixels (NDC [-1, 1] spanning the pixel edges, rows from the top): seen (2)
    where the depth at its pixel is at least 99 % of its own, hidden (1) where nearer, absent
    outside or behind. Asserts that no keypoint lies within 1e-6 of a pixel's edge, of the 99 %
    line or of a rounding tie, so that float error cannot flip it."""
    _, scale = unscaled(row_)
    lo, hi = np.array(bbox["min"]), np.array(bbox["max"])
    corners = [[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    height, width = depth.shape
    points = []
    for q in np.array(corners + [list((lo + hi) / 2)]):
        local = np.append(q / metres / scale, 1.0)
        camera = local @ row_["transform"].astype(np.float64) @ view
        z = -camera[2] * metres
        clip = camera @ projection
        u = (clip[0] / clip[3] + 1) / 2 * width - 0.5
        v = (1 - clip[1] / clip[3]) / 2 * height - 0.5
        col, line = int(np.floor(u + 0.5)), int(np.floor(v + 0.5))
        if z > 0:
            for c in (u, v):
                assert abs((c + 0.5) - round(c + 0.5)) > 1e-6 and abs((c * 100) % 1 - 0.5) > 1e-6, c
        if z <= 0 or not (0 <= col < width and 0 <= line < height):
            points.append([0.0, 0.0, 0])
            continue
        surface = float(depth[line, col]) * metres
        assert abs(surface - 0.99 * z) > 1e-6, (surface, z)
        points.append([round_hundredth(u), round_hundredth(v), 2 if surface >= 0.99 * z else 1])
    return points
