//! The depth map as a depth ControlNet expects it: normalised per image over its valid pixels,
//! near = bright, replicated to three 8-bit channels (diffusers' SDXL depth ControlNet is fed
//! MiDaS-style relative inverse depth, min–max normalised per image). The other controls a frame's
//! labels give exactly: [`edges`], [`segmentation`] and [`normals`].

mod ade20k;
pub mod edges;
pub mod normals;
pub mod segmentation;

use rayon::prelude::*;

/// A control image a frame's labels give.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ControlKind {
    Depth,
    Edges,
    Segmentation,
    Normals,
}

impl ControlKind {
    pub const ALL: [ControlKind; 4] =
        [ControlKind::Depth, ControlKind::Edges, ControlKind::Segmentation, ControlKind::Normals];

    /// Its name on the command line, in file names and in dataset.json.
    pub fn name(self) -> &'static str {
        match self {
            ControlKind::Depth => "depth",
            ControlKind::Edges => "edges",
            ControlKind::Segmentation => "segmentation",
            ControlKind::Normals => "normals",
        }
    }

    pub fn parse(name: &str) -> Option<ControlKind> {
        ControlKind::ALL.into_iter().find(|k| k.name() == name.trim())
    }
}

/// How depth becomes brightness.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ControlDepth {
    /// Brightness linear in 1/z: what MiDaS/DPT estimators produce.
    #[default]
    Inverse,
    /// Brightness linear in z (reversed, near = bright).
    Linear,
}

/// RGB8 control image of `depth` (metres; non-finite or non-positive pixels are invalid and
/// black). A frame of a single depth is all white: everything in it is nearest.
pub fn control_image(depth: &[f32], mode: ControlDepth) -> Vec<u8> {
    let valid = |z: f32| z.is_finite() && z > 0.0;
    let value = |z: f32| match mode {
        ControlDepth::Inverse => 1.0 / z as f64,
        ControlDepth::Linear => -(z as f64),
    };
    let (lo, hi) = depth
        .par_iter()
        .filter(|&&z| valid(z))
        .map(|&z| (value(z), value(z)))
        .reduce(|| (f64::MAX, f64::MIN), |a, b| (a.0.min(b.0), a.1.max(b.1)));
    let range = hi - lo;
    depth
        .par_iter()
        .flat_map_iter(|&z| {
            let level = if !valid(z) {
                0
            } else if range > 0.0 {
                // + 0.5 and truncation: rounding of a non-negative value, without a libm call.
                (255.0 * (value(z) - lo) / range + 0.5) as u8
            } else {
                255
            };
            [level; 3]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn near_is_bright_and_the_range_is_stretched_per_image() {
        let depth = [0.96f32, 1.0, 0.98, f32::INFINITY];
        let inverse = control_image(&depth, ControlDepth::Inverse);
        assert_eq!(inverse.len(), 12);
        assert_eq!(&inverse[0..3], &[255, 255, 255]);
        assert_eq!(&inverse[3..6], &[0, 0, 0]);
        assert_eq!(inverse[9], 0, "invalid pixels are black");
        // 1/z is convex, so the midpoint in z sits below half-way in 1/z.
        let expected = ((1.0 / 0.98f32 as f64 - 1.0) / (1.0 / 0.96f32 as f64 - 1.0) * 255.0).round() as u8;
        assert_eq!(inverse[6], expected);
        let linear = control_image(&depth, ControlDepth::Linear);
        assert_eq!(linear[6], ((1.0 - 0.98f32 as f64) / (1.0 - 0.96f32 as f64) * 255.0).round() as u8);
        assert!(inverse[6] < linear[6]);
        assert_eq!(control_image(&[0.5, 0.5], ControlDepth::Linear), vec![255; 6]);
    }
}
