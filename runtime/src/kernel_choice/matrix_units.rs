//! The device's matrix units as `VK_KHR_cooperative_matrix` lists them, and which cooperative
//! kernel variant (kernels/src/spec_cooperative.rs) fits them.

use ash::vk;

/// One product shape the device's matrix units take: A (M×K) · B (K×N) + C (M×N).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MatrixShape {
    pub m: u32,
    pub n: u32,
    pub k: u32,
    /// Component types of A, B, C and the result ("f16", "f32", "i8", …).
    pub types: [&'static str; 4],
    /// Whether a subgroup computes it together (the only scope the kernels but the
    /// `VK_NV_cooperative_matrix2` probe use).
    pub subgroup_scope: bool,
    /// At workgroup scope, the workgroup size it is offered for (flexible dimensions); else 0.
    pub workgroup_invocations: u32,
}

impl MatrixShape {
    pub fn label(&self) -> String {
        let [a, b, c, r] = self.types;
        let scope = match (self.subgroup_scope, self.workgroup_invocations) {
            (true, _) => String::new(),
            (false, 0) => " (not subgroup scope)".into(),
            (false, n) => format!(" (workgroup scope, {n} invocations)"),
        };
        format!("{}×{}×{} {a}·{b}+{c}→{r}{scope}", self.m, self.n, self.k)
    }

    /// As flexible-dimension granularities of workgroup scope: whether an M×N×K f16·f16+f32
    /// product on `invocations` is a multiple of them.
    pub(crate) fn divides_for_workgroup(&self, (m, n, k): (u32, u32, u32), invocations: u32) -> bool {
        let workgroup = !self.subgroup_scope && self.workgroup_invocations == invocations;
        workgroup && self.has_f16_f32_types() && self.granularities_divide(m, n, k)
    }

    /// M×N×K with f16 operands and f32 accumulation at subgroup scope: what the kernels compute.
    fn is_f16_f32(&self, m: u32, n: u32, k: u32) -> bool {
        (self.m, self.n, self.k) == (m, n, k) && self.computes_f16_f32()
    }

    /// As flexible-dimension granularities: whether M×N×K f16·f16+f32 at subgroup scope is a
    /// multiple of them.
    pub(crate) fn divides(&self, m: u32, n: u32, k: u32) -> bool {
        self.granularities_divide(m, n, k) && self.computes_f16_f32()
    }

    /// Whether M, N and K are multiples of this shape's sides, read as granularities.
    fn granularities_divide(&self, m: u32, n: u32, k: u32) -> bool {
        let multiple = |x: u32, g: u32| g > 0 && x.is_multiple_of(g);
        multiple(m, self.m) && multiple(n, self.n) && multiple(k, self.k)
    }

    fn has_f16_f32_types(&self) -> bool {
        self.types == ["f16", "f16", "f32", "f32"]
    }

    fn computes_f16_f32(&self) -> bool {
        self.has_f16_f32_types() && self.subgroup_scope
    }
}

pub(crate) fn component(t: vk::ComponentTypeKHR) -> &'static str {
    match t {
        vk::ComponentTypeKHR::FLOAT16 => "f16",
        vk::ComponentTypeKHR::FLOAT32 => "f32",
        vk::ComponentTypeKHR::FLOAT64 => "f64",
        vk::ComponentTypeKHR::SINT8 => "i8",
        vk::ComponentTypeKHR::SINT16 => "i16",
        vk::ComponentTypeKHR::SINT32 => "i32",
        vk::ComponentTypeKHR::SINT64 => "i64",
        vk::ComponentTypeKHR::UINT8 => "u8",
        vk::ComponentTypeKHR::UINT16 => "u16",
        vk::ComponentTypeKHR::UINT32 => "u32",
        vk::ComponentTypeKHR::UINT64 => "u64",
        // VK_KHR_shader_bfloat16 and VK_EXT_shader_float8, newer than ash's headers.
        t if t.as_raw() == 1_000_141_000 => "bf16",
        t if t.as_raw() == 1_000_491_002 => "fp8 e4m3",
        t if t.as_raw() == 1_000_491_003 => "fp8 e5m2",
        _ => "other",
    }
}

