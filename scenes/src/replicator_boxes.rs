//! The rows of Replicator BasicWriter's bounding_box_3d_N.npy (bounding_box_3d=True): each
//! prim's extent in its own frame and its local-to-world transform, in USD's row-vector
//! convention, so that a box corner reaches the camera as corner · transform ·
//! cameraViewTransform (as Isaac Sim's PoseWriter takes it there).

use crate::replicator::file;
use crate::replicator_camera::{dot, orthonormal, View};
use crate::replicator_files::{read_json, refuse};
use crate::SceneError;
use serde_json::{Map, Value};
use std::collections::BTreeMap;
use std::io::{BufReader, Read};
use std::path::Path;
use vkdiff_render::geometry::{Box3, ObjectPose};

/// One row of bounding_box_3d_N.npy, in scene units.
#[derive(Clone, Debug, PartialEq)]
struct BoxRow {
    semantic_id: u32,
    min: [f64; 3],
    max: [f64; 3],
    /// The prim's local-to-world transform, row-vector convention.
    transform: [[f64; 4]; 4],
}

/// The fields of a row as the bounding_box_3d annotator gives them (omni.replicator.core's
/// annotator registry) and BasicWriter np.saves them: semanticId <u4, transform <f4 4×4, the
/// rest <f4; occlusionRatio is read past, not used.
const BOX_FIELDS: [&str; 9] =
    ["semanticId", "x_min", "y_min", "z_min", "x_max", "y_max", "z_max", "transform", "occlusionRatio"];
/// Eight 4-byte fields and the transform's sixteen.
const ROW_BYTES: usize = 4 * (8 + 16);

fn box_dtype() -> npyz::DType {
    let plain = |t: &str| npyz::DType::Plain(t.parse().expect("a numpy type string"));
    let fields = BOX_FIELDS.iter().map(|&name| {
        let dtype = match name {
            "semanticId" => plain("<u4"),
            "transform" => npyz::DType::Array(4, Box::new(npyz::DType::Array(4, Box::new(plain("<f4"))))),
            _ => plain("<f4"),
        };
        npyz::Field { name: name.into(), dtype }
    });
    npyz::DType::Record(fields.collect())
}

/// A dtype as numpy lists it, shortly: `[semanticId <u4, …, transform <f4 (4, 4), …]`.
fn describe(dtype: &npyz::DType) -> String {
    match dtype {
        npyz::DType::Plain(t) => t.to_string(),
        npyz::DType::Array(..) => {
            let (mut shape, mut inner) = (Vec::new(), dtype);
            while let npyz::DType::Array(n, element) = inner {
                shape.push(n.to_string());
                inner = element;
            }
            format!("{} ({})", describe(inner), shape.join(", "))
        }
        npyz::DType::Record(fields) => {
            let fields: Vec<String> = fields.iter().map(|f| format!("{} {}", f.name, describe(&f.dtype))).collect();
            format!("[{}]", fields.join(", "))
        }
    }
}

/// The rows of a bounding_box_3d_N.npy; `Err` says what is wrong with the file.
fn read_box_rows(path: &Path) -> Result<Vec<BoxRow>, String> {
    let file = std::fs::File::open(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => "missing".to_string(),
        _ => e.to_string(),
    })?;
    let mut reader = BufReader::new(file);
    let header = npyz::NpyHeader::from_reader(&mut reader).map_err(|e| format!("not a .npy file: {e}"))?;
    let expected = box_dtype();
    if header.dtype() != expected {
        let (got, want) = (describe(&header.dtype()), describe(&expected));
        return Err(format!("dtype {got}; BasicWriter's bounding_box_3d rows are {want}"));
    }
    let &[rows] = header.shape() else {
        return Err(format!("shape {:?}; bounding_box_3d holds one row per prim", header.shape()));
    };
    let mut bytes = Vec::new();
    reader.read_to_end(&mut bytes).map_err(|e| format!("unreadable: {e}"))?;
    if bytes.len() as u64 != rows * ROW_BYTES as u64 {
        return Err(format!("{} bytes of rows; {rows} rows of {ROW_BYTES} bytes were announced", bytes.len()));
    }
    let rows = bytes.chunks_exact(ROW_BYTES).map(|row| {
        let word = |k: usize| <[u8; 4]>::try_from(&row[4 * k..4 * k + 4]).expect("4 bytes");
        let float = |k: usize| f32::from_le_bytes(word(k)) as f64;
        BoxRow {
            semantic_id: u32::from_le_bytes(word(0)),
            min: [float(1), float(2), float(3)],
            max: [float(4), float(5), float(6)],
            transform: std::array::from_fn(|i| std::array::from_fn(|j| float(7 + 4 * i + j))),
        }
    });
    Ok(rows.collect())
}

