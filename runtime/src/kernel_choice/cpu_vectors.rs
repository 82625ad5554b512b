//! lavapipe's vector width on CPUs with AVX-512. Mesa picks 256 bits (8-lane subgroups) unless
//! `LP_NATIVE_VECTOR_WIDTH` says otherwise, and vkdiff leaves it so: 512 bits (16 lanes) ran the
//! SDXL UNet 4.9× slower on an Intel Xeon and 1.04× faster on an AMD EPYC (1.14× since the CPU
//! kernels read 64-bit words, 2026-12-05), and made the README's demo 1.4× (Mesa 22.3) to 3×
//! (Mesa 25) slower from a cold shader cache on that EPYC, as the 16-lane kernels take 2–3×
//! longer to compile (BENCHMARKS.md).

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
