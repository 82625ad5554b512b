//! Triangle meshes and the one way this crate builds round things: revolving a profile curve.

use crate::math::Vec3;

/// An indexed triangle mesh. Triangles wind counter-clockwise seen from outside, so a closed mesh
/// can be back-face culled.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
}

/// A point of a profile curve in the (radius, height) half-plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProfilePoint {
    pub r: f64,
    pub z: f64,
}

/// Revolves `profile` (from the top pole downwards; the first point must lie on the axis, r = 0)
/// around the z axis in `segments` steps. `radial_scale(phi, r)` may vary each ring's radius
/// with the azimuth, which is how irregular caps are made. The bottom end is left open.
pub fn revolve(profile: &[ProfilePoint], segments: usize, radial_scale: impl Fn(f64, f64) -> f64) -> Mesh {
    assert!(profile.len() >= 2 && profile[0].r == 0.0 && segments >= 3, "degenerate profile");
    let mut mesh = Mesh::default();
    mesh.positions.push(Vec3::new(0.0, 0.0, profile[0].z));
    let sin_cos: Vec<(f64, f64)> =
        (0..segments).map(|j| (std::f64::consts::TAU * j as f64 / segments as f64).sin_cos()).collect();
    for p in &profile[1..] {
        for (j, &(s, c)) in sin_cos.iter().enumerate() {
            let phi = std::f64::consts::TAU * j as f64 / segments as f64;
            let r = p.r * radial_scale(phi, p.r);
            mesh.positions.push(Vec3::new(r * c, r * s, p.z));
        }
    }
    let ring = |i: usize, j: usize| (1 + (i - 1) * segments + j % segments) as u32;
    for j in 0..segments {
        mesh.triangles.push([0, ring(1, j), ring(1, j + 1)]);
    }
    for i in 1..profile.len() - 1 {
        for j in 0..segments {
            let (a, b) = (ring(i, j), ring(i, j + 1));
            let (c, d) = (ring(i + 1, j + 1), ring(i + 1, j));
            mesh.triangles.push([a, d, c]);
            mesh.triangles.push([a, c, b]);
        }
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed unit sphere from a profile: outward winding means every face normal points away
    /// from the centre, and the enclosed volume (divergence theorem) approaches 4π/3.
    #[test]
    fn revolved_sphere_winds_outward_and_encloses_its_volume() {
        let n = 64;
        let profile: Vec<ProfilePoint> = (0..=n)
            .map(|k| {
                let t = std::f64::consts::PI * k as f64 / n as f64;
                ProfilePoint { r: if k == 0 || k == n { 0.0 } else { t.sin() }, z: t.cos() }
            })
            .collect();
        let mesh = revolve(&profile, 96, |_, _| 1.0);
        let mut volume = 0.0;
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            let normal = (b - a).cross(c - a);
            let centroid = (a + b + c) * (1.0 / 3.0);
            if normal.length() > 1e-12 {
                assert!(normal.dot(centroid) > 0.0, "inward face {t:?}");
            }
            volume += a.dot(b.cross(c)) / 6.0;
        }
        let exact = 4.0 / 3.0 * std::f64::consts::PI;
        assert!((volume - exact).abs() / exact < 0.01, "volume {volume}");
    }
}
