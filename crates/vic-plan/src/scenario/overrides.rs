//! `--set section.key=value` overrides, applied to the parsed file before it is checked, so that
//! an overridden value is checked like one written in the file.

use super::error::ConfigError;

/// Sets `section.key` in `table` to `value` (a TOML value if it parses as one: numbers, booleans,
/// arrays; else a bare string). Setting the key that selects a section's variant (`noise.kind`,
/// `actuator.type`, ...) to another variant starts that section afresh, so that
/// `--set noise.kind=none` works on a file whose noise has other keys; later overrides fill it.
pub(super) fn apply_override(table: &mut toml::Table, assignment: &str) -> Result<(), ConfigError> {
    let err = |message: &str| ConfigError::Override {
        assignment: assignment.to_string(),
        message: message.to_string(),
    };
    let (key, value) = assignment
        .split_once('=')
        .ok_or_else(|| err("expected section.key=value"))?;
    let (section, field) = key
        .trim()
        .split_once('.')
        .ok_or_else(|| err("expected section.key=value"))?;
    if section.is_empty() || field.is_empty() || field.contains('.') {
        return Err(err("expected section.key=value"));
    }
    let value = value.trim();
    let parsed = format!("v = {value}")
        .parse::<toml::Table>()
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(value.to_string()));
    let entry = table
        .entry(section.to_string())
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    let toml::Value::Table(sec) = entry else {
        return Err(err(&format!("{section} is not a section")));
    };
    if super::sections::tag_of(section) == Some(field) && sec.get(field) != Some(&parsed) {
        sec.clear();
    }
    sec.insert(field.to_string(), parsed);
    Ok(())
}
