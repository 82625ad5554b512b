//! `VKDIFF_VALIDATE=1` ([`crate::Settings::validate`]): every instance vkdiff creates runs the Khronos validation layer with
//! synchronization validation. A message is printed and the process aborts, so no test and no
//! run passes with one (lavapipe forgives what real drivers need not).

use crate::error::{Error, Result, VkContext};
use ash::vk;
use std::ffi::{c_char, c_void, CStr};

const LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// Creates the instance `info` describes with `extensions`, validated where `validated`, with the
/// debug messenger that prints the layer's messages (destroyed with the instance,
/// [`crate::instance`]).
pub(crate) fn create_instance(
    entry: &ash::Entry,
    info: vk::InstanceCreateInfo,
    mut extensions: Vec<*const c_char>,
    validated: bool,
) -> Result<(ash::Instance, Option<vk::DebugUtilsMessengerEXT>)> {
    if !validated {
        let info = info.enabled_extension_names(&extensions);
        // SAFETY: the create info and everything it points to outlive the call.
        return Ok((unsafe { entry.create_instance(&info, None) }.vk("vkCreateInstance")?, None));
    }
    // SAFETY: a plain query of the loader.
    let layers = unsafe { entry.enumerate_instance_layer_properties() }.vk("vkEnumerateInstanceLayerProperties")?;
    if !layers.iter().any(|l| l.layer_name_as_c_str() == Ok(LAYER)) {
        return Err(Error::NoValidationLayer);
    }
    let layer_names: [*const c_char; 1] = [LAYER.as_ptr()];
    extensions.push(ash::ext::debug_utils::NAME.as_ptr());
    let features = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
    let mut enables = vk::ValidationFeaturesEXT::default().enabled_validation_features(&features);
    let info = info.enabled_layer_names(&layer_names).enabled_extension_names(&extensions).push_next(&mut enables);
    // SAFETY: the create info and everything it points to outlive the call.
    let instance = unsafe { entry.create_instance(&info, None) }.vk("vkCreateInstance")?;
    let loader = ash::ext::debug_utils::Instance::new(entry, &instance);
    let create = vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(vk::DebugUtilsMessageSeverityFlagsEXT::WARNING | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR)
        .message_type(vk::DebugUtilsMessageTypeFlagsEXT::GENERAL | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION)
        .pfn_user_callback(Some(on_message));
    // SAFETY: the instance was created with the debug-utils extension.
    match unsafe { loader.create_debug_utils_messenger(&create, None) } {
        Ok(messenger) => Ok((instance, Some(messenger))),
        Err(e) => {
            // SAFETY: nothing else was created from the instance.
            unsafe { instance.destroy_instance(None) };
            Err(e).vk("vkCreateDebugUtilsMessengerEXT")
        }
    }
}

unsafe extern "system" fn on_message(
    _severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _kind: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    _user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the layer passes valid callback data with a NUL-terminated message.
    let message = unsafe { data.as_ref().and_then(|d| d.message_as_c_str()).map(|m| m.to_string_lossy().into_owned()) };
    eprintln!("vkdiff: Vulkan validation (VKDIFF_VALIDATE=1): {}", message.unwrap_or_default());
    std::process::abort()
}
