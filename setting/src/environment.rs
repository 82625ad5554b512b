//! The process's environment, read once at the edge and handed down as a value, with the one
//! grammar every `VKDIFF_*` variable is parsed by: a variable set to nothing (or blanks) reads
//! as unset; a switch takes 1/0, true/false, yes/no or on/off (any case), and `auto` for its
//! default; every other value is parsed by its setting and a value it refuses names the variable
//! and what it accepts.

use std::collections::BTreeMap;
use std::fmt;

/// A variable's value that its setting refuses.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BadVariable {
    pub name: String,
    pub value: String,
    /// What the variable accepts, as a phrase: "1 or 0", "a size such as 8G".
    pub expected: String,
}

impl fmt::Display for BadVariable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}={}: expected {}", self.name, self.value, self.expected)
    }
}

impl std::error::Error for BadVariable {}

/// What a switch accepts, for messages and help.
pub const SWITCH_VALUES: &str = "1 or 0 (also true/false, yes/no, on/off; auto or nothing for the default)";

/// A snapshot of environment variables.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Environment {
    vars: BTreeMap<String, String>,
}

impl Environment {
    /// This process's environment now: the one place vkdiff reads it (variables whose name or
    /// value is not Unicode are left out; none of vkdiff's is).
    pub fn of_process() -> Environment {
        Environment::from_pairs(
            std::env::vars_os().filter_map(|(k, v)| Some((k.into_string().ok()?, v.into_string().ok()?))),
        )
    }

    /// An environment of these variables (tests give theirs).
    pub fn from_pairs<K: Into<String>, V: Into<String>>(pairs: impl IntoIterator<Item = (K, V)>) -> Environment {
        Environment { vars: pairs.into_iter().map(|(k, v)| (k.into(), v.into())).collect() }
    }

    /// `name`'s value, trimmed; None where unset or blank.
    pub fn get(&self, name: &str) -> Option<&str> {
        self.vars.get(name).map(|v| v.trim()).filter(|v| !v.is_empty())
    }

    /// `name`'s value exactly as set, blank included (a scheduler's empty device list gives a
    /// process no device).
    pub fn raw(&self, name: &str) -> Option<&str> {
        self.vars.get(name).map(String::as_str)
    }

    /// A switch: Some(true) for 1/true/yes/on, Some(false) for 0/false/no/off, None where unset,
    /// blank or `auto`.
    pub fn switch(&self, name: &str) -> Result<Option<bool>, BadVariable> {
        self.parse(name, SWITCH_VALUES, |value| match value.to_ascii_lowercase().as_str() {
            "1" | "true" | "yes" | "on" => Some(Some(true)),
            "0" | "false" | "no" | "off" => Some(Some(false)),
            "auto" => Some(None),
            _ => None,
        })
        .map(Option::flatten)
    }

    /// `name` parsed by `parse`, which returns None for a value it refuses (the error then says
    /// the value was `expected`); None where unset or blank.
    pub fn parse<T>(
        &self,
        name: &str,
        expected: &str,
        parse: impl FnOnce(&str) -> Option<T>,
    ) -> Result<Option<T>, BadVariable> {
        let Some(value) = self.get(name) else { return Ok(None) };
        match parse(value) {
            Some(parsed) => Ok(Some(parsed)),
            None => Err(BadVariable { name: name.into(), value: value.into(), expected: expected.into() }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn switches_read_every_spelling_and_refuse_the_rest_by_name() {
        let env = Environment::from_pairs([
            ("ON", " Yes"),
            ("OFF", "off"),
            ("TRUE", "TRUE"),
            ("ZERO", "0"),
            ("AUTO", "auto"),
            ("BLANK", "  "),
            ("BAD", "maybe"),
        ]);
        assert_eq!(env.switch("ON"), Ok(Some(true)));
        assert_eq!(env.switch("TRUE"), Ok(Some(true)));
        assert_eq!(env.switch("OFF"), Ok(Some(false)));
        assert_eq!(env.switch("ZERO"), Ok(Some(false)));
        assert_eq!(env.switch("AUTO"), Ok(None));
        assert_eq!(env.switch("BLANK"), Ok(None));
        assert_eq!(env.switch("UNSET"), Ok(None));
        let err = env.switch("BAD").unwrap_err().to_string();
        assert_eq!(err, format!("BAD=maybe: expected {SWITCH_VALUES}"));
    }

    #[test]
    fn values_are_trimmed_and_refused_with_what_they_accept() {
        let env = Environment::from_pairs([("N", " 12 "), ("X", "twelve")]);
        let number = |v: &str| v.parse::<u32>().ok();
        assert_eq!(env.parse("N", "a number", number), Ok(Some(12)));
        assert_eq!(env.parse("UNSET", "a number", number), Ok(None));
        assert_eq!(env.parse("X", "a number", number).unwrap_err().to_string(), "X=twelve: expected a number");
        assert_eq!(env.get("N"), Some("12"));
    }
}
