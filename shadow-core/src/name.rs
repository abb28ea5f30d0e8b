//! Method names as a user types them: a family, then options, each after a
//! `:`, an option a switch (`queries`) or a `key=value` (`k=66`), e.g.
//! `occlusion-query:k=66:queries`. Each method crate reads its own options
//! (`Config::from_name`) and writes its settings back in the same words
//! (`Config::name`), so that the name a report prints is one a user can
//! type and builds the same method.
//!
//! ```
//! use shadow_core::name::{MethodName, NameWriter};
//!
//! let name = MethodName::parse("blur:radius=2:fast", "blur")?;
//! let mut radius = 1.0_f32;
//! let mut fast = false;
//! for option in name.options() {
//!     match (option.key, option.value) {
//!         ("radius", Some(value)) => radius = name.value(option, value)?,
//!         ("fast", None) => fast = true,
//!         _ => return Err(name.unknown(option, &["radius=R", "fast"])),
//!     }
//! }
//! assert_eq!((radius, fast), (2.0, true));
//!
//! let typo = MethodName::parse("blur:fsat", "blur")?;
//! let error = typo.unknown(typo.options().next().unwrap(), &["radius=R", "fast"]);
//! assert!(error.to_string().contains("did you mean fast?"));
//!
//! let mut written = NameWriter::new("blur");
//! written.value("radius", 2.0);
//! written.switch("fast", fast);
//! assert_eq!(written.finish(), "blur:radius=2:fast");
//! # Ok::<(), shadow_core::Error>(())
//! ```

use std::{fmt::Display, str::FromStr};

use crate::{Error, Result};

/// One option of a name: `key` alone (a switch) or `key=value`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Opt<'a> {
    pub key: &'a str,
    pub value: Option<&'a str>,
}

impl Display for Opt<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.value {
            Some(value) => write!(f, "{}={value}", self.key),
            None => f.write_str(self.key),
        }
    }
}

/// A method name split into its family and options; errors about it name
/// the whole text.
#[derive(Clone, Debug)]
pub struct MethodName<'a> {
    text: &'a str,
    options: Vec<Opt<'a>>,
}

impl<'a> MethodName<'a> {
    /// Splits `text`, which must be `family` alone or followed by `:` and
    /// options; an empty option (`family::k=6`, a trailing `:`) is refused.
    pub fn parse(text: &'a str, family: &str) -> Result<MethodName<'a>> {
        let rest = text
            .strip_prefix(family)
            .ok_or_else(|| Error::config(text, format!("not a {family} method")))?;
        let options = match rest.strip_prefix(':') {
            None if rest.is_empty() => Vec::new(),
            None => {
                return Err(Error::config(
                    text,
                    format!("options follow the family {family} after ':'"),
                ));
            }
            Some(options) => options
                .split(':')
                .map(|option| match option.split_once('=') {
                    _ if option.is_empty() => {
                        Err(Error::config(text, "an empty option (two ':' in a row)"))
                    }
                    Some((key, value)) => Ok(Opt {
                        key,
                        value: Some(value),
                    }),
                    None => Ok(Opt {
                        key: option,
                        value: None,
                    }),
                })
                .collect::<Result<_>>()?,
        };
        Ok(MethodName { text, options })
    }

    /// The whole name.
    pub fn text(&self) -> &'a str {
        self.text
    }

    /// The options in the order given.
    pub fn options(&self) -> impl Iterator<Item = Opt<'a>> + '_ {
        self.options.iter().copied()
    }

    /// Whether the switch `key` is among the options.
    pub fn has(&self, key: &str) -> bool {
        self.options
            .iter()
            .any(|o| o.key == key && o.value.is_none())
    }

    /// `value` of `option` read as a `T`; the error names the option.
    pub fn value<T: FromStr>(&self, option: Opt<'_>, value: &str) -> Result<T> {
        value.parse().map_err(|_| {
            self.error(format!(
                "{option}: {value:?} is not a {}",
                readable_type::<T>()
            ))
        })
    }

    /// An error about this name.
    pub fn error(&self, what: impl Into<String>) -> Error {
        Error::config(self.text, what)
    }

    /// `checked`, a settings check's result, with its error about this
    /// name: a check names the family, the user typed the name.
    pub fn checked(&self, checked: Result<()>) -> Result<()> {
        checked.map_err(|e| match e {
            Error::InvalidConfig { what, .. } => self.error(what),
            other => self.error(other.to_string()),
        })
    }

