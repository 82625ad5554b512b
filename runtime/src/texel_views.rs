//! Uniform texel views of a tensor, as the CPU family's subgroup kernels read B where the device
//! fetches texels faster than it loads storage (`texel_b` in the plan): what the device allows,
//! whether a tensor fits it, and the view itself.

use crate::context::Context;
use crate::device::DeviceInfo;
use crate::error::{Result, VkContext};
use crate::tensor::{dtype_size, Dtype, Tensor};
use ash::vk;

/// What a device allows of a uniform texel buffer's view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TexelLimits {
    pub max_elements: u32,
    pub offset_alignment: u64,
}

/// The texel views the device allows, where it fetches RGBA texels in f32 and f16 from uniform
/// texel buffers.
pub(crate) fn limits(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    limits: &vk::PhysicalDeviceLimits,
) -> Option<TexelLimits> {
    let fetched = [format(Dtype::F32), format(Dtype::F16)].iter().all(|&format| {
        // SAFETY: pd comes from this instance.
        let props = unsafe { instance.get_physical_device_format_properties(pd, format) };
        props.buffer_features.contains(vk::FormatFeatureFlags::UNIFORM_TEXEL_BUFFER)
    });
    fetched.then_some(TexelLimits {
        max_elements: limits.max_texel_buffer_elements,
        offset_alignment: limits.min_texel_buffer_offset_alignment.max(1),
    })
}

/// Whether the device allows a texel view of all of `b` (four values a texel, from its offset).
pub(crate) fn fits(info: &DeviceInfo, b: &Tensor) -> bool {
    let texel = texel_bytes(b.dtype());
    info.texel_fetch.is_some_and(|limits| texels_fit(limits, b.offset, b.bytes(), texel))
}

/// Whether `bytes` from `offset` make a texel view of `texel`-byte texels within `limits`.
fn texels_fit(limits: TexelLimits, offset: u64, bytes: u64, texel: u64) -> bool {
    offset.is_multiple_of(limits.offset_alignment) && bytes >= texel && bytes / texel <= u64::from(limits.max_elements)
}

/// A view of `t` as four-value texels (RGBA in its dtype); the caller checked [`fits`]. The
/// recording that binds it destroys it.
pub(crate) fn create(ctx: &Context, t: &Tensor) -> Result<vk::BufferView> {
    let texel = texel_bytes(t.dtype());
    let info = vk::BufferViewCreateInfo::default()
        .buffer(t.buf.raw)
        .format(format(t.dtype()))
        .offset(t.offset)
        .range(t.bytes() / texel * texel);
    // SAFETY: the buffer lives as long as the recording, which destroys the view.
    unsafe { ctx.shared.device.create_buffer_view(&info, None) }.vk("vkCreateBufferView")
}

/// The RGBA format of a texel of a storage dtype, which the fetch widens to f32.
fn format(dtype: Dtype) -> vk::Format {
    match dtype {
        Dtype::F32 => vk::Format::R32G32B32A32_SFLOAT,
        Dtype::F16 => vk::Format::R16G16B16A16_SFLOAT,
    }
}

/// Bytes of a four-value texel of a storage dtype.
fn texel_bytes(dtype: Dtype) -> u64 {
    4 * dtype_size(dtype) as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn b_takes_a_texel_view_only_within_the_devices_limits() {
        let limits = TexelLimits { max_elements: 1000, offset_alignment: 64 };
        assert!(texels_fit(limits, 128, 16 * 1000, 16), "aligned, at the element limit");
        assert!(!texels_fit(limits, 16, 16 * 1000, 16), "an offset off the texel alignment");
        assert!(!texels_fit(limits, 0, 16 * 1001, 16), "past the element limit");
        assert!(!texels_fit(limits, 0, 8, 16), "less than one texel");
        assert!(texels_fit(limits, 0, 8 * 1000 + 4, 8), "a partial last texel is left out of the view");
    }
}
