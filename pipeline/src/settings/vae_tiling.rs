//! `--vae-tiling`: whether the VAE decodes the whole image at once or in diffusers' overlapping
//! tiles (`enable_tiling`), which need a tile's memory rather than the image's.

use std::fmt;
use std::str::FromStr;

/// How the VAE decodes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum VaeTilingSetting {
    /// Whole where the memory plan says the decode fits, else in the largest tiles that fit.
    #[default]
    Auto,
    /// Whole; a decode that does not fit fails before the denoising starts.
    Off,
    /// In tiles of diffusers' default side, the VAE config's `sample_size`.
    On,
    /// In tiles of this many pixels.
    Pixels(usize),
}

impl FromStr for VaeTilingSetting {
    type Err = String;

    fn from_str(text: &str) -> Result<VaeTilingSetting, String> {
        match text.trim() {
            "auto" => Ok(VaeTilingSetting::Auto),
            "off" => Ok(VaeTilingSetting::Off),
            "on" => Ok(VaeTilingSetting::On),
            other => other
                .parse()
                .ok()
                .filter(|&n| n > 0)
                .map(VaeTilingSetting::Pixels)
                .ok_or_else(|| format!("`{text}`: give auto, off, on, or a tile side in pixels")),
        }
    }
}

impl fmt::Display for VaeTilingSetting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            VaeTilingSetting::Auto => f.write_str("auto"),
            VaeTilingSetting::Off => f.write_str("off"),
            VaeTilingSetting::On => f.write_str("on"),
            VaeTilingSetting::Pixels(n) => write!(f, "{n}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_what_it_writes() {
        for setting in
            [VaeTilingSetting::Auto, VaeTilingSetting::Off, VaeTilingSetting::On, VaeTilingSetting::Pixels(512)]
        {
            assert_eq!(setting.to_string().parse(), Ok(setting));
        }
        for bad in ["0", "yes", "-64", ""] {
            assert!(bad.parse::<VaeTilingSetting>().unwrap_err().contains("give auto, off, on"), "{bad}");
        }
    }
}