/// A row's box in metres and, where the view is known, its pose in the camera (OpenCV axes,
/// metres). The object's frame is the prim's with its scale taken out (the transform's rows'
/// lengths, applied to the extent instead), and a mirror (a negative determinant) folded into x,
/// so that the pose is a rotation. A transform that is not a scaled rotation and a translation
/// is refused.
fn object_box(row: &BoxRow, view: Option<&View>, metres_per_unit: f64) -> Result<(Box3, Option<ObjectPose>), String> {
    let m = &row.transform;
    if !row.min.iter().chain(&row.max).chain(m.iter().flatten()).all(|v| v.is_finite()) {
        return Err("holds a value that is not finite".into());
    }
    if (0..3).any(|i| row.min[i] > row.max[i]) {
        return Err(format!("its min {:?} is past its max {:?}", row.min, row.max));
    }
    if [m[0][3], m[1][3], m[2][3], m[3][3]] != [0.0, 0.0, 0.0, 1.0] {
        return Err("transform's last column is not [0, 0, 0, 1] (row-vector convention)".into());
    }
    // Row i is where the local axis i lands in the world: its length is the prim's scale there.
    let mut scale: [f64; 3] =
        std::array::from_fn(|i| (m[i][0] * m[i][0] + m[i][1] * m[i][1] + m[i][2] * m[i][2]).sqrt());
    if scale.iter().any(|&s| s <= 0.0) {
        return Err("transform scales an axis to nothing".into());
    }
    let mut axes: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| m[i][j] / scale[i]));
    if !orthonormal(&axes) {
        return Err("transform is sheared (its axes are not perpendicular)".into());
    }
    let cross = [
        axes[0][1] * axes[1][2] - axes[0][2] * axes[1][1],
        axes[0][2] * axes[1][0] - axes[0][0] * axes[1][2],
        axes[0][0] * axes[1][1] - axes[0][1] * axes[1][0],
    ];
    if dot(&cross, &axes[2]) < 0.0 {
        scale[0] = -scale[0];
        axes[0] = axes[0].map(|v| -v);
    }
    let ends = |i: usize| (scale[i] * row.min[i] * metres_per_unit, scale[i] * row.max[i] * metres_per_unit);
    let bbox = Box3 {
        min: std::array::from_fn(|i| ends(i).0.min(ends(i).1)),
        max: std::array::from_fn(|i| ends(i).0.max(ends(i).1)),
    };
    let pose = view.map(|v| {
        // world = axesᵀ·q + origin, camera = r·world + t; then USD's camera axes to OpenCV's.
        let origin = [m[3][0], m[3][1], m[3][2]];
        let flip = [1.0, -1.0, -1.0];
        ObjectPose {
            r: std::array::from_fn(|i| std::array::from_fn(|j| flip[i] * dot(&v.r[i], &axes[j]))),
            t: std::array::from_fn(|i| flip[i] * (dot(&v.r[i], &origin) + v.t[i]) * metres_per_unit),
        }
    });
    Ok((bbox, pose))
}

/// The files of frame N's boxes.
pub(crate) const BOXES: &str = "bounding_box_3d_";
const BOX_LABELS: &str = "bounding_box_3d_labels_";
const BOX_PRIMS: &str = "bounding_box_3d_prim_paths_";

/// The three files BasicWriter writes for a frame's boxes: the rows, idToLabels and primPaths.
pub(crate) fn box_files(frame: &str) -> [String; 3] {
    [file(BOXES, frame, "npy"), file(BOX_LABELS, frame, "json"), file(BOX_PRIMS, frame, "json")]
}

/// A frame's 3D boxes by prim path: the box in metres, and the pose where the view is known.
pub(crate) type FrameBoxes = BTreeMap<String, (Box3, Option<ObjectPose>)>;