/// The shapes `pd` lists; empty without the extension or where the query fails.
pub(crate) fn query(entry: &ash::Entry, instance: &ash::Instance, pd: vk::PhysicalDevice) -> Vec<MatrixShape> {
    let loader = ash::khr::cooperative_matrix::Instance::new(entry, instance);
    // SAFETY: pd comes from this instance, which has the extension's entry point where the
    // device lists it (checked by the caller).
    let props = unsafe { loader.get_physical_device_cooperative_matrix_properties(pd) }.unwrap_or_default();
    props
        .iter()
        .map(|p| MatrixShape {
            m: p.m_size,
            n: p.n_size,
            k: p.k_size,
            types: [p.a_type, p.b_type, p.c_type, p.result_type].map(component),
            subgroup_scope: p.scope == vk::ScopeKHR::SUBGROUP,
            workgroup_invocations: 0,
        })
        .collect()
}

/// A cooperative kernel variant: fragments A (m×k) · B (k×n) + C (m×n), f16 operands and f32
/// sums, on subgroups pinned to `lanes`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fragment {
    pub m: u32,
    pub n: u32,
    pub k: u32,
    pub lanes: u32,
    /// Whether the device runs this shape only through `VK_NV_cooperative_matrix2`'s flexible
    /// dimensions (it lists no such shape itself), which the device is then created with.
    pub flexible: bool,
}

