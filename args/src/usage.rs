//! A refusal of the command line itself (a flag's value, a combination of flags) that no
//! library makes: exit code 2, as clap's own usage errors.

/// One line naming the flag at fault.
#[derive(Debug)]
pub struct Usage(pub String);

impl std::fmt::Display for Usage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Usage {}

/// `Err(Usage(message))` unless `cond` holds.
pub fn ensure_usage(cond: bool, message: impl FnOnce() -> String) -> anyhow::Result<()> {
    if cond {
        Ok(())
    } else {
        Err(Usage(message()).into())
    }
}