    /// The error for an option not in `vocabulary` (entries such as `k=N`
    /// or `queries`): it names the closest entry, when one is close, and
    /// every entry.
    pub fn unknown(&self, option: Opt<'_>, vocabulary: &[&str]) -> Error {
        let keys = vocabulary
            .iter()
            .map(|entry| entry.split('=').next().unwrap_or(entry));
        let hint = match closest(option.key, keys) {
            Some(key) => {
                let entry = vocabulary.iter().find(|e| e.split('=').next() == Some(key));
                format!(" (did you mean {}?)", entry.unwrap_or(&key))
            }
            None => String::new(),
        };
        self.error(format!(
            "unknown option \"{option}\"{hint}; options are {}",
            vocabulary.join(", ")
        ))
    }
}

/// The candidate closest to `word` by edit distance (insertions,
/// deletions, substitutions and swaps of neighbours), if it differs in at
/// most half its letters: a typo of it.
pub fn closest<'a>(word: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    candidates
        .into_iter()
        .map(|c| (strsim::normalized_damerau_levenshtein(word, c), c))
        .filter(|(similarity, _)| *similarity >= 0.5)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, c)| c)
}

/// What a parse failure calls `T`.
fn readable_type<T>() -> &'static str {
    let name = std::any::type_name::<T>();
    if name.starts_with('f') {
        "number"
    } else if name.starts_with('u') || name.starts_with('i') {
        "whole number"
    } else {
        name.rsplit("::").next().unwrap_or(name)
    }
}

/// Writes a name in the words [`MethodName`] reads: the family, then each
/// option after a `:`.
#[derive(Clone, Debug)]
pub struct NameWriter(String);

impl NameWriter {
    pub fn new(family: &str) -> NameWriter {
        NameWriter(family.to_string())
    }

    /// Adds the switch `key` where `on`.
    pub fn switch(&mut self, key: &str, on: bool) -> &mut NameWriter {
        if on {
            self.0.push(':');
            self.0.push_str(key);
        }
        self
    }

    /// Adds `key=value` (numbers as Rust prints them, the shortest text
    /// that reads back to the same value).
    pub fn value(&mut self, key: &str, value: impl Display) -> &mut NameWriter {
        self.0.push_str(&format!(":{key}={value}"));
        self
    }

    /// Adds `key=value` where `value` differs from `default`.
    pub fn changed<T: PartialEq + Display>(
        &mut self,
        key: &str,
        value: T,
        default: T,
    ) -> &mut NameWriter {
        if value != default {
            self.value(key, value);
        }
        self
    }

    pub fn finish(&self) -> String {
        self.0.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_split_into_switches_and_values() {
        let name = MethodName::parse("m:k=6:fast:x=", "m").unwrap();
        let options: Vec<_> = name.options().collect();
        assert_eq!(options.len(), 3);
        assert_eq!(options[0].value, Some("6"));
        assert!(name.has("fast") && !name.has("k"));
        assert_eq!(options[2].value, Some(""));
        assert_eq!(MethodName::parse("m", "m").unwrap().options().count(), 0);
    }

    #[test]
    fn malformed_names_are_refused() {
        for bad in ["mx", "m:", "m::k=2", "other"] {
            let err = MethodName::parse(bad, "m").unwrap_err();
            assert!(matches!(err, Error::InvalidConfig { .. }), "{bad}");
        }
    }

    #[test]
    fn values_read_or_say_what_they_are_not() {
        let name = MethodName::parse("m:k=x", "m").unwrap();
        let option = name.options().next().unwrap();
        let err = name.value::<u32>(option, "x").unwrap_err().to_string();
        assert!(err.contains("k=x") && err.contains("whole number"), "{err}");
        assert_eq!(name.value::<f32>(option, "0.5").unwrap(), 0.5);
    }

    #[test]
    fn typos_name_the_closest_option() {
        let vocabulary = ["queries", "k=N", "filter", "map=N"];
        for (typo, meant) in [
            ("querie", "queries"),
            ("fliter", "filter"),
            ("mpa", "map=N"),
        ] {
            let text = format!("m:{typo}");
            let name = MethodName::parse(&text, "m").unwrap();
            let err = name.unknown(name.options().next().unwrap(), &vocabulary);
            assert!(
                err.to_string().contains(&format!("did you mean {meant}?")),
                "{err}"
            );
        }
        let name = MethodName::parse("m:zzzzzz", "m").unwrap();
        let err = name.unknown(name.options().next().unwrap(), &vocabulary);
        assert!(!err.to_string().contains("did you mean"), "{err}");
    }

    #[test]
    fn written_names_read_back() {
        let mut writer = NameWriter::new("m");
        writer.switch("off", false).switch("on", true);
        writer
            .value("x", 0.1_f32)
            .changed("y", 3, 3)
            .changed("z", 4, 3);
        let text = writer.finish();
        assert_eq!(text, "m:on:x=0.1:z=4");
        let name = MethodName::parse(&text, "m").unwrap();
        let x = name.options().nth(1).unwrap();
        assert_eq!(name.value::<f32>(x, x.value.unwrap()).unwrap(), 0.1);
    }
}
