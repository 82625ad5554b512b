//! vkdiff's compute kernels: WGSL sources in `wgsl/`, compiled and validated by naga in `build.rs`,
//! embedded here as SPIR-V, one blob per variant (storage dtype × compile-time parameters).

include!("spec.rs");

/// One compiled variant of a kernel.
pub struct Variant {
    pub kernel: &'static str,
    pub dtype: Dtype,
    /// Compile-time parameters (tile sizes, subgroup width, operation codes).
    pub params: &'static [(&'static str, u32)],
    /// Little-endian SPIR-V words.
    pub spirv: &'static [u8],
}

include!(concat!(env!("OUT_DIR"), "/variants.rs"));

impl Variant {
    /// The value of a compile-time parameter, if this kernel has it.
    pub fn param(&self, name: &str) -> Option<u32> {
        self.params.iter().find(|(n, _)| *n == name).map(|(_, v)| *v)
    }

    /// SPIR-V as words (the embedded bytes carry no alignment guarantee).
    pub fn words(&self) -> Vec<u32> {
        self.spirv.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
    }
}

/// Every compiled variant of `kernel` in `dtype`.
pub fn variants(kernel: &str, dtype: Dtype) -> impl Iterator<Item = &'static Variant> + '_ {
    VARIANTS.iter().filter(move |v| v.kernel == kernel && v.dtype == dtype)
}

/// The variant of `kernel` whose parameters include every `(name, value)` in `want`.
pub fn find(kernel: &str, dtype: Dtype, want: &[(&str, u32)]) -> Option<&'static Variant> {
    variants(kernel, dtype).find(|v| want.iter().all(|(n, x)| v.param(n) == Some(*x)))
}
