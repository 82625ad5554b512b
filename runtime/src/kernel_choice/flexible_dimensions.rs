//! `VK_NV_cooperative_matrix2`'s flexible dimensions, newer than ash's headers: the feature
//! struct and the query of the granularities, which let a device take fragment shapes it does
//! not list (`VKDIFF_FRAGMENT`; Mesa 26.1 lavapipe runs Intel's shapes this way in CI).

use crate::kernel_choice::matrix_units::{component, MatrixShape};
use ash::vk;

/// `VkPhysicalDeviceCooperativeMatrix2FeaturesNV` (`VK_NV_cooperative_matrix2`, newer than
/// ash's headers): its seven features in the header's order ([`FEATURE_NAMES`]); vkdiff enables
/// `cooperativeMatrixFlexibleDimensions` and, for its probes (`ops::linear_cm2`, `ops::conv2d_cm2`,
/// `ops::attention_cm2`), the scope and operations their tiles use.
#[repr(C)]
pub(crate) struct CooperativeMatrix2Features {
    s_type: vk::StructureType,
    p_next: *mut std::ffi::c_void,
    features: [vk::Bool32; 7],
}

/// The features of `VK_NV_cooperative_matrix2`, as `vkdiff devices` names them.
pub const FEATURE_NAMES: [&str; 7] = [
    "workgroup scope",
    "flexible dimensions",
    "reductions",
    "conversions",
    "per-element operations",
    "tensor addressing",
    "block loads",
];
const FLEXIBLE_DIMENSIONS: usize = 1;

// SAFETY: the struct is laid out as the Vulkan one, which extends both chains.
unsafe impl vk::ExtendsPhysicalDeviceFeatures2 for CooperativeMatrix2Features {}
unsafe impl vk::ExtendsDeviceCreateInfo for CooperativeMatrix2Features {}

impl CooperativeMatrix2Features {
    pub(crate) const EXTENSION: &'static std::ffi::CStr = c"VK_NV_cooperative_matrix2";

    /// Every feature off but those `named` ([`FEATURE_NAMES`]).
    pub(crate) fn enabling(named: &[&str]) -> Self {
        let features = FEATURE_NAMES.map(|name| named.contains(&name).into());
        CooperativeMatrix2Features {
            s_type: vk::StructureType::from_raw(1_000_593_000),
            p_next: std::ptr::null_mut(),
            features,
        }
    }

    pub(crate) fn flexible_dimensions(&self) -> bool {
        self.features[FLEXIBLE_DIMENSIONS] == vk::TRUE
    }

    /// The names of the features the device reports ([`FEATURE_NAMES`]).
    pub(crate) fn reported(&self) -> Vec<&'static str> {
        FEATURE_NAMES.iter().zip(self.features).filter(|(_, on)| *on == vk::TRUE).map(|(name, _)| *name).collect()
    }
}

/// `VkCooperativeMatrixFlexibleDimensionsPropertiesNV`.
#[repr(C)]
#[derive(Clone, Copy)]
struct FlexibleDimensions {
    s_type: vk::StructureType,
    p_next: *mut std::ffi::c_void,
    m_granularity: u32,
    n_granularity: u32,
    k_granularity: u32,
    types: [vk::ComponentTypeKHR; 4],
    saturating_accumulation: vk::Bool32,
    scope: vk::ScopeKHR,
    workgroup_invocations: u32,
}

/// The granularities `vkGetPhysicalDeviceCooperativeMatrixFlexibleDimensionsPropertiesNV` lists
/// for `pd`, as shapes (m, n, k: the granularities); empty where the query is missing or fails.
pub(crate) fn query(entry: &ash::Entry, instance: &ash::Instance, pd: vk::PhysicalDevice) -> Vec<MatrixShape> {
    type Query = unsafe extern "system" fn(vk::PhysicalDevice, *mut u32, *mut FlexibleDimensions) -> vk::Result;
    let name = c"vkGetPhysicalDeviceCooperativeMatrixFlexibleDimensionsPropertiesNV";
    // SAFETY: a valid instance; the name is NUL-terminated.
    let Some(address) = (unsafe { (entry.static_fn().get_instance_proc_addr)(instance.handle(), name.as_ptr()) })
    else {
        return Vec::new();
    };
    // SAFETY: the loader returns this command's entry point, whose signature is `Query`.
    let query: Query = unsafe { std::mem::transmute::<unsafe extern "system" fn(), Query>(address) };
    let blank = FlexibleDimensions {
        s_type: vk::StructureType::from_raw(1_000_593_001),
        p_next: std::ptr::null_mut(),
        m_granularity: 0,
        n_granularity: 0,
        k_granularity: 0,
        types: [vk::ComponentTypeKHR::FLOAT16; 4],
        saturating_accumulation: vk::FALSE,
        scope: vk::ScopeKHR::DEVICE,
        workgroup_invocations: 0,
    };
    let mut count = 0;
    // SAFETY: the two-call idiom; `list` holds `count` initialised structs with their sType.
    let mut list = unsafe {
        if query(pd, &mut count, std::ptr::null_mut()) != vk::Result::SUCCESS {
            return Vec::new();
        }
        let mut list = vec![blank; count as usize];
        if query(pd, &mut count, list.as_mut_ptr()) != vk::Result::SUCCESS {
            return Vec::new();
        }
        list
    };
    list.truncate(count as usize);
    list.iter()
        .map(|f| MatrixShape {
            m: f.m_granularity,
            n: f.n_granularity,
            k: f.k_granularity,
            types: f.types.map(component),
            subgroup_scope: f.scope == vk::ScopeKHR::SUBGROUP,
            workgroup_invocations: if f.scope == vk::ScopeKHR::WORKGROUP { f.workgroup_invocations } else { 0 },
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reported_features_are_named_in_the_headers_order() {
        let mut f = CooperativeMatrix2Features::enabling(&["flexible dimensions"]);
        assert!(f.flexible_dimensions());
        assert_eq!(f.reported(), ["flexible dimensions"]);
        let both = CooperativeMatrix2Features::enabling(&["flexible dimensions", "workgroup scope"]);
        assert_eq!(both.reported(), ["workgroup scope", "flexible dimensions"]);
        f.features = [vk::TRUE, vk::FALSE, vk::FALSE, vk::FALSE, vk::FALSE, vk::TRUE, vk::TRUE];
        assert!(!f.flexible_dimensions());
        assert_eq!(f.reported(), ["workgroup scope", "tensor addressing", "block loads"]);
        assert!(CooperativeMatrix2Features::enabling(&[]).reported().is_empty());
    }
}
