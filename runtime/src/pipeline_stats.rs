//! `VKDIFF_PIPELINE_STATS=1`: one line on stderr per kernel variant the driver compiles, with the
//! statistics it reports through `VK_KHR_pipeline_executable_properties` (NVIDIA: registers per
//! thread, the figure that decides how many workgroups share a compute unit; lavapipe: its
//! LLVM instruction counts). A tuning aid: nothing else changes.

use ash::vk;
use std::ffi::CStr;
use vkdiff_kernels::Variant;

/// Whether the environment asks for the statistics.
pub(crate) fn requested() -> bool {
    std::env::var("VKDIFF_PIPELINE_STATS").is_ok_and(|v| v == "1")
}

/// "gemm_coop f16 CM=16 SG=32 WT=4: Register Count 168, …" for each executable of `pipeline`
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
