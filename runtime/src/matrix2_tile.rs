//! Which tiles of `VK_NV_cooperative_matrix2`'s probe (kernels/wgsl/gemm_cm2.wgsl,
//! `ops::linear_cm2`) a device runs: those of workgroup scope where the driver offers that scope
//! for their workgroup size, those of subgroup scope where its flexible dimensions take them.

use crate::device::DeviceInfo;
use vkdiff_kernels::Dtype;

/// One built variant of the probe: an m×n accumulator a workgroup of `invocations`, walking K in
/// steps of k, on subgroups of `lanes`; its matrices of workgroup scope, or of subgroup scope
/// where the workgroup is one subgroup.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Matrix2Tile {
    pub m: u32,
    pub n: u32,
    pub k: u32,
    pub lanes: u32,
    pub invocations: u32,
}

impl Matrix2Tile {
    pub fn workgroup_scope(&self) -> bool {
        self.invocations > self.lanes
    }

    /// The kernel's parameters: FM, FN, FK, SG, WS and WG.
    pub fn params(&self) -> [(&'static str, u32); 6] {
        [
            ("FM", self.m),
            ("FN", self.n),
            ("FK", self.k),
            ("SG", self.lanes),
            ("WS", self.workgroup_scope() as u32),
            ("WG", self.invocations),
        ]
    }

    /// "128×128×32, workgroup scope (256 invocations)".
    pub fn label(&self) -> String {
        let scope = match self.workgroup_scope() {
            true => format!("workgroup scope ({} invocations)", self.invocations),
            false => format!("subgroup scope ({} lanes)", self.lanes),
        };
        format!("{}×{}×{}, {scope}", self.m, self.n, self.k)
    }
}

/// Every tile built (kernels/src/spec.rs).
pub fn built() -> Vec<Matrix2Tile> {
    vkdiff_kernels::variants("gemm_cm2", Dtype::F16)
        .map(|v| {
            let get = |name| v.param(name).expect("gemm_cm2 variants carry FM, FN, FK, SG and WG");
            Matrix2Tile { m: get("FM"), n: get("FN"), k: get("FK"), lanes: get("SG"), invocations: get("WG") }
        })
        .collect()
}

pub(crate) fn offered(info: &DeviceInfo) -> Vec<Matrix2Tile> {
    if !info.cooperative_features || !info.supports_f16() {
        return Vec::new();
    }
    let workgroup_scope = info.cooperative_matrix2.contains(&"workgroup scope");
    let runs = |t: &Matrix2Tile| match t.workgroup_scope() {
        true => {
            workgroup_scope
                && t.invocations <= info.max_workgroup_invocations
                && info.flexible_shapes.iter().any(|s| s.divides_for_workgroup((t.m, t.n, t.k), t.invocations))
        }
        false => info.flexible_shapes.iter().any(|s| s.divides(t.m, t.n, t.k)),
    };
    built().into_iter().filter(|t| info.can_use_subgroup(t.lanes) && runs(t)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::{tests::device, DeviceKind};
    use crate::matrix_units::MatrixShape;

    fn granularity(g: u32, subgroup_scope: bool, workgroup_invocations: u32) -> MatrixShape {
        let types = ["f16", "f16", "f32", "f32"];
        MatrixShape { m: g, n: g, k: g, types, subgroup_scope, workgroup_invocations }
    }

    #[test]
    fn tiles_are_offered_by_scope_workgroup_size_and_granularity() {
        // Mesa 26.1's lavapipe: flexible dimensions in multiples of 8 at subgroup scope, 8 lanes.
        let mut lavapipe = device(0, DeviceKind::Cpu, true);
        lavapipe.cooperative_features = true;
        lavapipe.subgroup_size = 8;
        lavapipe.flexible_shapes = vec![granularity(8, true, 0)];
        let tiles = offered(&lavapipe);
        assert!(!tiles.is_empty() && tiles.iter().all(|t| !t.workgroup_scope() && t.lanes == 8), "{tiles:?}");
        // A driver of workgroup scope at 256 invocations in multiples of 16, 32 lanes.
        let mut nvidia = device(1, DeviceKind::Discrete, true);
        nvidia.cooperative_features = true;
        nvidia.cooperative_matrix2 = vec!["workgroup scope", "flexible dimensions"];
        nvidia.flexible_shapes = vec![granularity(16, false, 256)];
        let tiles = offered(&nvidia);
        assert!(tiles.iter().any(|t| (t.m, t.n, t.k) == (128, 128, 32)), "{tiles:?}");
        assert!(tiles.iter().all(|t| t.workgroup_scope() && t.invocations == 256), "{tiles:?}");
        // At 128 invocations, the tile built for them.
        nvidia.flexible_shapes = vec![granularity(16, false, 128)];
        let tiles = offered(&nvidia);
        assert!(!tiles.is_empty() && tiles.iter().all(|t| t.invocations == 128), "{tiles:?}");
        // The scope unreported, a workgroup size no tile is built for, or no matrix units: none.
        nvidia.cooperative_matrix2 = vec!["flexible dimensions"];
        assert!(offered(&nvidia).is_empty());
        nvidia.cooperative_matrix2 = vec!["workgroup scope", "flexible dimensions"];
        nvidia.flexible_shapes = vec![granularity(16, false, 512)];
        assert!(offered(&nvidia).is_empty());
        lavapipe.cooperative_features = false;
        assert!(offered(&lavapipe).is_empty());
    }
}
