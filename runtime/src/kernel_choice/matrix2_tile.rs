//! Which tiles of `VK_NV_cooperative_matrix2`'s probes a device runs: the linear layers'
//! product (kernels/wgsl/gemm_cm2.wgsl, `ops::linear_cm2`), the convolution
//! (kernels/wgsl/conv_cm2.wgsl, `ops::conv2d_cm2`) and attention
//! (kernels/wgsl/attention_cm2.wgsl, `ops::attention_cm2`); those of workgroup scope where the
//! driver offers that scope for their workgroup size, those of subgroup scope where its flexible
//! dimensions take them, each with the features its kernel uses.

use crate::device::DeviceInfo;
use vkdiff_kernels::Dtype;

/// What a probe computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Matrix2Probe {
    /// out = A·Bᵀ: an m×n accumulator walking K in steps of k.
    Linear,
    /// A convolution's implicit GEMM: m output pixels × n output channels, K in steps of k.
    Conv,
    /// Attention: m query rows against chunks of n keys, heads of up to k values.
    Attention,
}

impl Matrix2Probe {
    pub fn kernel(self) -> &'static str {
        match self {
            Matrix2Probe::Linear => "gemm_cm2",
            Matrix2Probe::Conv => "conv_cm2",
            Matrix2Probe::Attention => "attention_cm2",
        }
    }

    /// The extension's features the kernel uses beyond its matrices' dimensions and scope (as
    /// `DeviceInfo::cooperative_matrix2` names them).
    pub fn features(self) -> &'static [&'static str] {
        match self {
            Matrix2Probe::Linear | Matrix2Probe::Conv => &["conversions", "per-element operations"],
            Matrix2Probe::Attention => &["reductions", "conversions", "per-element operations"],
        }
    }
}

/// One built variant of a probe: m, n and k as [`Matrix2Probe`] reads them, on subgroups of
/// `lanes`; its matrices of workgroup scope, or of subgroup scope where the workgroup is one
/// subgroup.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Matrix2Tile {
    pub probe: Matrix2Probe,
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

    /// The products its matrices take: the linear and convolution tiles' m×n×k; attention's S = Q·Kᵀ (m×n×k)
    /// and O = P·V (m×k×n).
    fn products(&self) -> Vec<(u32, u32, u32)> {
        match self.probe {
            Matrix2Probe::Linear | Matrix2Probe::Conv => vec![(self.m, self.n, self.k)],
            Matrix2Probe::Attention => vec![(self.m, self.n, self.k), (self.m, self.k, self.n)],
        }
    }

    /// The workgroup memory its kernel declares: none for the linear probe (the driver stages its
    /// operands); conv_cm2.wgsl's gathered A step (f16, 8 values of padding a row); attention_cm2.wgsl's staged K and V rows (f16, 8 values of padding each), its
    /// output rows (f32, 4 of padding) and one flag.
    pub fn workgroup_bytes(&self) -> u32 {
        match self.probe {
            Matrix2Probe::Linear => 0,
            Matrix2Probe::Conv => self.m * (self.k + 8) * 2,
            Matrix2Probe::Attention => 2 * self.n * (self.k + 8) * 2 + self.m * (self.k + 4) * 4 + 4,
        }
    }

    /// "linear 128×128×32 at workgroup scope (256 invocations)"; "convolution 128 pixels × 64
    /// channels in K-steps of 32 at …"; "attention 8 rows × 32 keys with heads of up to 64 at
    /// subgroup scope (8 lanes)": no commas, so that a list of them reads.
    pub fn label(&self) -> String {
        let scope = match self.workgroup_scope() {
            true => format!("workgroup scope ({} invocations)", self.invocations),
            false => format!("subgroup scope ({} lanes)", self.lanes),
        };
        match self.probe {
            Matrix2Probe::Linear => format!("linear {}×{}×{} at {scope}", self.m, self.n, self.k),
            Matrix2Probe::Conv => {
                format!("convolution {} pixels × {} channels in K-steps of {} at {scope}", self.m, self.n, self.k)
            }
            Matrix2Probe::Attention => {
                format!("attention {} rows × {} keys with heads of up to {} at {scope}", self.m, self.n, self.k)
            }
        }
    }
}

