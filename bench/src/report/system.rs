//! The machine a report was made on, named as a reader needs to trust a row and compare it:
//! device, vendor, driver, Vulkan, the kernels chosen, the CPU and OS, vkdiff's build, the
//! command line and the date.

use crate::peaks;
use serde::{Deserialize, Serialize};
use vkdiff_runtime::{Context, DeviceKind, Dtype, Environment};

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct System {
    pub device: String,
    /// `GPU (discrete)`, `CPU`, …
    pub kind: String,
    pub vendor: String,
    /// The driver's name and version as it reports them.
    pub driver: String,
    pub vulkan: String,
    /// The products' kernels in f16 and f32 (`matrix units 16×16×16`, `tiled`, …).
    pub kernels_f16: String,
    pub kernels_f32: String,
    pub subgroup_size: u32,
    pub cpu: String,
    pub os: String,
    /// vkdiff's version and commit.
    pub vkdiff: String,
    pub command: String,
    /// UTC, ISO 8601.
    pub date: String,
}

impl System {
    /// `ctx`'s device, and the command as run under `env`.
    pub fn of(ctx: &Context, env: &Environment) -> System {
        let info = ctx.info();
        let (major, minor, patch) = info.api_version;
        System {
            device: info.name.clone(),
            kind: info.kind.label().into(),
            vendor: vendor_name(info.vendor_id, info.kind),
            driver: info.driver.clone(),
            vulkan: format!("{major}.{minor}.{patch}"),
            kernels_f16: peaks::family_label(ctx, Dtype::F16),
            kernels_f32: peaks::family_label(ctx, Dtype::F32),
            subgroup_size: info.subgroup_size,
            cpu: cpu_name(),
            os: os_name(),
            vkdiff: vkdiff_setting::version().into(),
            // As a user types it, whatever path ran the binary; the environment variables that
            // change the kernels in front.
            command: command_line(env),
            date: utc_now(),
        }
    }

    /// The column a report takes in a comparison: device, driver and build.
    pub fn column(&self) -> String {
        format!("{} · {} · {}", self.device, self.driver, self.vkdiff)
    }
}

fn vendor_name(id: u32, kind: DeviceKind) -> String {
    match id {
        0x10de => "NVIDIA".into(),
        0x1002 => "AMD".into(),
        0x8086 => "Intel".into(),
        0x13b5 => "Arm".into(),
        0x5143 => "Qualcomm".into(),
        0x106b => "Apple".into(),
        0x10005 if kind == DeviceKind::Cpu => "Mesa (lavapipe)".into(),
        _ => format!("0x{id:04x}"),
    }
}

/// The CPU's model name and logical core count, from /proc/cpuinfo on Linux.
fn cpu_name() -> String {
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let model = std::fs::read_to_string("/proc/cpuinfo").ok().and_then(|text| {
        text.lines()
            .find(|l| l.starts_with("model name"))
            .and_then(|l| l.split(':').nth(1))
            .map(|m| m.trim().to_string())
    });
    format!("{}, {cores} threads", model.unwrap_or_else(|| std::env::consts::ARCH.into()))
}

/// The distribution's name and the kernel's release on Linux; the OS family elsewhere.
fn os_name() -> String {
    let pretty = std::fs::read_to_string("/etc/os-release").ok().and_then(|text| {
        text.lines().find_map(|l| l.strip_prefix("PRETTY_NAME=").map(|v| v.trim_matches('"').to_string()))
    });
    let kernel = std::fs::read_to_string("/proc/sys/kernel/osrelease").ok().map(|k| k.trim().to_string());
    match (pretty, kernel) {
        (Some(p), Some(k)) => format!("{p}, Linux {k}"),
        (Some(p), None) => p,
        _ => std::env::consts::OS.into(),
    }
}

fn utc_now() -> String {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    utc(secs)
}

/// Seconds since 1970 as `YYYY-MM-DDTHH:MM:SSZ` (the proleptic Gregorian calendar).
fn utc(secs: u64) -> String {
    let (days, rest) = ((secs / 86_400) as i64, secs % 86_400);
    // Howard Hinnant's days-to-civil algorithm, eras of 400 years from 0000-03-01.
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z", rest / 3600, rest % 3600 / 60, rest % 60)
}

/// This run's command as a user types it: `vkdiff` and its arguments, after the `VKDIFF_*`
/// variables that choose kernels (a report made under them is made again only with them).
fn command_line(env: &Environment) -> String {
    let chosen = ["VKDIFF_COOPERATIVE", "VKDIFF_MATRIX_TILE", "VKDIFF_FRAGMENT", "VKDIFF_GPU_PATHS"];
    let vars = chosen.iter().filter_map(|k| env.raw(k).map(|v| format!("{k}={v} ")));
    let args = std::env::args().skip(1);
    vars.collect::<String>() + &std::iter::once("vkdiff".to_string()).chain(args).collect::<Vec<_>>().join(" ")
}

#[cfg(test)]
mod tests {
    #[test]
    fn dates_are_utc_iso_8601() {
        assert_eq!(super::utc(0), "1970-01-01T00:00:00Z");
        // As `date -u -d @SECONDS` reads them: 2000 is a leap year (its 29 February).
        assert_eq!(super::utc(951_782_399), "2000-02-28T23:59:59Z");
        assert_eq!(super::utc(951_868_799), "2000-02-29T23:59:59Z");
        assert_eq!(super::utc(951_868_800), "2000-03-01T00:00:00Z");
        assert_eq!(super::utc(1_795_898_096), "2026-11-28T20:34:56Z");
    }
}
