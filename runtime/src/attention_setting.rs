//! `VKDIFF_ATTENTION`: which attention kernel a context takes where it has a choice.

use crate::error::{Error, Result};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AttentionKernel {
    /// Unset or `auto`: the kernel `ops::attention` picks for the device and the heads.
    Auto,
    /// `cm2`: `VK_NV_cooperative_matrix2`'s probe (`ops::attention_cm2`, its softmax on the
    /// extension's reductions) wherever the device runs one of its attention tiles and the heads
    /// fit it (f16, up to 64 values), else as `auto`: whole networks timed and tested with it.
    Matrix2,
}

impl AttentionKernel {
    pub fn from_env() -> Result<AttentionKernel> {
        match std::env::var("VKDIFF_ATTENTION") {
            Err(_) => Ok(AttentionKernel::Auto),
            Ok(value) => AttentionKernel::parse(&value),
        }
    }

    pub fn parse(value: &str) -> Result<AttentionKernel> {
        match value.trim().to_ascii_lowercase().as_str() {
            "auto" | "" => Ok(AttentionKernel::Auto),
            "cm2" => Ok(AttentionKernel::Matrix2),
            _ => Err(Error::BadSetting(format!(
                "VKDIFF_ATTENTION={value}: use cm2 (VK_NV_cooperative_matrix2's attention where the device runs it) \
                 or auto (the default)"
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_setting_names_the_kernel() {
        for (value, kernel) in
            [("", AttentionKernel::Auto), (" Auto", AttentionKernel::Auto), ("CM2", AttentionKernel::Matrix2)]
        {
            assert_eq!(AttentionKernel::parse(value).unwrap(), kernel, "{value:?}");
        }
        let err = AttentionKernel::parse("flash").unwrap_err().to_string();
        assert!(err.contains("VKDIFF_ATTENTION=flash: use cm2"), "{err}");
    }
}