/// Frame `frame`'s boxes, every row checked; `class_of` gives each instance's prim its class,
/// which the row's label must name too.
pub(crate) fn frame_boxes(
    dir: &Path,
    frame: &str,
    class_of: &BTreeMap<&str, &str>,
    view: Option<&View>,
    metres_per_unit: f64,
) -> Result<FrameBoxes, SceneError> {
    let [npy, labels_name, prims_name] = box_files(frame);
    let rows = read_box_rows(&dir.join(&npy)).map_err(|why| refuse(frame, &npy, why))?;
    let prims: Vec<String> = read_json(dir, frame, &prims_name)?;
    if prims.len() != rows.len() {
        return Err(refuse(frame, &prims_name, format!("lists {} prims; {npy} has {} rows", prims.len(), rows.len())));
    }
    let labels: BTreeMap<String, Map<String, Value>> = read_json(dir, frame, &labels_name)?;
    let mut boxes = FrameBoxes::new();
    for (k, (row, prim)) in rows.iter().zip(&prims).enumerate() {
        let label = labels.get(&row.semantic_id.to_string()).and_then(|l| l.get("class")?.as_str());
        let class = label.ok_or_else(|| {
            let why = format!("no class for semanticId {} (row {k}, {prim})", row.semantic_id);
            refuse(frame, &labels_name, why)
        })?;
        if let Some(shown) = class_of.get(prim.as_str()).filter(|&&shown| shown != class) {
            let why = format!("row {k} ({prim}) is `{class}`; the semantics mapping makes its instance `{shown}`");
            return Err(refuse(frame, &labels_name, why));
        }
        let found = object_box(row, view, metres_per_unit)
            .map_err(|why| refuse(frame, &npy, format!("row {k} ({prim}): {why}")))?;
        if boxes.insert(prim.clone(), found).is_some() {
            return Err(refuse(frame, &prims_name, format!("lists {prim} twice")));
        }
    }
    Ok(boxes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn turn(a: f64, b: f64) -> [[f64; 3]; 3] {
        let (ca, sa, cb, sb) = (a.cos(), a.sin(), b.cos(), b.sin());
        // About z by a, then about x by b.
        [[ca, -sa * cb, sa * sb], [sa, ca * cb, -ca * sb], [0.0, sb, cb]]
    }

    /// A row-vector 4×4: three rows, then the translation.
    fn affine(rows: [[f64; 3]; 3], origin: [f64; 3]) -> [[f64; 4]; 4] {
        let row = |r: [f64; 3], w: f64| [r[0], r[1], r[2], w];
        [row(rows[0], 0.0), row(rows[1], 0.0), row(rows[2], 0.0), row(origin, 1.0)]
    }

    /// The row-vector product p · M of a point with a 4×4 (the point's w = 1).
    fn through(p: [f64; 3], m: &[[f64; 4]; 4]) -> [f64; 3] {
        std::array::from_fn(|j| p[0] * m[0][j] + p[1] * m[1][j] + p[2] * m[2][j] + m[3][j])
    }

    #[test]
    fn a_scaled_mirrored_prim_in_a_centimetre_stage_keeps_its_corners_where_the_view_puts_them() {
        let (axes, scale) = (turn(0.7, -0.4), [-2.0, 0.5, 3.0]);
        let scaled: [[f64; 3]; 3] = std::array::from_fn(|i| axes[i].map(|a| a * scale[i]));
        let transform = affine(scaled, [40.0, -25.0, 310.0]);
        let row = BoxRow { semantic_id: 0, min: [-3.0, -1.0, 0.0], max: [5.0, 2.0, 4.0], transform };
        let view = View { r: turn(-1.1, 0.3), t: [12.0, -7.0, -500.0] };
        // camera = r·world + t as a row-vector matrix: rᵀ above t.
        let v = affine(std::array::from_fn(|i| std::array::from_fn(|j| view.r[j][i])), view.t);
        let metres = 0.01;
        let (bbox, pose) = object_box(&row, Some(&view), metres).unwrap();
        let pose = pose.unwrap();
        // The prim's own corners through its transform and the view, USD's camera axes turned to
        // OpenCV's, in metres; and the object box's corners through the pose: the same eight.
        let key = |p: [f64; 3]| p.map(|c| (c * 1e9).round() as i64);
        let mut want: Vec<[i64; 3]> = (0..8)
            .map(|k| {
                let local = std::array::from_fn(|i| if k >> i & 1 == 0 { row.min[i] } else { row.max[i] });
                let [x, y, z] = through(through(local, &row.transform), &v);
                key([x * metres, -y * metres, -z * metres])
            })
            .collect();
        let mut got: Vec<[i64; 3]> = bbox.points()[..8].iter().map(|&p| key(pose.apply(p))).collect();
        want.sort();
        got.sort();
        assert_eq!(got, want);
        let size: Vec<f64> = (0..3).map(|i| bbox.max[i] - bbox.min[i]).collect();
        for (i, s) in size.iter().enumerate() {
            assert!((s - scale[i].abs() * (row.max[i] - row.min[i]) * metres).abs() < 1e-12, "{size:?}");
        }
        let r = &pose.r;
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1]) - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        assert!((det - 1.0).abs() < 1e-12, "a rotation, not a mirror: {det}");
        assert_eq!(object_box(&row, None, metres).unwrap(), (bbox, None), "no view, no pose");
    }

    #[test]
    fn transforms_that_are_not_a_scaled_rotation_are_refused() {
        const IDENTITY: [[f64; 4]; 4] =
            [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
        let row = |transform| BoxRow { semantic_id: 0, min: [0.0; 3], max: [1.0; 3], transform };
        assert!(object_box(&row(IDENTITY), None, 1.0).is_ok());
        let why = |edit: &dyn Fn(&mut [[f64; 4]; 4])| {
            let mut transform = IDENTITY;
            edit(&mut transform);
            object_box(&row(transform), None, 1.0).unwrap_err()
        };
        assert!(why(&|m| m[1][0] = 0.5).contains("sheared"));
        assert!(why(&|m| m[1][1] = 0.0).contains("to nothing"));
        assert!(why(&|m| m[3][3] = 2.0).contains("last column"));
        assert!(why(&|m| m[3][0] = f64::NAN).contains("not finite"));
        let inverted = BoxRow { min: [0.0, 2.0, 0.0], ..row(IDENTITY) };
        assert!(object_box(&inverted, None, 1.0).unwrap_err().contains("past its max"));
    }
}
