//! The process's Vulkan instance: every context and device listing shares it, and it lives until
//! the process ends or [`release_idle_instances`] destroys it. With an instance of its own per
//! context, NVIDIA's driver (580.159, on an H200) failed the 31st context opened after the one
//! before had closed: vkCreateInstance found "no Vulkan driver" (the loader unloads the driver
//! with the last instance). One instance per (API version, validation) asked for, since both are
//! fixed when it is made ([`crate::Settings::vulkan_api`], [`crate::Settings::validate`]).

use crate::error::{Error, Result, VkContext};
use crate::settings::Settings;
use ash::vk;
use std::sync::{Arc, Mutex};

pub(crate) struct Instance {
    pub(crate) entry: ash::Entry,
    pub(crate) raw: ash::Instance,
    /// The Vulkan version asked for.
    pub(crate) api: (u32, u32),
    validated: bool,
    messenger: Option<ash::vk::DebugUtilsMessengerEXT>,
}

impl Drop for Instance {
    fn drop(&mut self) {
        // SAFETY: no context holds the instance any more (each holds an Arc of it), so nothing
        // made from it is alive; the messenger was made from it.
        unsafe {
            if let Some(messenger) = self.messenger {
                ash::ext::debug_utils::Instance::new(&self.entry, &self.raw)
                    .destroy_debug_utils_messenger(messenger, None);
            }
            self.raw.destroy_instance(None);
        }
    }
}

/// Destroys the instances no context holds, so that a driver which keeps device memory until
/// its instance goes gives it back: Mesa 26.1's lavapipe keeps all it ever allocated (one
/// memfd, 13.5 GB after `bench report`'s image) until then, and the diffusers references the
/// report runs next were killed for want of it (`bench` calls this before each CPU reference).
/// The next context makes a new instance. For the end of a stretch of Vulkan work, not between
/// contexts (NVIDIA's driver failed after 30 such cycles, above).
pub fn release_idle_instances() {
    let mut open = OPEN.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    open.retain(|instance| Arc::strong_count(instance) > 1);
}

static OPEN: Mutex<Vec<Arc<Instance>>> = Mutex::new(Vec::new());

/// The instance for the API version and validation `settings` ask for, created on first use.
/// `drivers` names where the loader looked for drivers, for the error that finds none.
pub(crate) fn shared(settings: &Settings, drivers: &dyn Fn() -> String) -> Result<Arc<Instance>> {
    open_instance((settings.vulkan_api, settings.validate), drivers)
}

fn open_instance((api, validated): ((u32, u32), bool), drivers: &dyn Fn() -> String) -> Result<Arc<Instance>> {
    let mut open = OPEN.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some(found) = open.iter().find(|i| i.api == api && i.validated == validated) {
        return Ok(found.clone());
    }
    // SAFETY: loading the system Vulkan loader; its symbols follow the Vulkan ABI.
    let entry = unsafe { ash::Entry::load() }.map_err(|e| Error::NoLoader(e.to_string()))?;
    let (raw, messenger) = create_instance(&entry, api, validated).map_err(|e| match e {
        Error::Vulkan { result: ash::vk::Result::ERROR_INCOMPATIBLE_DRIVER, .. } => Error::NoDriver(drivers()),
        e => e,
    })?;
    let made = Arc::new(Instance { entry, raw, api, validated, messenger });
    open.push(made.clone());
    Ok(made)
}

/// vkdiff's instance for Vulkan up to `api` (major, minor), validated where `validated`.
/// Where the loader offers `VK_KHR_portability_enumeration`, portability devices (MoltenVK) are
/// listed too.
pub(crate) fn create_instance(
    entry: &ash::Entry,
    api: (u32, u32),
    validated: bool,
) -> Result<(ash::Instance, Option<vk::DebugUtilsMessengerEXT>)> {
    let app = vk::ApplicationInfo::default()
        .application_name(c"vkdiff")
        .engine_name(c"vkdiff")
        .api_version(vk::make_api_version(0, api.0, api.1, 0));
    // SAFETY: a plain query of the loader.
    let available =
        unsafe { entry.enumerate_instance_extension_properties(None) }.vk("vkEnumerateInstanceExtensionProperties")?;
    let portability = ash::khr::portability_enumeration::NAME;
    let mut info = vk::InstanceCreateInfo::default().application_info(&app);
    let mut extensions = Vec::new();
    if available.iter().any(|e| e.extension_name_as_c_str() == Ok(portability)) {
        extensions.push(portability.as_ptr());
        info = info.flags(vk::InstanceCreateFlags::ENUMERATE_PORTABILITY_KHR);
    }
    crate::validation::create_instance(entry, info, extensions, validated)
}

#[cfg(test)]
mod tests {
    use super::{open_instance, release_idle_instances};
    use crate::settings::tests::process_settings;
    use crate::Context;
    use std::sync::{Arc, Mutex};

    /// Held by the tests that watch an instance's lifetime: a release in between would end it.
    static WATCHING: Mutex<()> = Mutex::new(());

    #[test]
    fn the_instance_outlives_its_contexts_and_serves_the_next() {
        let _watching = WATCHING.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let first = Context::new(&Default::default(), process_settings()).unwrap();
        let held = Arc::downgrade(&first.shared.vulkan);
        drop(first);
        let next = Context::new(&Default::default(), process_settings()).unwrap();
        let kept = held.upgrade().expect("the instance was destroyed with its last context");
        assert!(Arc::ptr_eq(&kept, &next.shared.vulkan), "the next context made an instance of its own");
    }

    #[test]
    fn idle_instances_are_released_and_the_next_is_made_anew() {
        let _watching = WATCHING.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        // Vulkan 1.1, which no context asks for: no other test holds this one.
        let validated = process_settings().validate;
        let held = open_instance(((1, 1), validated), &String::new).unwrap();
        let watched = Arc::downgrade(&held);
        release_idle_instances();
        assert!(watched.upgrade().is_some(), "an instance still held was destroyed");
        drop(held);
        release_idle_instances();
        assert!(watched.upgrade().is_none(), "the idle instance was kept");
        let next = open_instance(((1, 1), validated), &String::new).unwrap();
        // SAFETY: the instance is alive while `next` is.
        let devices = unsafe { next.raw.enumerate_physical_devices() }.unwrap();
        assert!(!devices.is_empty(), "the new instance finds no device");
    }
}
