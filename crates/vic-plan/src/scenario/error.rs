//! Configuration errors: every one names the file, the key (`[task] dt`) and what is wrong, so
//! that a user who wrote a bad file knows which line to fix.

use super::sections::SECTIONS;
use serde_path_to_error::Segment;
use std::path::{Path, PathBuf};

/// A configuration error: which file, which key, what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Syntax { path: PathBuf, message: String },
    #[error("{path}{}: [{section}] {key}: {message}", set_by(set))]
    Invalid {
        path: PathBuf,
        section: String,
        key: String,
        message: String,
        /// The `--set` assignment that wrote this key, when one did: the file is then not at
        /// fault, and the message says so.
        set: Option<String>,
    },
    #[error("--set {assignment}: {message}")]
    Override { assignment: String, message: String },
}

/// ` (--set section.key=value)` after the file's name when an override wrote the faulty key.
fn set_by(set: &Option<String>) -> String {
    set.as_ref()
        .map_or_else(String::new, |a| format!(" (--set {a})"))
}

impl ConfigError {
    /// Names the `--set` assignment among `overrides` that wrote the faulty key, if any (the
    /// last one that did: it is the value that was read).
    pub(super) fn blame_override(self, overrides: &[String]) -> ConfigError {
        match self {
            ConfigError::Invalid {
                path,
                section,
                key,
                message,
                set: None,
            } => {
                let set = overrides
                    .iter()
                    .rev()
                    .find(|a| {
                        a.split_once('=')
                            .and_then(|(k, _)| k.trim().split_once('.'))
                            .is_some_and(|(s, k)| s == section && k == key)
                    })
                    .cloned();
                ConfigError::Invalid {
                    path,
                    section,
                    key,
                    message,
                    set,
                }
            }
            other => other,
        }
    }
}

/// Builds the errors of one file and holds the range checks every section shares.
pub(super) struct FileCheck<'a> {
    pub path: &'a Path,
}

impl FileCheck<'_> {
    /// `[section] key` is wrong: `message` says how.
    pub fn invalid(&self, section: &str, key: &str, message: impl Into<String>) -> ConfigError {
        ConfigError::Invalid {
            path: self.path.to_path_buf(),
            section: section.into(),
            key: key.into(),
            message: message.into(),
            set: None,
        }
    }

    /// A key that only some variants need (`why` says which).
    pub fn required<T>(
        &self,
        value: Option<T>,
        section: &str,
        key: &str,
        why: &str,
    ) -> Result<T, ConfigError> {
        value.ok_or_else(|| self.invalid(section, key, format!("missing, required {why}")))
    }

    pub fn positive(&self, v: f64, section: &str, key: &str) -> Result<f64, ConfigError> {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(self.invalid(section, key, format!("must be a positive number, got {v}")))
        }
    }

    pub(crate) fn non_negative(
        &self,
        v: f64,
        section: &str,
        key: &str,
    ) -> Result<f64, ConfigError> {
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(self.invalid(section, key, format!("must be a number ≥ 0, got {v}")))
        }
    }

    pub fn syntax(&self, message: impl Into<String>) -> ConfigError {
        ConfigError::Syntax {
            path: self.path.to_path_buf(),
            message: message.into(),
        }
    }

    pub(crate) fn missing_section(&self, section: &str) -> ConfigError {
        self.syntax(format!("missing section [{section}]"))
    }

    /// Turns a deserialisation error into one that names the section and the key. Serde reports
    /// unknown and missing keys at the enclosing table, and an unknown variant at the section: the
    /// key is then recovered from the message, or is the section's tag key.
    pub(crate) fn serde_error(
        &self,
        error: serde_path_to_error::Error<toml::de::Error>,
        tag_of: impl Fn(&str) -> Option<&'static str>,
    ) -> ConfigError {
        let mut keys = Vec::new();
        let mut variant = None;
        for segment in error.path() {
            match segment {
                Segment::Map { key } => keys.push(key.clone()),
                Segment::Seq { index } => match keys.last_mut() {
                    Some(k) => k.push_str(&format!("[{index}]")),
                    None => keys.push(format!("[{index}]")),
                },
                Segment::Enum { variant: v } => variant = Some(v.clone()),
                Segment::Unknown => {}
            }
        }
        // toml appends "in `section.key`" on a line of its own: the key is named already.
        let message = error
            .into_inner()
            .to_string()
            .lines()
            .filter(|l| !l.trim().is_empty() && !l.starts_with("in `"))
            .collect::<Vec<_>>()
            .join(" ");
        let Some(section) = keys
            .first()
            .cloned()
            .filter(|s| SECTIONS.contains(&s.as_str()))
        else {
            return self.syntax(match quoted_name(&message, "unknown field `") {
                Some(name) => format!("unknown section [{name}]: {message}"),
                None => message,
            });
        };
        let named = |prefix: &str| quoted_name(&message, prefix);
        let key = if keys.len() > 1 {
            keys[1..].join(".")
        } else if let Some(name) = named("unknown field `") {
            name
        } else if let Some(name) = named("missing field `") {
            let why = match (&variant, tag_of(&section)) {
                (Some(v), Some(tag)) => format!(" for {tag} = \"{v}\""),
                _ => String::new(),
            };
            return self.invalid(&section, &name, format!("missing, required{why}"));
        } else if let Some(tag) = tag_of(&section).filter(|_| message.contains("variant")) {
            tag.to_string()
        } else {
            return self.syntax(format!("[{section}] {message}"));
        };
        self.invalid(&section, &key, message)
    }
}

/// The name between backticks after `prefix` in a serde message (`unknown field `x``).
fn quoted_name(message: &str, prefix: &str) -> Option<String> {
    let rest = &message[message.find(prefix)? + prefix.len()..];
    Some(rest[..rest.find('`')?].to_string())
}