/// Every tile built of `probe` (kernels/src/spec_cooperative.rs).
pub fn built(probe: Matrix2Probe) -> Vec<Matrix2Tile> {
    vkdiff_kernels::variants(probe.kernel(), Dtype::F16)
        .map(|v| {
            let get = |name| v.param(name).expect("the probes' variants carry FM, FN, FK, SG and WG");
            Matrix2Tile { probe, m: get("FM"), n: get("FN"), k: get("FK"), lanes: get("SG"), invocations: get("WG") }
        })
        .collect()
}

pub(crate) fn offered(info: &DeviceInfo) -> Vec<Matrix2Tile> {
    if !info.cooperative_features || !info.supports_f16() {
        return Vec::new();
    }
    let reported = |feature: &&str| info.cooperative_matrix2.contains(feature);
    let workgroup_scope = reported(&"workgroup scope");
    let runs = |t: &Matrix2Tile| {
        let divide = |s: &crate::kernel_choice::matrix_units::MatrixShape| match t.workgroup_scope() {
            true => t.products().into_iter().all(|p| s.divides_for_workgroup(p, t.invocations)),
            false => t.products().into_iter().all(|(m, n, k)| s.divides(m, n, k)),
        };
        let scope = !t.workgroup_scope() || (workgroup_scope && t.invocations <= info.max_workgroup_invocations);
        let memory = t.workgroup_bytes() <= info.max_shared_memory;
        scope && memory && t.probe.features().iter().all(reported) && info.flexible_shapes.iter().any(divide)
    };
    [Matrix2Probe::Linear, Matrix2Probe::Conv, Matrix2Probe::Attention]
        .into_iter()
        .flat_map(built)
        .filter(|t| info.can_use_subgroup(t.lanes) && runs(t))
        .collect()
}

/// The extension's features a context enables: flexible dimensions (the matrix-unit kernels'
/// fragments may take them), and what `tiles` use.
pub(crate) fn features(tiles: &[Matrix2Tile]) -> Vec<&'static str> {
    let mut features = vec!["flexible dimensions"];
    if tiles.iter().any(|t| t.workgroup_scope()) {
        features.push("workgroup scope");
    }
    for feature in tiles.iter().flat_map(|t| t.probe.features()) {
        if !features.contains(feature) {
            features.push(feature);
        }
    }
    features
}

