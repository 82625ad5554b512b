//! Which device a process uses: one it names (index, UUID or PCI address), the one its
//! scheduler gave it (`CUDA_VISIBLE_DEVICES`, `ROCR_VISIBLE_DEVICES`, `SLURM_LOCALID`), else the
//! best one; and, with `require_gpu`, never the CPU.

use crate::device::{DeviceInfo, DeviceKind};
use crate::error::{Error, Result};
use crate::pci::PciAddress;
use std::fmt;
use std::str::FromStr;
use vkdiff_setting::{Environment, Message};

const NVIDIA: u32 = 0x10de;
const AMD: u32 = 0x1002;

/// How a user names a device: its index in `vkdiff devices`, its UUID (as `vkdiff devices` and
/// `nvidia-smi -L` print it, with or without `GPU-`, or a unique prefix of 8 or more digits), or
/// its PCI address (`0000:65:00.0`, or `65:00.0` in domain 0).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DeviceSpec {
    Index(usize),
    /// Lowercase hex digits, without dashes.
    Uuid(String),
    Pci(PciAddress),
}

impl FromStr for DeviceSpec {
    type Err = String;

    fn from_str(text: &str) -> std::result::Result<DeviceSpec, String> {
        let s = text.trim();
        let bad = || {
            format!("`{text}` names no device: give an index, a UUID or a PCI address as `vkdiff devices` prints them")
        };
        if !s.is_empty() && s.len() <= 4 && s.bytes().all(|b| b.is_ascii_digit()) {
            return s.parse().map(DeviceSpec::Index).map_err(|_| bad());
        }
        if s.contains(':') {
            return PciAddress::parse(s).map(DeviceSpec::Pci).ok_or_else(bad);
        }
        let hex: String = s.strip_prefix("GPU-").unwrap_or(s).chars().filter(|&c| c != '-').collect();
        if (8..=32).contains(&hex.len()) && hex.chars().all(|c| c.is_ascii_hexdigit()) {
            return Ok(DeviceSpec::Uuid(hex.to_ascii_lowercase()));
        }
        Err(bad())
    }
}

impl fmt::Display for DeviceSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DeviceSpec::Index(i) => write!(f, "{i}"),
            DeviceSpec::Uuid(hex) => write!(f, "UUID {hex}"),
            DeviceSpec::Pci(address) => write!(f, "PCI {address}"),
        }
    }
}

/// What the user asked for: a device (`--device`, else `VKDIFF_DEVICE`, else the scheduler's
/// variables, else the best device), and whether a CPU device is refused (`--require-gpu`, or
/// `VKDIFF_REQUIRE_GPU=1`).
#[derive(Clone, Debug, Default)]
pub struct DeviceChoice {
    pub device: Option<DeviceSpec>,
    /// Whether `VKDIFF_DEVICE` named [`DeviceChoice::device`] (else the flag did).
    pub named_by_variable: bool,
    pub require_gpu: bool,
    /// The environment the edge read: the scheduler's variables (`CUDA_VISIBLE_DEVICES`,
    /// `SLURM_LOCALID`, …) and the Vulkan loader's (`VK_DRIVER_FILES`, the XDG folders).
    pub environment: Environment,
}

impl DeviceChoice {
    /// The device `index` (tests and benchmarks that name one).
    pub fn index(index: usize) -> DeviceChoice {
        DeviceChoice { device: Some(DeviceSpec::Index(index)), ..DeviceChoice::default() }
    }

    /// `device` and `require_gpu` as the flags give them, else as `VKDIFF_DEVICE` and
    /// `VKDIFF_REQUIRE_GPU` in `env` do, with `env` for the scheduler and the loader.
    pub fn from_environment(device: Option<DeviceSpec>, require_gpu: bool, env: &Environment) -> Result<DeviceChoice> {
        let named = "an index, a UUID or a PCI address as `vkdiff devices` prints them";
        let variable = match device {
            Some(_) => None,
            None => env.parse("VKDIFF_DEVICE", named, |v| v.parse::<DeviceSpec>().ok()).map_err(Error::BadVariable)?,
        };
        let required = env.switch("VKDIFF_REQUIRE_GPU").map_err(Error::BadVariable)?;
        Ok(DeviceChoice {
            named_by_variable: variable.is_some(),
            device: device.or(variable),
            require_gpu: require_gpu || required.unwrap_or(false),
            environment: env.clone(),
        })
    }
}

