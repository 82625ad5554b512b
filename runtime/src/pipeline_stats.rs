//! The statistics a driver reports for a compiled kernel through
//! `VK_KHR_pipeline_executable_properties` (NVIDIA: registers per thread, the figure that decides
//! how many workgroups share a compute unit; RADV and NVK: registers, spills, instruction counts;
//! lavapipe offers none). `VKDIFF_PIPELINE_STATS=1` prints one line on stderr per kernel variant
//! as it is compiled, a tuning aid that changes nothing else; `vkdiff devices --compile` reads
//! them for every variant (`crate::kernel_choice::census`). Values are printed as the driver reports them:
//! NVIDIA's 580 driver sets bit 36 in "Local Memory Size" (2^36 plus the bytes a lane spills).

use ash::vk;
use std::ffi::CStr;
use vkdiff_kernels::Variant;

/// One executable's statistics, as (name, value) in the driver's order.
pub type Statistics = Vec<(String, StatisticValue)>;

/// A statistic's value in the format the driver gave it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StatisticValue {
    Bool(bool),
    Int(i64),
    Uint(u64),
    Float(f64),
    /// A format newer than these.
    Unknown,
}

impl std::fmt::Display for StatisticValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StatisticValue::Bool(b) => write!(f, "{b}"),
            StatisticValue::Int(i) => write!(f, "{i}"),
            StatisticValue::Uint(u) => write!(f, "{u}"),
            StatisticValue::Float(x) => write!(f, "{x:.3}"),
            StatisticValue::Unknown => f.write_str("?"),
        }
    }
}

/// The statistics of each executable of `pipeline` (created with `CAPTURE_STATISTICS`); a failed
/// query is the error's text.
pub(crate) fn query(
    loader: &ash::khr::pipeline_executable_properties::Device,
    pipeline: vk::Pipeline,
) -> Result<Vec<Statistics>, String> {
    let info = vk::PipelineInfoKHR::default().pipeline(pipeline);
    // SAFETY: the pipeline was created on the loader's device with statistics captured.
    let executables = unsafe { loader.get_pipeline_executable_properties(&info) }
        .map_err(|e| format!("no executables reported ({e})"))?;
    (0..executables.len() as u32)
        .map(|index| {
            let exe = vk::PipelineExecutableInfoKHR::default().pipeline(pipeline).executable_index(index);
            // SAFETY: as above; the index is below the count the driver gave.
            let stats = unsafe { loader.get_pipeline_executable_statistics(&exe) }
                .map_err(|e| format!("no statistics reported ({e})"))?;
            Ok(stats.iter().map(statistic).collect())
        })
        .collect()
}

/// "gemm_coop F16 FM=16 FN=16 FK=16 SG=32 GN=2 WM=4 WN=4 …", how these lines and `vkdiff devices --compile` name a variant.
pub fn variant_label(variant: &Variant) -> String {
    let params: Vec<String> = variant.params.iter().map(|(k, v)| format!(" {k}={v}")).collect();
    format!("{} {:?}{}", variant.kernel, variant.dtype, params.concat())
}

/// "Register Count 168, …": one executable's statistics on a line.
pub fn describe(stats: &Statistics) -> String {
    stats.iter().map(|(name, value)| format!("{name} {value}")).collect::<Vec<_>>().join(", ")
}

/// The bytes of scratch (per-lane memory, where spilled registers go) that `stats` say the
/// kernel uses, where the driver reports it under a name known here: RADV's "Scratch size",
/// NVK's "SLM size", Intel's "Scratch Memory Size", NVIDIA's "Local Memory Size" (its 580
/// driver sets bit 36 beside the bytes). None where it reports none of them.
pub fn memory_spills(stats: &Statistics) -> Option<u64> {
    let bytes = |v: &StatisticValue| match *v {
        StatisticValue::Uint(u) => Some(u),
        StatisticValue::Int(i) => Some(i.max(0) as u64),
        _ => None,
    };
    let each = stats.iter().filter_map(|(name, value)| match name.as_str() {
        "Scratch size" | "SLM size" | "Scratch Memory Size" => bytes(value),
        "Local Memory Size" => bytes(value).map(|b| b & !(1 << 36)),
        _ => None,
    });
    each.reduce(|a, b| a + b)
}

fn statistic(s: &vk::PipelineExecutableStatisticKHR) -> (String, StatisticValue) {
    let name = s.name_as_c_str().ok().and_then(|n: &CStr| n.to_str().ok()).unwrap_or("?");
    // SAFETY: the union member read is the one `format` names.
    let value = unsafe {
        match s.format {
            vk::PipelineExecutableStatisticFormatKHR::BOOL32 => StatisticValue::Bool(s.value.b32 == vk::TRUE),
            vk::PipelineExecutableStatisticFormatKHR::INT64 => StatisticValue::Int(s.value.i64),
            vk::PipelineExecutableStatisticFormatKHR::UINT64 => StatisticValue::Uint(s.value.u64),
            vk::PipelineExecutableStatisticFormatKHR::FLOAT64 => StatisticValue::Float(s.value.f64),
            _ => StatisticValue::Unknown,
        }
    };
    (name.to_string(), value)
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
        describe(&vec![statistic(&s)])
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

    #[test]
    fn memory_spills_read_each_driver_s_name() {
        let named =
            |name: &str, value| vec![(name.to_string(), value), ("VGPRs".to_string(), StatisticValue::Uint(96))];
        assert_eq!(memory_spills(&named("Scratch size", StatisticValue::Uint(0))), Some(0));
        assert_eq!(memory_spills(&named("Scratch size", StatisticValue::Uint(256))), Some(256));
        assert_eq!(memory_spills(&named("SLM size", StatisticValue::Uint(88))), Some(88));
        assert_eq!(memory_spills(&named("Local Memory Size", StatisticValue::Uint(1 << 36))), Some(0));
        assert_eq!(memory_spills(&named("Local Memory Size", StatisticValue::Uint((1 << 36) + 64))), Some(64));
        assert_eq!(memory_spills(&named("Register Count", StatisticValue::Uint(255))), None, "no spill figure");
    }
}