impl DeviceInfo {
    /// The tiles of `VK_NV_cooperative_matrix2`'s probes (`ops::linear_cm2`, `ops::conv2d_cm2`,
    /// `ops::attention_cm2`) this device runs.
    pub fn matrix2_tiles(&self) -> Vec<Matrix2Tile> {
        offered(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::{tests::device, DeviceKind};
    use crate::kernel_choice::matrix_units::MatrixShape;

    fn granularity(g: u32, subgroup_scope: bool, workgroup_invocations: u32) -> MatrixShape {
        let types = ["f16", "f16", "f32", "f32"];
        MatrixShape { m: g, n: g, k: g, types, subgroup_scope, workgroup_invocations }
    }

    #[test]
    fn a_context_enables_the_features_its_tiles_use() {
        assert_eq!(features(&[]), ["flexible dimensions"]);
        let [linear, attention] = [Matrix2Probe::Linear, Matrix2Probe::Attention].map(built);
        let subgroup = linear.iter().find(|t| !t.workgroup_scope()).copied().unwrap();
        let workgroup = linear.iter().find(|t| t.workgroup_scope()).copied().unwrap();
        let epilogue = ["conversions", "per-element operations"];
        assert_eq!(features(&[subgroup]), [&["flexible dimensions"][..], &epilogue].concat());
        assert_eq!(
            features(&[subgroup, workgroup]),
            [&["flexible dimensions", "workgroup scope"][..], &epilogue].concat()
        );
        let twin = attention.iter().find(|t| !t.workgroup_scope()).copied().unwrap();
        let all = ["flexible dimensions", "reductions", "conversions", "per-element operations"];
        assert_eq!(features(&[twin, subgroup, twin]), all, "each feature once");
    }

    #[test]
    fn tiles_are_offered_by_scope_workgroup_size_and_granularity() {
        // Mesa 26.1's lavapipe: flexible dimensions in multiples of 8 at subgroup scope, 8 lanes.
        let mut lavapipe = device(0, DeviceKind::Cpu, true);
        lavapipe.cooperative_features = true;
        lavapipe.subgroup_size = 8;
        lavapipe.flexible_shapes = vec![granularity(8, true, 0)];
        assert!(offered(&lavapipe).is_empty(), "every probe needs the extension's operations");
        let probes = |tiles: &[Matrix2Tile]| {
            [Matrix2Probe::Linear, Matrix2Probe::Conv, Matrix2Probe::Attention]
                .map(|p| tiles.iter().any(|t| t.probe == p))
        };
        // With the reductions, conversions and per-element operations it reports, all three.
        lavapipe.cooperative_matrix2 =
            vec!["flexible dimensions", "reductions", "conversions", "per-element operations"];
        let tiles = offered(&lavapipe);
        assert!(tiles.iter().all(|t| !t.workgroup_scope() && t.lanes == 8), "{tiles:?}");
        assert_eq!(probes(&tiles), [true; 3]);
        let attention: Vec<_> = tiles.into_iter().filter(|t| t.probe == Matrix2Probe::Attention).collect();
        assert_eq!(attention.len(), 1, "{attention:?}");
        assert_eq!((attention[0].m, attention[0].n, attention[0].k, attention[0].lanes), (8, 32, 64, 8));
        lavapipe.cooperative_matrix2.remove(1);
        assert_eq!(probes(&offered(&lavapipe)), [true, true, false], "attention needs the reductions");
        lavapipe.cooperative_matrix2.pop();
        assert!(offered(&lavapipe).is_empty(), "per-element operations unreported");
        // A driver of workgroup scope at 256 invocations in multiples of 16, 32 lanes, with the
        // operations the linear and convolution probes use.
        let mut nvidia = device(1, DeviceKind::Discrete, true);
        nvidia.cooperative_features = true;
        let scope = ["workgroup scope", "flexible dimensions"];
        nvidia.cooperative_matrix2 = [&scope[..], Matrix2Probe::Conv.features()].concat();
        nvidia.flexible_shapes = vec![granularity(16, false, 256)];
        let tiles = offered(&nvidia);
        assert!(tiles.iter().any(|t| (t.m, t.n, t.k) == (128, 128, 32)), "{tiles:?}");
        assert_eq!(probes(&tiles), [true, true, false], "{tiles:?}");
        assert!(tiles.iter().all(|t| t.workgroup_scope() && t.invocations == 256), "{tiles:?}");
        // At 128 invocations, the tiles built for them; the convolution's gathers its A step in
        // 128 rows of 32 + 8 halves.
        nvidia.flexible_shapes = vec![granularity(16, false, 128)];
        let tiles = offered(&nvidia);
        assert!(!tiles.is_empty() && tiles.iter().all(|t| t.invocations == 128), "{tiles:?}");
        let conv: Vec<_> =
            tiles.iter().filter(|t| t.probe == Matrix2Probe::Conv).map(|t| (t.n, t.workgroup_bytes())).collect();
        assert_eq!(conv, [(64, 10240)]);
        nvidia.cooperative_matrix2.push("reductions");
        let attention = |info: &DeviceInfo| offered(info).into_iter().filter(|t| t.probe == Matrix2Probe::Attention);
        nvidia.max_shared_memory = 49152; // NVIDIA's 48 KiB
        assert_eq!(attention(&nvidia).count(), 2, "both attention tiles of 128 invocations");
        // With 32 KiB of workgroup memory, the 32×128 tile's 45 KiB does not fit.
        nvidia.max_shared_memory = 32768;
        let fitting: Vec<_> = attention(&nvidia).map(|t| (t.m, t.n, t.workgroup_bytes())).collect();
        assert_eq!(fitting, [(64, 32, 26628)]);
        // The scope unreported, a workgroup size no tile is built for, or no matrix units: none.
        nvidia.cooperative_matrix2.retain(|f| *f != "workgroup scope");
        assert!(offered(&nvidia).is_empty());
        nvidia.cooperative_matrix2.push("workgroup scope");
        nvidia.flexible_shapes = vec![granularity(16, false, 512)];
        assert!(offered(&nvidia).is_empty());
        lavapipe.cooperative_matrix2.push("per-element operations");
        assert!(!offered(&lavapipe).is_empty());
        lavapipe.cooperative_features = false;
        assert!(offered(&lavapipe).is_empty());
    }
}
