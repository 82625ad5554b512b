//! `VKDIFF_PIPELINE_STATS=1`: one line on stderr per kernel variant the driver compiles, with the
//! statistics it reports through `VK_KHR_pipeline_executable_properties` (NVIDIA: registers per
//! thread, the figure that decides how many workgroups share a compute unit; lavapipe offers
//! none). A tuning aid: nothing else changes. Values are printed as the driver reports them:
//! NVIDIA's 580 driver sets bit 36 in "Local Memory Size" (2^36 plus the bytes a lane spills).

use ash::vk;
use std::ffi::CStr;
use vkdiff_kernels::Variant;

/// Whether the environment asks for the statistics.
pub(crate) fn requested() -> bool {
    std::env::var("VKDIFF_PIPELINE_STATS").is_ok_and(|v| v == "1")
}

/// "gemm_coop f16 FM=16 FN=16 FK=16 SG=32 WT=4: Register Count 168, …" for each executable of `pipeline`
/// (created with `CAPTURE_STATISTICS`); a failed query is reported on its line, not raised.
pub(crate) fn describe(
    loader: &ash::khr::pipeline_executable_properties::Device,
    pipeline: vk::Pipeline,
    variant: &Variant,
) -> Vec<String> {
    let params: Vec<String> = variant.params.iter().map(|(k, v)| format!(" {k}={v}")).collect();
    let label = format!("{} {:?}{}", variant.kernel, variant.dtype, params.concat());
    let info = vk::PipelineInfoKHR::default().pipeline(pipeline);
    // SAFETY: the pipeline was created on the loader's device with statistics captured.
    let executables = match unsafe { loader.get_pipeline_executable_properties(&info) } {
        Ok(e) => e.len() as u32,
        Err(e) => return vec![format!("{label}: no executables reported ({e})")],
    };
    (0..executables)
        .map(|index| {
            let exe = vk::PipelineExecutableInfoKHR::default().pipeline(pipeline).executable_index(index);
            // SAFETY: as above; the index is below the count the driver gave.
            match unsafe { loader.get_pipeline_executable_statistics(&exe) } {
                Ok(stats) => {
                    let each: Vec<String> = stats.iter().map(statistic).collect();
                    format!("{label}: {}", each.join(", "))
                }
                Err(e) => format!("{label}: no statistics reported ({e})"),
            }
        })
        .collect()
}

fn statistic(s: &vk::PipelineExecutableStatisticKHR) -> String {
    let name = s.name_as_c_str().ok().and_then(|n: &CStr| n.to_str().ok()).unwrap_or("?");
    // SAFETY: the union member read is the one `format` names.
    let value = unsafe {
        match s.format {
            vk::PipelineExecutableStatisticFormatKHR::BOOL32 => (s.value.b32 == vk::TRUE).to_string(),
            vk::PipelineExecutableStatisticFormatKHR::INT64 => s.value.i64.to_string(),
            vk::PipelineExecutableStatisticFormatKHR::UINT64 => s.value.u64.to_string(),
            vk::PipelineExecutableStatisticFormatKHR::FLOAT64 => format!("{:.3}", s.value.f64),
            _ => "?".into(),
        }
    };
    format!("{name} {value}")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stat(
        name: &str,
        format: vk::PipelineExecutableStatisticFormatKHR,
        value: vk::PipelineExecutableStatisticValueKHR,
    ) -> String {
        let mut s = vk::PipelineExecutableStatisticKHR::default();
        for (to, from) in s.name.iter_mut().zip(name.bytes()) {
            *to = from as std::ffi::c_char;
        }
        s.format = format;
        s.value = value;
        statistic(&s)
    }

    #[test]
    fn each_format_reads_its_own_member() {
        use vk::PipelineExecutableStatisticFormatKHR as F;
        use vk::PipelineExecutableStatisticValueKHR as V;
        assert_eq!(stat("Register Count", F::UINT64, V { u64: 255 }), "Register Count 255");
        assert_eq!(stat("Offset", F::INT64, V { i64: -3 }), "Offset -3");
        assert_eq!(stat("Spills", F::BOOL32, V { b32: vk::TRUE }), "Spills true");
        assert_eq!(stat("Occupancy", F::FLOAT64, V { f64: 0.5 }), "Occupancy 0.500");
        assert_eq!(stat("Future", F::from_raw(7), V { u64: 1 }), "Future ?");
    }
}
