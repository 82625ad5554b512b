//! Every `VKDIFF_*` variable the runtime takes, parsed in this one place from the environment the
//! edge read ([`Environment`]: the command line, the benchmarks, the tests), into one value
//! handed to [`crate::Context::new`]. The runtime itself reads no environment.

use crate::error::{Error, Result};
use crate::kernel_choice::matrix_tile::MatrixTile;
use crate::kernel_choice::matrix_units::parse_fragment;
use crate::kernel_choice::probe::ProbeChoice;
use vkdiff_setting::{BadVariable, Environment};

/// GFLOP per submission: about 40 ms on a mid-range GPU (an RTX 3060 at the 2.5 TFLOP/s vkdiff's
/// tiled f32 kernels reach on a 13 TFLOP/s card, estimated from the H200's 20 % of fp32 peak),
/// 0.2 s on an entry card at 0.6 TFLOP/s; attention, at about 40 % of the GEMM rate, 2.5× that.
pub const DEFAULT_SUBMIT_GFLOP: f64 = 100.0;

/// The default [`crate::SubmitBudget::merge`]: a twentieth of Windows' TDR, so a device twice as
/// slow as when it was timed stays far from it, yet few enough submissions that their cost
/// vanishes.
pub const DEFAULT_MERGE_SECONDS: f64 = 0.1;

/// What `VKDIFF_COOPERATIVE` asks for ([`crate::Settings::cooperative`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CooperativeSetting {
    /// Unset or `auto`: the matrix units where a variant fits and the trial keeps them.
    Trial,
    /// `1`: the matrix units wherever a variant fits, untried.
    Always,
    /// `0`: never (the tiled kernels).
    Never,
}

/// A size as `VKDIFF_MEMORY_BUDGET` takes it: bytes, or a number with K, M, G or T (powers of
/// 1024; `GiB`, `GB` read the same); None for anything else, or for nothing.
pub(crate) fn parse_size(text: &str) -> Option<u64> {
    let t = text.trim().trim_end_matches(['B', 'b']).trim_end_matches(['i', 'I']);
    let (number, scale) = match t.chars().last().map(|c| c.to_ascii_uppercase()) {
        Some('K') => (&t[..t.len() - 1], 1u64 << 10),
        Some('M') => (&t[..t.len() - 1], 1 << 20),
        Some('G') => (&t[..t.len() - 1], 1 << 30),
        Some('T') => (&t[..t.len() - 1], 1 << 40),
        _ => (t, 1),
    };
    let value: f64 = number.trim().parse().ok()?;
    (value.is_finite() && value > 0.0).then_some((value * scale as f64) as u64)
}

/// How a process runs its device: each field is a variable's typed value, or its default.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// `VKDIFF_VULKAN_API`: the newest Vulkan version asked for, 1.3, or 1.2 to run the 1.2
    /// paths (extensions where 1.3 has core features) on a 1.3 driver.
    pub vulkan_api: (u32, u32),
    /// `VKDIFF_VALIDATE`: every instance runs the Khronos validation layer.
    pub validate: bool,
    /// `VKDIFF_GPU_PATHS`: run as a discrete GPU would (see [`crate::Context::gpu_paths`]).
    pub gpu_paths: bool,
    /// `VKDIFF_QUICK_COMPILE`: small products on the quickly compiled kernels; None leaves it to
    /// the device's plan ([`crate::KernelPlan`]).
    pub quick_compile: Option<bool>,
    /// `VKDIFF_PIPELINE_STATS`: print each kernel's driver statistics as it is compiled.
    pub pipeline_stats: bool,
    /// `VKDIFF_COOPERATIVE`: the matrix units tried (auto), always, or never.
    pub cooperative: CooperativeSetting,
    /// `VKDIFF_FRAGMENT=MxNxK`: the matrix units' fragment shape asked for instead of the best.
    pub fragment: Option<(u32, u32, u32)>,
    /// `VKDIFF_MATRIX_TILE`: the matrix-unit GEMM and convolution's workgroup tile.
    pub matrix_tile: MatrixTile,
    /// `VKDIFF_ATTENTION`, `VKDIFF_LINEAR`, `VKDIFF_CONV`: VK_NV_cooperative_matrix2's probes.
    pub attention: ProbeChoice,
    pub linear: ProbeChoice,
    pub conv: ProbeChoice,
    /// `VKDIFF_TUNE`: time each shape's kernels and take the fastest.
    pub tune: bool,
    /// `VKDIFF_SUBMIT_GFLOP`: matrix work per submission, in GFLOP.
    pub submit_gflop: f64,
    /// `VKDIFF_SUBMIT_TIMEOUT`: seconds a submission may run; None for the device's default.
    pub submit_timeout: Option<f64>,
    /// `VKDIFF_SUBMIT_MERGE`: seconds of chunks one submission may join (0: none).
    pub submit_merge: f64,
    /// `VKDIFF_MEMORY_BUDGET`: the most device memory live tensors may hold, in bytes.
    pub memory_budget: Option<u64>,
    /// `VKDIFF_BUFFER_CACHE`: keep freed device buffers for reuse.
    pub buffer_cache: bool,
    /// `VKDIFF_WINOGRAD`: 3×3 convolutions of stride 1 on the CPU family as Winograd's
    /// F(2×2, 3×3); 0 runs them as direct products.
    pub winograd: bool,
    /// Whether `LP_NATIVE_VECTOR_WIDTH` chooses lavapipe's vector width (Mesa reads it itself).
    pub lavapipe_width_chosen: bool,
}

