//! Uniform texel views of a tensor, as the CPU family's subgroup kernels read B (and A in the
//! plain products) where the device fetches texels faster than it loads storage (`texel_reads` in
//! the plan): what the device allows, whether a tensor fits it, and the view itself.

use crate::context::Context;
use crate::device::DeviceInfo;
use crate::error::{Result, VkContext};
use crate::tensor::{dtype_size, Dtype, Tensor};
use ash::vk;
use vkdiff_kernels::Variant;

/// What a device allows of a uniform texel buffer's view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TexelLimits {
    pub max_elements: u32,
    pub offset_alignment: u64,
}

/// The texel views the device allows, where it fetches every [`Texels`] format from uniform texel
/// buffers.
pub(crate) fn limits(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    limits: &vk::PhysicalDeviceLimits,
) -> Option<TexelLimits> {
    let formats = [Texels::Values(Dtype::F32), Texels::Values(Dtype::F16), Texels::Halves8].map(Texels::format);
    let fetched = formats.iter().all(|&format| {
        // SAFETY: pd comes from this instance.
        let props = unsafe { instance.get_physical_device_format_properties(pd, format) };
        props.buffer_features.contains(vk::FormatFeatureFlags::UNIFORM_TEXEL_BUFFER)
    });
    fetched.then_some(TexelLimits {
        max_elements: limits.max_texel_buffer_elements,
        offset_alignment: limits.min_texel_buffer_offset_alignment.max(1),
    })
}

/// What a texel holds, as a kernel variant reads its texel operands (all of them alike).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Texels {
    /// Four values in their dtype (RGBA32F, RGBA16F), which the fetch widens to f32.
    Values(Dtype),
    /// Eight halves as four 32-bit words (RGBA32UI), which the kernel unpacks: f16 A and B of
    /// the products that read both from texels (TA = 1, kernels/wgsl/gemm_sg_pairs.wgsl).
    Halves8,
}

impl Texels {
    /// How `variant` reads its texel operands.
    pub(crate) fn of(variant: &Variant) -> Texels {
        match (variant.dtype, variant.param("TA")) {
            (Dtype::F16, Some(1)) => Texels::Halves8,
            (dtype, _) => Texels::Values(dtype),
        }
    }

    fn format(self) -> vk::Format {
        match self {
            Texels::Values(Dtype::F32) => vk::Format::R32G32B32A32_SFLOAT,
            Texels::Values(Dtype::F16) => vk::Format::R16G16B16A16_SFLOAT,
            Texels::Halves8 => vk::Format::R32G32B32A32_UINT,
        }
    }

    fn bytes(self) -> u64 {
        match self {
            Texels::Values(dtype) => 4 * dtype_size(dtype) as u64,
            Texels::Halves8 => 16,
        }
    }
}

/// Whether the device allows a texel view of all of `t` (from its offset) in `texels`.
pub(crate) fn fits(info: &DeviceInfo, t: &Tensor, texels: Texels) -> bool {
    info.texel_fetch.is_some_and(|limits| texels_fit(limits, t.offset, t.bytes(), texels.bytes()))
}

/// Whether `bytes` from `offset` make a texel view of `texel`-byte texels within `limits`.
fn texels_fit(limits: TexelLimits, offset: u64, bytes: u64, texel: u64) -> bool {
    offset.is_multiple_of(limits.offset_alignment) && bytes >= texel && bytes / texel <= u64::from(limits.max_elements)
}

/// A view of `t` in `texels`; the caller checked [`fits`]. The recording that binds it destroys
/// it.
pub(crate) fn create(ctx: &Context, t: &Tensor, texels: Texels) -> Result<vk::BufferView> {
    let texel = texels.bytes();
    let info = vk::BufferViewCreateInfo::default()
        .buffer(t.buf.raw)
        .format(texels.format())
        .offset(t.offset)
        .range(t.bytes() / texel * texel);
    // SAFETY: the buffer lives as long as the recording, which destroys the view.
    unsafe { ctx.shared.device.create_buffer_view(&info, None) }.vk("vkCreateBufferView")
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
