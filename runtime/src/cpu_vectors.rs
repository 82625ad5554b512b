//! lavapipe's vector width on CPUs with AVX-512. Mesa picks 256 bits unless
//! `LP_NATIVE_VECTOR_WIDTH` says otherwise. On an AMD EPYC with AVX-512, 512 bits ran the SDXL UNet
//! 1.67× faster end to end (issue 23's report), with the 16-lane kernel variants; on a 16-core
//! Intel Xeon with AVX-512 (FP16, so Sapphire Rapids or later) it ran 4.9× slower (25.9 → 126.6 s
//! per evaluation at 512², BENCHMARKS.md), so only AMD CPUs are widened.

use std::sync::atomic::{AtomicBool, Ordering};

static WIDENED: AtomicBool = AtomicBool::new(false);

/// Sets `LP_NATIVE_VECTOR_WIDTH=512` for this process when the CPU is an AMD one with AVX-512
/// and the user has not chosen a width; returns whether it did. Mesa reads the variable when the driver loads,
/// so this must run before the first Vulkan call.
///
/// # Safety
/// Changes the environment: no other thread may exist yet (call it first thing in `main`).
pub unsafe fn widen_lavapipe_vectors() -> bool {
    if std::env::var_os("LP_NATIVE_VECTOR_WIDTH").is_some() || !amd_with_avx512() {
        return false;
    }
    // SAFETY: the caller guarantees a single-threaded process.
    unsafe { std::env::set_var("LP_NATIVE_VECTOR_WIDTH", "512") };
    WIDENED.store(true, Ordering::SeqCst);
    true
}

/// Whether [`widen_lavapipe_vectors`] set the width in this process.
pub fn lavapipe_vectors_widened() -> bool {
    WIDENED.load(Ordering::SeqCst)
}

fn amd_with_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        // CPUID leaf 0 spells the vendor in EBX, EDX, ECX.
        let id = std::arch::x86_64::__cpuid(0);
        let vendor = [id.ebx, id.edx, id.ecx].map(u32::to_le_bytes).concat();
        vendor == b"AuthenticAMD" && std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