impl Fragment {
    /// The kernels' parameters for it: FM, FN, FK and SG.
    pub fn params(&self) -> [(&'static str, u32); 4] {
        [("FM", self.m), ("FN", self.n), ("FK", self.k), ("SG", self.lanes)]
    }

    /// "8×16×16".
    pub fn shape(&self) -> String {
        format!("{}×{}×{}", self.m, self.n, self.k)
    }
}

/// (M, N, K) of a fragment.
type Shape = (u32, u32, u32);

/// The cooperative variants built (kernels/src/spec_cooperative.rs): fragment shape (M, N, K) and the
/// subgroup widths each is built for, in order of preference. 16×16×16 is NVIDIA's and AMD's,
/// 8×16×16 Intel Xe2's (16 lanes), 8×8×16 Intel Xe-HPG's (8 lanes), 8×8×8 lavapipe's. 8×16×16 at
/// 8 lanes is the instantiation lavapipe proves (through flexible dimensions) for Xe2's. 8-wide
/// fragments only at 8 and 16 lanes: lavapipe offers no cooperativeMatrix feature at 4 lanes,
/// and Mesa 26.1 crashes inside the driver running these kernels at 16.
const VARIANTS: [(Shape, &[u32]); 4] =
    [((16, 16, 16), &[32, 64]), ((8, 16, 16), &[16, 8]), ((8, 8, 16), &[8]), ((8, 8, 8), &[8])];

/// The variants built, for messages: "16×16×16 at 32 or 64 lanes, 8×16×16 at 16 or 8 lanes, …".
pub fn built_cooperative_variants() -> String {
    let each = VARIANTS.map(|((m, n, k), widths)| {
        let widths: Vec<String> = widths.iter().map(u32::to_string).collect();
        format!("{m}×{n}×{k} at {} lanes", widths.join(" or "))
    });
    each.join(", ")
}

/// What `VKDIFF_FRAGMENT` takes: one of the shapes built, as MxNxK.
pub(crate) fn fragment_values() -> String {
    format!("one of the shapes vkdiff builds, as MxNxK ({})", built_cooperative_variants())
}

/// `MxNxK` (such as `8x16x16`, or with `×`): a fragment shape vkdiff builds; None for any other.
pub(crate) fn parse_fragment(text: &str) -> Option<Shape> {
    let numbers: Vec<Option<u32>> = text.split(['x', '×']).map(|w| w.trim().parse().ok()).collect();
    match numbers[..] {
        [Some(m), Some(n), Some(k)] if VARIANTS.iter().any(|(shape, _)| *shape == (m, n, k)) => Some((m, n, k)),
        _ => None,
    }
}

/// The cooperative variant for a device with `shapes`, whose subgroups `pinnable` can be made a
/// given width: the first built variant the device lists at a width it pins. Where a shape is
/// asked for (`request`), only that one, listed or else taken through flexible dimensions
/// (`flexible`: their granularities). Flexible dimensions serve requests only: Mesa 26.1
/// lavapipe offers them at 16 lanes too, where it crashed running these kernels. None where
/// no variant fits.
pub(crate) fn pick(
    shapes: &[MatrixShape],
    flexible: &[MatrixShape],
    pinnable: impl Fn(u32) -> bool,
    request: Option<Shape>,
) -> Option<Fragment> {
    let wanted = VARIANTS.iter().filter(|(shape, _)| request.is_none_or(|r| r == *shape));
    let fitting = |flexible_ok: bool| {
        wanted.clone().find_map(|&((m, n, k), widths)| {
            let listed = shapes.iter().any(|s| s.is_f16_f32(m, n, k));
            let flex = flexible_ok && !listed && flexible.iter().any(|g| g.divides(m, n, k));
            let lanes = widths.iter().copied().find(|&sg| (listed || flex) && pinnable(sg))?;
            Some(Fragment { m, n, k, lanes, flexible: flex })
        })
    };
    fitting(false).or_else(|| fitting(request.is_some()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape(m: u32, n: u32, k: u32, c: &'static str) -> MatrixShape {
        MatrixShape { m, n, k, types: ["f16", "f16", c, c], subgroup_scope: true, workgroup_invocations: 0 }
    }

    fn fits(m: u32, n: u32, k: u32, lanes: u32, flexible: bool) -> Option<Fragment> {
        Some(Fragment { m, n, k, lanes, flexible })
    }

    #[test]
    fn picks_the_largest_listed_fragment_at_a_width_the_device_pins() {
        let pick = |shapes: &[MatrixShape], width: u32| pick(shapes, &[], |w| w == width, None);
        let nvidia = [shape(16, 16, 16, "f16"), shape(16, 16, 16, "f32"), shape(16, 8, 16, "f32")];
        assert_eq!(pick(&nvidia, 32), fits(16, 16, 16, 32, false));
        let amd_wave64_only = [shape(16, 16, 16, "f32")];
        assert_eq!(pick(&amd_wave64_only, 64), fits(16, 16, 16, 64, false));
        let lavapipe = [shape(8, 8, 8, "f32"), shape(8, 8, 8, "f16")];
        assert_eq!(pick(&lavapipe, 8), fits(8, 8, 8, 8, false));
        assert_eq!(pick(&lavapipe, 16), None);
        // Intel: Xe2 lists 8×16×16 at 16 lanes, Xe-HPG 8×8×16 at 8.
        assert_eq!(pick(&[shape(8, 16, 16, "f32")], 16), fits(8, 16, 16, 16, false));
        assert_eq!(pick(&[shape(8, 8, 16, "f32")], 8), fits(8, 8, 16, 8, false));
        // f16 accumulation only, a width no variant is built for, a shape none is built for: none.
        assert_eq!(pick(&[shape(16, 16, 16, "f16")], 32), None);
        assert_eq!(pick(&nvidia, 128), None);
        assert_eq!(pick(&[shape(16, 8, 16, "f32")], 32), None);
        assert_eq!(
            built_cooperative_variants(),
            "16×16×16 at 32 or 64 lanes, 8×16×16 at 16 or 8 lanes, 8×8×16 at 8 lanes, 8×8×8 at 8 lanes"
        );
    }

    #[test]
    fn flexible_dimensions_serve_a_shape_asked_for() {
        // Mesa 26.1 lavapipe: 8×8×8 listed, any multiple of 8 through flexible dimensions.
        let lavapipe = [shape(8, 8, 8, "f32")];
        let granular = [shape(8, 8, 8, "f32")];
        let eight = |w: u32| w == 8;
        assert_eq!(pick(&lavapipe, &granular, eight, None), fits(8, 8, 8, 8, false), "listed shapes first");
        assert_eq!(pick(&[], &granular, eight, None), None, "only where asked for");
        assert_eq!(pick(&lavapipe, &granular, eight, Some((8, 16, 16))), fits(8, 16, 16, 8, true));
        assert_eq!(pick(&lavapipe, &granular, eight, Some((8, 8, 16))), fits(8, 8, 16, 8, true));
        assert_eq!(pick(&lavapipe, &[], eight, Some((8, 16, 16))), None, "no flexible dimensions");
        assert_eq!(pick(&lavapipe, &[shape(16, 16, 16, "f32")], eight, Some((8, 16, 16))), None, "granularity 16");
        assert_eq!(pick(&lavapipe, &granular, |w| w == 4, Some((8, 8, 8))), None, "no width it pins");
    }

    #[test]
    fn a_requested_fragment_is_a_shape_vkdiff_builds() {
        assert_eq!(parse_fragment("8x16x16"), Some((8, 16, 16)));
        assert_eq!(parse_fragment("8×8×16"), Some((8, 8, 16)));
        for bad in ["16x8x16", "8x8", "eight", "8x8x8x8"] {
            assert_eq!(parse_fragment(bad), None, "{bad}");
        }
        assert!(fragment_values().contains("8×16×16 at 16 or 8 lanes"), "{}", fragment_values());
    }
}
