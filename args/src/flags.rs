//! The command line's names for the settings the libraries name in their errors
//! (`vkdiff_setting::Message`): `--` and the name with dashes, except where a flag is called
//! otherwise.

/// The flag of `setting` in every command but `dataset`.
pub fn flag(setting: &str) -> String {
    match setting {
        "guidance_scale" => "--cfg".into(),
        "replace" => "--force".into(),
        other => format!("--{}", other.replace('_', "-")),
    }
}

/// The flag of `setting` in `vkdiff dataset`, whose img2img strength is `--init-strength`.
pub fn dataset_flag(setting: &str) -> String {
    match setting {
        "strength" => "--init-strength".into(),
        other => flag(other),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_map_to_the_flags_clap_defines() {
        assert_eq!(flag("guidance_scale"), "--cfg");
        assert_eq!(flag("replace"), "--force");
        assert_eq!(flag("crop_min_fraction"), "--crop-min-fraction");
        assert_eq!(flag("strength"), "--strength");
        assert_eq!(dataset_flag("strength"), "--init-strength");
        assert_eq!(dataset_flag("ip_image"), "--ip-image");
    }
}