impl Default for Settings {
    fn default() -> Settings {
        Settings {
            vulkan_api: (1, 3),
            validate: false,
            gpu_paths: false,
            quick_compile: None,
            pipeline_stats: false,
            cooperative: CooperativeSetting::Trial,
            fragment: None,
            matrix_tile: MatrixTile::Auto,
            attention: ProbeChoice::Auto,
            linear: ProbeChoice::Auto,
            conv: ProbeChoice::Auto,
            tune: false,
            submit_gflop: DEFAULT_SUBMIT_GFLOP,
            submit_timeout: None,
            submit_merge: DEFAULT_MERGE_SECONDS,
            memory_budget: None,
            buffer_cache: true,
            winograd: true,
            lavapipe_width_chosen: false,
        }
    }
}

/// A probe setting's values.
const PROBE_VALUES: &str = "cm2 (VK_NV_cooperative_matrix2's kernel where the device runs it) or auto";

impl Settings {
    /// The settings `env` gives; a value a variable does not take is an error naming it and what
    /// it takes.
    pub fn from_environment(env: &Environment) -> Result<Settings> {
        Settings::read(env).map_err(Error::BadVariable)
    }

    fn read(env: &Environment) -> std::result::Result<Settings, BadVariable> {
        let d = Settings::default();
        let switch = |name: &str, default: bool| env.switch(name).map(|v| v.unwrap_or(default));
        let probe = |name: &str| env.parse(name, PROBE_VALUES, ProbeChoice::parse).map(|v| v.unwrap_or_default());
        let seconds = |name: &str, zero: bool| {
            let expected = if zero { "zero or a positive number of seconds" } else { "a positive number of seconds" };
            env.parse(name, expected, |v| {
                v.parse::<f64>().ok().filter(|s| s.is_finite() && (*s > 0.0 || zero && *s == 0.0))
            })
        };
        Ok(Settings {
            vulkan_api: env
                .parse("VKDIFF_VULKAN_API", "1.2 or 1.3", |v| match v {
                    "1.3" => Some((1, 3)),
                    "1.2" => Some((1, 2)),
                    _ => None,
                })?
                .unwrap_or(d.vulkan_api),
            validate: switch("VKDIFF_VALIDATE", false)?,
            gpu_paths: switch("VKDIFF_GPU_PATHS", false)?,
            quick_compile: env.switch("VKDIFF_QUICK_COMPILE")?,
            pipeline_stats: switch("VKDIFF_PIPELINE_STATS", false)?,
            cooperative: match env.switch("VKDIFF_COOPERATIVE")? {
                None => CooperativeSetting::Trial,
                Some(true) => CooperativeSetting::Always,
                Some(false) => CooperativeSetting::Never,
            },
            fragment: env.parse(
                "VKDIFF_FRAGMENT",
                &crate::kernel_choice::matrix_units::fragment_values(),
                parse_fragment,
            )?,
            matrix_tile: env
                .parse("VKDIFF_MATRIX_TILE", MatrixTile::VALUES, MatrixTile::parse)?
                .unwrap_or(d.matrix_tile),
            attention: probe("VKDIFF_ATTENTION")?,
            linear: probe("VKDIFF_LINEAR")?,
            conv: probe("VKDIFF_CONV")?,
            tune: switch("VKDIFF_TUNE", false)?,
            submit_gflop: env
                .parse("VKDIFF_SUBMIT_GFLOP", "a positive number of GFLOP", |v| {
                    v.parse::<f64>().ok().filter(|g| g.is_finite() && *g > 0.0)
                })?
                .unwrap_or(d.submit_gflop),
            submit_timeout: seconds("VKDIFF_SUBMIT_TIMEOUT", false)?,
            submit_merge: seconds("VKDIFF_SUBMIT_MERGE", true)?.unwrap_or(d.submit_merge),
            memory_budget: env.parse("VKDIFF_MEMORY_BUDGET", "bytes, or a size such as 8G or 512M", parse_size)?,
            buffer_cache: switch("VKDIFF_BUFFER_CACHE", true)?,
            winograd: switch("VKDIFF_WINOGRAD", true)?,
            lavapipe_width_chosen: env.get("LP_NATIVE_VECTOR_WIDTH").is_some(),
        })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The settings of the process the unit tests run in (the CI's passes set them), read at
    /// this test edge as the command line reads them at its own.
    pub(crate) fn process_settings() -> Settings {
        Settings::from_environment(&Environment::of_process()).expect("the VKDIFF_* settings")
    }

    fn read(pairs: &[(&str, &str)]) -> Result<Settings> {
        Settings::from_environment(&Environment::from_pairs(pairs.iter().copied()))
    }

    #[test]
    fn reads_sizes_with_units() {
        assert_eq!(parse_size("8G"), Some(8 << 30));
        assert_eq!(parse_size("8GiB"), Some(8 << 30));
        assert_eq!(parse_size("512M"), Some(512 << 20));
        assert_eq!(parse_size("1.5g"), Some(3 << 29));
        assert_eq!(parse_size("4096"), Some(4096));
        for bad in ["", "lots", "-1G", "0", "G"] {
            assert_eq!(parse_size(bad), None, "{bad}");
        }
    }

    #[test]
    fn an_empty_environment_gives_the_defaults() {
        assert_eq!(read(&[]).unwrap(), Settings::default());
    }

    #[test]
    fn every_variable_reaches_its_field() {
        let s = read(&[
            ("VKDIFF_VULKAN_API", "1.2"),
            ("VKDIFF_VALIDATE", "yes"),
            ("VKDIFF_GPU_PATHS", "true"),
            ("VKDIFF_QUICK_COMPILE", "off"),
            ("VKDIFF_PIPELINE_STATS", "1"),
            ("VKDIFF_COOPERATIVE", "0"),
            ("VKDIFF_FRAGMENT", "8x16x16"),
            ("VKDIFF_MATRIX_TILE", "128x64"),
            ("VKDIFF_ATTENTION", "cm2"),
            ("VKDIFF_LINEAR", "CM2"),
            ("VKDIFF_CONV", "auto"),
            ("VKDIFF_TUNE", "on"),
            ("VKDIFF_SUBMIT_GFLOP", "25"),
            ("VKDIFF_SUBMIT_TIMEOUT", "5"),
            ("VKDIFF_SUBMIT_MERGE", "0"),
            ("VKDIFF_MEMORY_BUDGET", "8G"),
            ("VKDIFF_BUFFER_CACHE", "no"),
            ("VKDIFF_WINOGRAD", "0"),
            ("LP_NATIVE_VECTOR_WIDTH", "512"),
        ])
        .unwrap();
        let expected = Settings {
            vulkan_api: (1, 2),
            validate: true,
            gpu_paths: true,
            quick_compile: Some(false),
            pipeline_stats: true,
            cooperative: CooperativeSetting::Never,
            fragment: Some((8, 16, 16)),
            matrix_tile: MatrixTile::EightTall,
            attention: ProbeChoice::Matrix2,
            linear: ProbeChoice::Matrix2,
            conv: ProbeChoice::Auto,
            tune: true,
            submit_gflop: 25.0,
            submit_timeout: Some(5.0),
            submit_merge: 0.0,
            memory_budget: Some(8 << 30),
            buffer_cache: false,
            winograd: false,
            lavapipe_width_chosen: true,
        };
        assert_eq!(s, expected);
    }

    #[test]
    fn a_bad_value_names_its_variable_and_what_it_takes() {
        for (name, value, takes) in [
            ("VKDIFF_GPU_PATHS", "sometimes", "1 or 0"),
            ("VKDIFF_QUICK_COMPILE", "fast", "1 or 0"),
            ("VKDIFF_COOPERATIVE", "2", "1 or 0"),
            ("VKDIFF_VULKAN_API", "1.1", "1.2 or 1.3"),
            ("VKDIFF_FRAGMENT", "16x16", "8×16×16"),
            ("VKDIFF_MATRIX_TILE", "128", "128x64"),
            ("VKDIFF_ATTENTION", "flash", "cm2"),
            ("VKDIFF_SUBMIT_GFLOP", "0", "positive number of GFLOP"),
            ("VKDIFF_SUBMIT_TIMEOUT", "-1", "positive number of seconds"),
            ("VKDIFF_SUBMIT_MERGE", "x", "zero or a positive"),
            ("VKDIFF_MEMORY_BUDGET", "lots", "size such as 8G"),
            ("VKDIFF_BUFFER_CACHE", "maybe", "1 or 0"),
        ] {
            let err = read(&[(name, value)]).unwrap_err().to_string();
            assert!(err.starts_with(&format!("{name}={value}: expected ")) && err.contains(takes), "{err}");
        }
    }
}
