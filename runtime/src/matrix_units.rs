//! The device's matrix units as `VK_KHR_cooperative_matrix` lists them, and which cooperative
//! kernel variant (kernels/src/spec.rs) fits them.

use ash::vk;

/// One product shape the device's matrix units take: A (M×K) · B (K×N) + C (M×N).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MatrixShape {
    pub m: u32,
    pub n: u32,
    pub k: u32,
    /// Component types of A, B, C and the result ("f16", "f32", "i8", …).
    pub types: [&'static str; 4],
    /// Whether a subgroup computes it together (the only scope the kernels use).
    pub subgroup_scope: bool,
}

impl MatrixShape {
    pub fn label(&self) -> String {
        let [a, b, c, r] = self.types;
        let scope = if self.subgroup_scope { "" } else { " (not subgroup scope)" };
        format!("{}×{}×{} {a}·{b}+{c}→{r}{scope}", self.m, self.n, self.k)
    }

    /// f16 operands with f32 accumulation, square, at subgroup scope: what the kernels compute.
    fn is_square_f16_f32(&self, size: u32) -> bool {
        (self.m, self.n, self.k) == (size, size, size)
            && self.types == ["f16", "f16", "f32", "f32"]
            && self.subgroup_scope
    }
}

fn component(t: vk::ComponentTypeKHR) -> &'static str {
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
        })
        .collect()
}

/// The cooperative variants built (kernels/src/spec.rs): fragment size and the subgroup widths
/// each is built for, in order of preference. 8×8 only at 8 lanes, the one width it is proven
/// at: lavapipe (the only driver known to list 8×8) offers no cooperativeMatrix feature at 4
/// lanes, and Mesa 26.1 crashes inside the driver running these kernels at 16.
const VARIANTS: [(u32, &[u32]); 2] = [(16, &[32, 64]), (8, &[8])];

/// The variants built, for messages: "16×16 at 32 or 64 lanes, 8×8 at 8 lanes".
pub fn built_cooperative_variants() -> String {
    let each = VARIANTS.map(|(size, widths)| {
        let widths: Vec<String> = widths.iter().map(u32::to_string).collect();
        format!("{size}×{size} at {} lanes", widths.join(" or "))
    });
    each.join(", ")
}

/// The cooperative variant for a device with `shapes`, whose subgroups `pinnable` can be made
/// a given width: (fragment size CM, subgroup width SG), or None where no variant fits.
pub(crate) fn pick(shapes: &[MatrixShape], pinnable: impl Fn(u32) -> bool) -> Option<(u32, u32)> {
    VARIANTS.iter().find_map(|&(size, widths)| {
        let listed = shapes.iter().any(|s| s.is_square_f16_f32(size));
        widths.iter().copied().find(|&sg| listed && pinnable(sg)).map(|sg| (size, sg))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape(m: u32, n: u32, k: u32, c: &'static str) -> MatrixShape {
        MatrixShape { m, n, k, types: ["f16", "f16", c, c], subgroup_scope: true }
    }

    #[test]
    fn picks_the_largest_listed_fragment_at_a_width_the_device_pins() {
        let nvidia = [shape(16, 16, 16, "f16"), shape(16, 16, 16, "f32"), shape(16, 8, 16, "f32")];
        assert_eq!(pick(&nvidia, |w| w == 32), Some((16, 32)));
        let amd_wave64_only = [shape(16, 16, 16, "f32")];
        assert_eq!(pick(&amd_wave64_only, |w| w == 64), Some((16, 64)));
        let lavapipe = [shape(8, 8, 8, "f32"), shape(8, 8, 8, "f16")];
        assert_eq!(pick(&lavapipe, |w| w == 8), Some((8, 8)));
        assert_eq!(pick(&lavapipe, |w| w == 16), None);
        // f16 accumulation only, a width no variant is built for, Intel's 8×16×16: none.
        assert_eq!(pick(&[shape(16, 16, 16, "f16")], |w| w == 32), None);
        assert_eq!(pick(&nvidia, |w| w == 128), None);
        assert_eq!(pick(&[shape(8, 16, 16, "f32")], |w| w == 16), None);
        assert_eq!(built_cooperative_variants(), "16×16 at 32 or 64 lanes, 8×8 at 8 lanes");
    }
}
