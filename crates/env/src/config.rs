//! Configuration plumbing shared by every environment: TOML parsing with `section.key=value`
//! overrides and range checks whose errors name the key.
//!
//! The settings themselves live beside what they configure: the arm tasks' shared sections in
//! [`crate::arm::config`], each task's `[task]` and `[reward]` in its module under
//! [`crate::tasks`].

use crate::error::{EnvError, Result};
use serde::de::DeserializeOwned;

pub(crate) fn check_range(key: &str, r: [f32; 2], min: f32, max: f32) -> Result<()> {
    if !(r[0].is_finite() && r[1].is_finite() && r[0] <= r[1] && r[0] >= min && r[1] <= max) {
        return Err(EnvError::config(
            key,
            format!("must be [low, high] with {min} <= low <= high <= {max}, got {r:?}"),
        ));
    }
    Ok(())
}

pub(crate) fn check_at_least_one(key: &str, v: u32) -> Result<()> {
    if v >= 1 {
        Ok(())
    } else {
        Err(EnvError::config(key, "must be at least 1"))
    }
}

pub(crate) fn check_positive(key: &str, v: f32) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(EnvError::config(
            key,
            format!("must be a positive number, got {v}"),
        ))
    }
}

pub(crate) fn check_non_negative(key: &str, v: f32) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(EnvError::config(
            key,
            format!("must be a non-negative number, got {v}"),
        ))
    }
}

/// Parses TOML text into `C` after applying `overrides` (`dotted.key=value`, value in TOML
/// syntax, e.g. `control.action_mode="cartesian"` or `randomization.enabled=true`). Unknown keys
/// are errors that quote the offending line. No range checks: the caller validates.
pub fn parse_toml<C: DeserializeOwned>(text: &str, overrides: &[String]) -> Result<C> {
    let mut table: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| EnvError::config("(file)", e.to_string()))?;
    for item in overrides {
        apply_override(&mut table, item)?;
    }
    from_table(table)
}

/// Lays `top` over `base`: sections merge key by key, any other value in `top` replaces
/// `base`'s (as a later `--set` would).
pub fn overlay(base: &mut toml::Table, top: &toml::Table) {
    for (key, value) in top {
        match (base.get_mut(key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(t)) => overlay(b, t),
            _ => {
                base.insert(key.clone(), value.clone());
            }
        }
    }
}

/// Deserialises a TOML table into `C` (through text, so errors quote the line); the error's key
/// is the dotted path of the value that failed (`camera.mode`), `config` when it has none.
pub fn from_table<C: DeserializeOwned>(table: toml::Table) -> Result<C> {
    let text =
        toml::to_string(&table).map_err(|e| EnvError::config("(overrides)", e.to_string()))?;
    let deserializer =
        toml::Deserializer::parse(&text).map_err(|e| EnvError::config("config", e.to_string()))?;
    serde_path_to_error::deserialize(deserializer).map_err(|e| {
        let key = match e.path().to_string() {
            path if path == "." => "config".to_string(),
            path => path,
        };
        EnvError::config(key, e.into_inner().to_string())
    })
}

/// Reads a TOML file into a table; errors name the file.
pub fn read_table(path: &std::path::Path) -> Result<toml::Table> {
    let file_error = |problem: String| EnvError::File {
        path: path.display().to_string(),
        problem,
    };
    let text = std::fs::read_to_string(path).map_err(|e| file_error(e.to_string()))?;
    text.parse()
        .map_err(|e: toml::de::Error| file_error(format!("not valid TOML: {e}")))
}

/// Sets `section.key=value` in a TOML table (value in TOML syntax; bare words become strings),
/// creating sections as needed. Shared by every configuration that takes `--set` overrides.
pub fn apply_override(table: &mut toml::Table, item: &str) -> Result<()> {
    let (key, value) = item
        .split_once('=')
        .ok_or_else(|| EnvError::config(item, "an override must look like `section.key=value`"))?;
    let key = key.trim();
    let value_text = value.trim();
    // Parse the value as TOML; bare words become strings (`task.action_mode=cartesian`).
    let value: toml::Value = format!("v = {value_text}")
        .parse::<toml::Table>()
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(value_text.to_string()));
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(EnvError::config(key, "empty key segment"));
    }
    let mut current = table;
    for part in &parts[..parts.len() - 1] {
        let entry = current
            .entry(part.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        current = entry
            .as_table_mut()
            .ok_or_else(|| EnvError::config(key, format!("`{part}` is a value, not a section")))?;
    }
    current.insert(parts[parts.len() - 1].to_string(), value);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overlay_merges_sections_and_replaces_values() {
        let mut base: toml::Table = "a = 1\n[s]\nx = [1, 2]\ny = \"keep\"\n[s.t]\nz = 3\n"
            .parse()
            .unwrap();
        let top: toml::Table = "b = 2\n[s]\nx = [5]\n[s.t]\nw = 4\n".parse().unwrap();
        overlay(&mut base, &top);
        let want: toml::Table = "a = 1\nb = 2\n[s]\nx = [5]\ny = \"keep\"\n[s.t]\nz = 3\nw = 4\n"
            .parse()
            .unwrap();
        assert_eq!(base, want);
        // A value replaces a section and a section a value, as a later `--set` would.
        let mut base: toml::Table = "s = 1\n[t]\nu = 1\n".parse().unwrap();
        overlay(&mut base, &"t = 2\n[s]\nv = 3\n".parse().unwrap());
        assert_eq!(base, "t = 2\n[s]\nv = 3\n".parse().unwrap());
    }
}
