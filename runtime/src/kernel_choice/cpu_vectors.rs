//! lavapipe's vector width: the CPU family's subgroup width, and on CPUs with AVX-512 the
//! choice of 512 bits. Mesa picks 256 bits (8-lane subgroups) unless `LP_NATIVE_VECTOR_WIDTH`
//! says otherwise, and vkdiff leaves it so, as Mesa reads it before vkdiff can know the
//! driver's release: on an AMD EPYC (Zen 4) 512 bits (16 lanes, 128-row tiles) ran the SDXL
//! UNet 1.35× faster on Mesa 22.3 (2026-12-06), and on an Intel Xeon the UNet 4.9× slower
//! (2026-11-26); on Mesa 26.1, once the broadcasts were written as such
//! (`shuffles_loop_over_lanes`) and 16 lanes took the fast-running variants, the UNet ran 1.5×
//! faster, on Mesa 25.0 the products ran slower; and the 16-lane kernels take 2–3×
//! longer to compile, minutes from a cold shader cache (BENCHMARKS.md).

use crate::device::DeviceInfo;

/// Whether lavapipe of this release (major, minor) ran the SDXL UNet faster at 16 lanes than at
/// 8 on the AVX-512 CPU measured: Mesa 22 and 26. Mesa 25.0 ran the products slower there, and
/// 23, 24 and 27 are unmeasured.
pub(crate) fn wider_vectors_ran_faster(mesa: Option<(u32, u32)>) -> bool {
    matches!(mesa, Some((..=22 | 26, _)))
}

/// Whether to point the user at the wider vectors: the CPU has AVX-512 and `settings` say no
/// width is chosen.
pub(crate) fn wider_lavapipe_vectors_available(settings: &crate::Settings) -> bool {
    !settings.lavapipe_width_chosen && avx512()
}

fn avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

// The subgroup-register (CPU) family's width, and the integers its word loads need.
impl DeviceInfo {
    /// The width of the subgroup GEMM/convolution variants this device runs: its native
    /// subgroup width where variants exist for it (4, 8 or 16 lanes) and kernels can be pinned to it.
    pub fn gemm_subgroup_width(&self) -> Option<u32> {
        let native = self.subgroup_size;
        ([4, 8, 16].contains(&native) && self.can_use_subgroup(native)).then_some(native)
    }

    /// Whether the device has the integers the subgroup kernels' words are read as at its width:
    /// 64-bit ones (`shaderInt64`) up to `WIDEST_64_BIT_WORDS` lanes, 32-bit ones past it.
    pub fn can_read_words(&self) -> bool {
        self.gemm_subgroup_width().is_some_and(|lanes| lanes > vkdiff_kernels::WIDEST_64_BIT_WORDS) || self.shader_int64
    }

    /// Whether the driver builds a subgroup shuffle as a loop over the lanes even where the lane
    /// is a constant (lavapipe after Mesa 22 at 16 lanes: at 8 it is one `vpermd`), so that the
    /// kernels' broadcasts, which naga writes as shuffles, are better written as broadcasts.
    pub fn shuffles_loop_over_lanes(&self) -> bool {
        self.lavapipe_mesa.is_some_and(|(major, _)| major > 22) && self.subgroup_size > 8
    }

    /// Whether the subgroup kernels may read their operands through texel views (TB = 1 in
    /// kernels/src/spec.rs): a device that runs them and fetches every texel format they read.
    /// Its buffers are then made for texel views too.
    pub fn reads_texels(&self) -> bool {
        self.gemm_subgroup_width().is_some() && self.texel_fetch.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::wider_vectors_ran_faster;

    #[test]
    fn wider_vectors_are_suggested_on_the_releases_where_they_ran_faster() {
        for release in [(22, 3), (26, 1), (26, 0)] {
            assert!(wider_vectors_ran_faster(Some(release)), "{release:?}");
        }
        for release in [(25, 0), (24, 2), (23, 3), (27, 0)] {
            assert!(!wider_vectors_ran_faster(Some(release)), "{release:?}: slower or unmeasured at 16 lanes");
        }
        assert!(!wider_vectors_ran_faster(None), "other CPU drivers");
    }
}
