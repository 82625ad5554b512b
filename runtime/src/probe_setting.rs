//! `VKDIFF_ATTENTION`, `VKDIFF_LINEAR` and `VKDIFF_CONV`: whether attention, the linear layers'
//! products and the convolution take `VK_NV_cooperative_matrix2`'s probes where the device runs
//! them.

use crate::error::{Error, Result};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProbeChoice {
    /// Unset or `auto`: the kernel `ops` picks for the device and the shape.
    Auto,
    /// `cm2`: the probe (`ops::attention_cm2`, its softmax on the extension's reductions, for f16
    /// heads of up to 64; `ops::linear_cm2` and `ops::conv2d_cm2` for f16 products and
    /// convolutions on their tiles) wherever the device runs one of its tiles and the shape fits
    /// it, else as `auto`: whole networks timed and tested with it.
    Matrix2,
}

impl ProbeChoice {
    /// `VKDIFF_ATTENTION`.
    pub fn attention_from_env() -> Result<ProbeChoice> {
        ProbeChoice::from_env("VKDIFF_ATTENTION", "attention")
    }

    /// `VKDIFF_LINEAR`.
    pub fn linear_from_env() -> Result<ProbeChoice> {
        ProbeChoice::from_env("VKDIFF_LINEAR", "linear layers")
    }

    /// `VKDIFF_CONV`.
    pub fn conv_from_env() -> Result<ProbeChoice> {
        ProbeChoice::from_env("VKDIFF_CONV", "convolution")
    }

    fn from_env(variable: &str, op: &str) -> Result<ProbeChoice> {
        match std::env::var(variable) {
            Err(_) => Ok(ProbeChoice::Auto),
            Ok(value) => ProbeChoice::parse(variable, &value, op),
        }
    }

    /// `value` of `variable`, the setting of `op`'s kernel.
    pub fn parse(variable: &str, value: &str, op: &str) -> Result<ProbeChoice> {
        match value.trim().to_ascii_lowercase().as_str() {
            "auto" | "" => Ok(ProbeChoice::Auto),
            "cm2" => Ok(ProbeChoice::Matrix2),
            _ => Err(Error::BadSetting(format!(
                "{variable}={value}: use cm2 (VK_NV_cooperative_matrix2's {op} where the device runs it) or auto \
                 (the default)"
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_setting_names_the_kernel() {
        for (value, kernel) in [("", ProbeChoice::Auto), (" Auto", ProbeChoice::Auto), ("CM2", ProbeChoice::Matrix2)] {
            assert_eq!(ProbeChoice::parse("VKDIFF_CONV", value, "convolution").unwrap(), kernel, "{value:?}");
        }
        let err = ProbeChoice::parse("VKDIFF_ATTENTION", "flash", "attention").unwrap_err().to_string();
        assert!(err.contains("VKDIFF_ATTENTION=flash: use cm2 (VK_NV_cooperative_matrix2's attention"), "{err}");
    }
}
