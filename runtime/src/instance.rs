//! The process's Vulkan instance: every context and device listing shares it, and it lives until
//! the process ends. With an instance of its own per context, NVIDIA's driver (580.159, on an
//! H200) failed the 31st context opened after the one before had closed: vkCreateInstance found
//! "no Vulkan driver" (the loader unloads the driver with the last instance). One instance per
//! (API version, validation) asked for, since both are read from the environment when it is made.

use crate::device::{api_limit, create_instance};
use crate::error::{Error, Result};
use crate::validation;
use std::sync::{Arc, Mutex};

pub(crate) struct Instance {
    pub(crate) entry: ash::Entry,
    pub(crate) raw: ash::Instance,
    /// The Vulkan version asked for (see [`api_limit`]).
    pub(crate) api: (u32, u32),
    validated: bool,
}

static OPEN: Mutex<Vec<Arc<Instance>>> = Mutex::new(Vec::new());

/// The instance for the API version and validation the environment asks for, created on first use.
pub(crate) fn shared() -> Result<Arc<Instance>> {
    let api = api_limit()?;
    let validated = validation::requested();
    let mut open = OPEN.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(found) = open.iter().find(|i| i.api == api && i.validated == validated) {
        return Ok(found.clone());
    }
    // SAFETY: loading the system Vulkan loader; its symbols follow the Vulkan ABI.
    let entry = unsafe { ash::Entry::load() }.map_err(|e| Error::NoLoader(e.to_string()))?;
    let raw = create_instance(&entry, api).map_err(|e| match e {
        Error::Vulkan { result: ash::vk::Result::ERROR_INCOMPATIBLE_DRIVER, .. } => Error::NoDriver(searched()),
        e => e,
    })?;
    let made = Arc::new(Instance { entry, raw, api, validated });
    open.push(made.clone());
    Ok(made)
}

/// Where the loader looked for drivers, for the error that found none.
fn searched() -> String {
    let env = |k: &str| std::env::var(k).ok();
    match env("VK_DRIVER_FILES").or_else(|| env("VK_ICD_FILENAMES")).filter(|v| !v.is_empty()) {
        Some(list) => format!("VK_DRIVER_FILES={list}"),
        None => "no driver manifest in the loader's icd.d folders (/usr/share/vulkan/icd.d and the like)".into(),
    }
}

#[cfg(test)]
mod tests {
    use crate::Context;
    use std::sync::Arc;

    #[test]
    fn the_instance_outlives_its_contexts_and_serves_the_next() {
        let first = Context::new(&Default::default()).unwrap();
        let held = Arc::downgrade(&first.shared.vulkan);
        drop(first);
        let next = Context::new(&Default::default()).unwrap();
        let kept = held.upgrade().expect("the instance was destroyed with its last context");
        assert!(Arc::ptr_eq(&kept, &next.shared.vulkan), "the next context made an instance of its own");
    }
}