/// Which device of `devices` to use for `choice`.
pub fn choose(devices: &[DeviceInfo], choice: &DeviceChoice) -> Result<usize> {
    if devices.is_empty() {
        return Err(Error::NoDevice);
    }
    let env = &choice.environment;
    let index = match &choice.device {
        Some(spec) if choice.named_by_variable => Some(find(devices, spec, Message::text("VKDIFF_DEVICE"))?),
        Some(spec) => Some(find(devices, spec, Message::setting("device"))?),
        None => scheduled(devices, env)?,
    };
    let index = match index {
        Some(index) => {
            let d = &devices[index];
            if let Some(reason) = d.unsupported_reason() {
                return Err(Error::Unsupported { device: d.name.clone(), reason });
            }
            index
        }
        None => best(devices)?,
    };
    if choice.require_gpu && devices[index].kind == DeviceKind::Cpu {
        return Err(Error::NoGpu(format!(
            "the device chosen, `{}`, is a CPU (Vulkan driver manifests found: {}); install the GPU's Vulkan \
            driver, or in a container expose it (NVIDIA: NVIDIA_DRIVER_CAPABILITIES must include graphics)",
            devices[index].name,
            loader_icds(env).join(", ")
        )));
    }
    Ok(index)
}

/// The usable device of the preferred kind (discrete, integrated, virtual, CPU), first by index.
fn best(devices: &[DeviceInfo]) -> Result<usize> {
    devices
        .iter()
        .filter(|d| d.unsupported_reason().is_none())
        .min_by_key(|d| (d.kind, d.index))
        .map(|d| d.index)
        .ok_or_else(|| Error::Unsupported {
            device: devices[0].name.clone(),
            reason: devices[0].unsupported_reason().unwrap_or_default(),
        })
}

/// The device `spec` names.
fn find(devices: &[DeviceInfo], spec: &DeviceSpec, requested_by: Message) -> Result<usize> {
    let matches: Vec<usize> = match spec {
        DeviceSpec::Index(index) => {
            return (*index < devices.len()).then_some(*index).ok_or(Error::BadDeviceIndex {
                index: *index,
                count: devices.len(),
                requested_by,
            })
        }
        DeviceSpec::Uuid(hex) => {
            devices.iter().filter(|d| d.uuid_hex().starts_with(hex.as_str())).map(|d| d.index).collect()
        }
        DeviceSpec::Pci(address) => devices.iter().filter(|d| d.pci == Some(*address)).map(|d| d.index).collect(),
    };
    match matches[..] {
        [index] => Ok(index),
        [] => Err(Error::NoSuchDevice { spec: spec.to_string(), why: "no Vulkan device has it", requested_by }),
        _ => Err(Error::NoSuchDevice { spec: spec.to_string(), why: "several devices match it", requested_by }),
    }
}

/// The device the process's scheduler gave it, if it says: `CUDA_VISIBLE_DEVICES` (NVIDIA),
/// `ROCR_VISIBLE_DEVICES` or `HIP_VISIBLE_DEVICES` (AMD) list the GPUs this process owns, by
/// index among that vendor's GPUs in PCI order (CUDA's `PCI_BUS_ID` order, which Slurm and
/// Kubernetes' device plugins assume) or, for NVIDIA, by UUID; a Slurm task with several takes
/// the one at `SLURM_LOCALID`. An empty list (or "-1") gives it none of that vendor's GPUs.
/// Without a list, `SLURM_LOCALID` picks among the usable devices of the preferred kind, so a
/// node's tasks spread over its GPUs. Vulkan drivers read none of these variables.
fn scheduled(devices: &[DeviceInfo], env: &Environment) -> Result<Option<usize>> {
    let listed = [("CUDA_VISIBLE_DEVICES", NVIDIA), ("ROCR_VISIBLE_DEVICES", AMD), ("HIP_VISIBLE_DEVICES", AMD)]
        .into_iter()
        .find_map(|(name, vendor)| env.raw(name).map(|value| (name, vendor, value)));
    let local = env.get("SLURM_LOCALID").and_then(|v| v.parse::<usize>().ok()).unwrap_or(0);
    let mut hidden_vendor = None;
    if let Some((name, vendor, value)) = listed {
        let owned = visible(devices, (name, vendor, value), env)?;
        if !owned.is_empty() {
            return Ok(Some(owned[local % owned.len()]));
        }
        hidden_vendor = Some(vendor);
    }
    let usable = devices.iter().filter(|d| d.unsupported_reason().is_none() && Some(d.vendor_id) != hidden_vendor);
    let Some(kind) = usable.clone().map(|d| d.kind).min() else { return Ok(None) };
    let candidates = by_pci(usable.filter(|d| d.kind == kind));
    Ok(Some(candidates[local % candidates.len()]))
}

