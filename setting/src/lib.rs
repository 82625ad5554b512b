//! Messages about settings, with every setting they name kept as data, and the environment
//! variables settings are read from, parsed by one grammar.
//!
//! The libraries name a setting by its field in their settings types (`guidance_scale`,
//! `crop_size`); a front end that calls them something else (the command line's `--cfg`,
//! `--crop-size`) installs its names once with [`name_settings_with`], and every message then
//! reads in its words. Without a front end's names a message prints the field names.

mod environment;
mod version;

pub use environment::{BadVariable, Environment, SWITCH_VALUES};
pub use version::{install_version, version};

use std::fmt;
use std::sync::OnceLock;

/// How this process prints a setting's name: the front end's choice, set once.
static NAMES: OnceLock<fn(&str) -> String> = OnceLock::new();

/// Prints every setting named in a [`Message`] as `names` says from now on (the first call
/// wins; a process runs one front end). Returns whether this call's names are the ones in use.
pub fn name_settings_with(names: fn(&str) -> String) -> bool {
    NAMES.set(names).is_ok()
}

#[derive(Clone, Debug, PartialEq, Eq)]
enum Part {
    Text(String),
    Setting(String),
}

/// Text interleaved with settings' names, built left to right:
/// `Message::setting("steps").text(" must be at least 1")`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Message(Vec<Part>);

impl Message {
    /// A message that starts with a setting's name.
    pub fn setting(name: impl Into<String>) -> Message {
        Message(vec![Part::Setting(name.into())])
    }

    /// A message that starts with text.
    pub fn text(text: impl Into<String>) -> Message {
        Message(vec![Part::Text(text.into())])
    }

    /// Appends a setting's name.
    pub fn and(mut self, name: impl Into<String>) -> Message {
        self.0.push(Part::Setting(name.into()));
        self
    }

    /// Appends text.
    pub fn then(mut self, text: impl Into<String>) -> Message {
        self.0.push(Part::Text(text.into()));
        self
    }

    /// Appends another message.
    pub fn append(mut self, other: Message) -> Message {
        self.0.extend(other.0);
        self
    }

    /// The settings this message names, in order: what a caller fixes.
    pub fn settings(&self) -> impl Iterator<Item = &str> {
        self.0.iter().filter_map(|p| match p {
            Part::Setting(name) => Some(name.as_str()),
            Part::Text(_) => None,
        })
    }
}

impl fmt::Display for Message {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for part in &self.0 {
            match part {
                Part::Text(text) => f.write_str(text)?,
                Part::Setting(name) => match NAMES.get() {
                    Some(names) => f.write_str(&names(name))?,
                    None => f.write_str(name)?,
                },
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_settings_as_the_front_end_says_once_installed() {
        let m = Message::setting("crop_size").then(" 0 must exceed ").and("tile_overlap").then(".");
        assert_eq!(m.settings().collect::<Vec<_>>(), ["crop_size", "tile_overlap"]);
        assert_eq!(m.to_string(), "crop_size 0 must exceed tile_overlap.");
        assert!(name_settings_with(|name| format!("--{}", name.replace('_', "-"))));
        assert!(!name_settings_with(|name| name.to_uppercase()), "the first front end's names stay");
        assert_eq!(m.to_string(), "--crop-size 0 must exceed --tile-overlap.");
        assert_eq!(Message::text("no setting").to_string(), "no setting");
    }
}
