//! `VKDIFF_ATTENTION`, `VKDIFF_LINEAR` and `VKDIFF_CONV`: whether attention, the linear layers'
//! products and the convolution take `VK_NV_cooperative_matrix2`'s probes where the device runs
//! them.

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ProbeChoice {
    /// Unset or `auto`: the kernel `ops` picks for the device and the shape.
    #[default]
    Auto,
    /// `cm2`: the probe (`ops::attention_cm2`, its softmax on the extension's reductions, for f16
    /// heads of up to 64; `ops::linear_cm2` and `ops::conv2d_cm2` for f16 products and
    /// convolutions on their tiles) wherever the device runs one of its tiles and the shape fits
    /// it, else as `auto`: whole networks timed and tested with it.
    Matrix2,
}

impl ProbeChoice {
    /// `auto` (or nothing) or `cm2`, in any case; None for anything else.
    pub fn parse(value: &str) -> Option<ProbeChoice> {
        match value.trim().to_ascii_lowercase().as_str() {
            "auto" | "" => Some(ProbeChoice::Auto),
            "cm2" => Some(ProbeChoice::Matrix2),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_setting_names_the_kernel() {
        for (value, kernel) in [("", ProbeChoice::Auto), (" Auto", ProbeChoice::Auto), ("CM2", ProbeChoice::Matrix2)] {
            assert_eq!(ProbeChoice::parse(value), Some(kernel), "{value:?}");
        }
        assert_eq!(ProbeChoice::parse("flash"), None);
    }
}