/// The devices a `*_VISIBLE_DEVICES` list names, in its order.
fn visible(devices: &[DeviceInfo], (name, vendor, value): (&str, u32, &str), env: &Environment) -> Result<Vec<usize>> {
    let ours = by_pci(devices.iter().filter(|d| d.vendor_id == vendor));
    let brand = if vendor == NVIDIA { "NVIDIA" } else { "AMD" };
    let unmatched = |entry: &str| {
        Error::NotVisible(format!(
            "{name}={value} gives this process {brand} GPU {entry}, but the Vulkan loader lists {} {brand} \
            device(s) (driver manifests found: {}); in a container, NVIDIA_DRIVER_CAPABILITIES must include \
            graphics for NVIDIA's Vulkan driver; or choose with --device",
            ours.len(),
            loader_icds(env).join(", ")
        ))
    };
    let mut picked = Vec::new();
    for entry in value.split(',').map(str::trim) {
        // A list ends at its first invalid entry, as CUDA reads it ("-1" hides every GPU).
        let spec = match entry.parse::<DeviceSpec>() {
            Ok(DeviceSpec::Pci(_)) | Err(_) => break,
            Ok(spec) => spec,
        };
        let index = match &spec {
            DeviceSpec::Index(i) => ours.get(*i).copied(),
            DeviceSpec::Uuid(hex) if vendor == NVIDIA => {
                ours.iter().copied().find(|&i| devices[i].uuid_hex().starts_with(hex.as_str()))
            }
            // ROCm's UUIDs come from the board's serial, not Vulkan's deviceUUID.
            _ => return Err(Error::BadDeviceSpec(format!("{name}={value}: name AMD GPUs by index for vkdiff"))),
        };
        picked.push(index.ok_or_else(|| unmatched(entry))?);
    }
    Ok(picked)
}

/// Indices of `devices` in PCI order (devices without a PCI address last, by index).
fn by_pci<'a>(devices: impl Iterator<Item = &'a DeviceInfo>) -> Vec<usize> {
    let mut list: Vec<&DeviceInfo> = devices.collect();
    list.sort_by_key(|d| (d.pci.is_none(), d.pci, d.index));
    list.iter().map(|d| d.index).collect()
}

/// The driver manifests (ICDs) the Vulkan loader would read: `VK_DRIVER_FILES` or
/// `VK_ICD_FILENAMES` where set, else the `vulkan/icd.d` folders of the XDG search paths.
pub fn loader_icds(env: &Environment) -> Vec<String> {
    let named = env.get("VK_DRIVER_FILES").or_else(|| env.get("VK_ICD_FILENAMES"));
    let folders: Vec<std::path::PathBuf> = match &named {
        Some(list) => list.split(':').filter(|p| !p.is_empty()).map(Into::into).collect(),
        None => {
            let home = env.get("HOME").map(|h| format!("{h}/.local/share")).unwrap_or_default();
            let bases = [
                env.get("XDG_CONFIG_DIRS").unwrap_or("/etc/xdg").to_string(),
                "/etc".into(),
                env.get("XDG_DATA_HOME").map_or(home, str::to_string),
                env.get("XDG_DATA_DIRS").unwrap_or("/usr/local/share:/usr/share").to_string(),
            ];
            bases
                .iter()
                .flat_map(|b| b.split(':'))
                .filter(|b| !b.is_empty())
                .map(|b| format!("{b}/vulkan/icd.d").into())
                .collect()
        }
    };
    let mut icds = Vec::new();
    for path in &folders {
        match std::fs::read_dir(path) {
            Ok(entries) => {
                let mut names: Vec<String> = entries
                    .flatten()
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| n.ends_with(".json"))
                    .collect();
                names.sort();
                icds.extend(names);
            }
            // A file the variable names (a folder that does not exist is skipped).
            Err(_) if named.is_some() => icds.extend(path.file_name().map(|n| n.to_string_lossy().into_owned())),
            Err(_) => {}
        }
    }
    if icds.is_empty() {
        icds.push("none".into());
    }
    icds
}

#[cfg(test)]
mod tests;
