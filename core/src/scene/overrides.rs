//! `--set KEY=VALUE` overrides: applied to the file's TOML table before the scene is deserialised and
//! validated, so an override is checked exactly as the same value written in the file. The command line's
//! shorthands (`--spp`, `--size`, …) are overrides too. An error names the scene field and the override.

use super::{Scene, SceneError, base_dir, read};
use std::path::Path;

/// One parsed override: the dotted key and the TOML value.
#[derive(Clone)]
struct Setting<'a> {
    /// The override as given.
    text: &'a str,
    /// The dotted key, e.g. `render.photons.k`.
    key: &'a str,
    value: toml::Value,
}

impl<'a> Setting<'a> {
    /// Parses `KEY=VALUE`; `VALUE` is a TOML value (`64`, `"box"`, `true`, `[1.0, 0.0, 0.0]`), and a bare word
    /// is taken as a string.
    fn parse(text: &'a str, path: &Path) -> Result<Self, SceneError> {
        let invalid = |field: &str, message: &str| SceneError::Override {
            path: path.into(),
            field: field.into(),
            setting: text.into(),
            message: message.into(),
        };
        let (key, value) =
            text.split_once('=').ok_or_else(|| invalid(text, "expected KEY=VALUE, e.g. render.spp=64"))?;
        let key = key.trim();
        if key.is_empty() || key.split('.').any(str::is_empty) {
            return Err(invalid(key, "expected a dotted key such as render.photons.k"));
        }
        let value = value.trim();
        let value = toml::from_str::<toml::Table>(&format!("v = {value}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(value.to_string()));
        Ok(Self { text, key, value })
    }

    /// Writes the value into `table`, creating the tables on its path.
    fn apply(&self, table: &mut toml::Table, path: &Path) -> Result<(), SceneError> {
        let keys: Vec<&str> = self.key.split('.').collect();
        let Some((last, parents)) = keys.split_last() else { return Ok(()) };
        let mut t = table;
        for (i, k) in parents.iter().enumerate() {
            let entry = t.entry(k.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
            t = entry.as_table_mut().ok_or_else(|| SceneError::Override {
                path: path.into(),
                field: self.key.into(),
                setting: self.text.into(),
                message: format!("`{}` is not a table", keys[..=i].join(".")),
            })?;
        }
        t.insert(last.to_string(), self.value.clone());
        Ok(())
    }

    /// Whether a validation error of `field` is about this override's value: the same field or one inside it.
    fn covers(&self, field: &str) -> bool {
        field == self.key || field.strip_prefix(self.key).is_some_and(|rest| rest.starts_with(['.', '[']))
    }
}

impl Scene {
    /// Reads a scene file and applies overrides `KEY=VALUE` before validation, where `KEY` is a dotted path
    /// into the file's tables (`render.spp`, `render.photons.kernel`, `camera.width`) and `VALUE` is a TOML
    /// value (`64`, `"box"`, `true`, `[1.0, 0.0, 0.0]`); a bare word is taken as a string. Later overrides of
    /// the same key win.
    ///
    /// # Errors
    /// As [`Scene::load`]; an override that is malformed, of the wrong type or not allowed gives
    /// [`SceneError::Override`], which names the scene field and the override.
    pub fn load_with(path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        if overrides.is_empty() {
            return Self::load(path);
        }
        Self::parse_with(&read(path)?, path, overrides)
    }

    /// [`Scene::load_with`] for scene text already read (or made: a glTF rendered directly); `path` names the
    /// scene in errors and gives the base folder.
    ///
    /// # Errors
    /// As [`Scene::load_with`].
    pub fn parse_with(text: &str, path: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        if overrides.is_empty() {
            return Self::parse(text, path);
        }
        let text = text.to_owned();
        let file: toml::Table =
            toml::from_str(&text).map_err(|e| SceneError::Parse { path: path.into(), message: e.to_string() })?;
        let settings = overrides.iter().map(|o| Setting::parse(o, path)).collect::<Result<Vec<_>, _>>()?;
        let mut scene = match deserialize(&file, &settings, path)? {
            Ok(scene) => scene,
            Err(e) => return Err(blame(&text, &file, &settings, &e, path)?),
        };
        scene.base_dir = base_dir(path);
        // A refused value that an override set is the override's error (the last one of that field wins).
        scene.validate(&text, path).map_err(|e| match e {
            SceneError::Invalid { path, line, field, message } => {
                match settings.iter().rev().find(|s| s.covers(&field)) {
                    Some(s) => SceneError::Override { path, field, setting: s.text.into(), message },
                    None => SceneError::Invalid { path, line, field, message },
                }
            }
            e => e,
        })?;
        Ok(scene)
    }
}

/// The scene of `file` with `settings` applied, or the deserialiser's error.
fn deserialize(
    file: &toml::Table,
    settings: &[Setting<'_>],
    path: &Path,
) -> Result<Result<Scene, toml::de::Error>, SceneError> {
    let mut table = file.clone();
    for s in settings {
        s.apply(&mut table, path)?;
    }
    Ok(toml::Value::Table(table).try_into())
}

/// The error of a scene that does not deserialise with its overrides: the override without which it does
/// (named with its field), else the file's own error (with its line), else the error after the overrides.
fn blame(
    text: &str,
    file: &toml::Table,
    settings: &[Setting<'_>],
    error: &toml::de::Error,
    path: &Path,
) -> Result<SceneError, SceneError> {
    for (i, s) in settings.iter().enumerate().rev() {
        let others: Vec<Setting<'_>> =
            settings.iter().enumerate().filter(|&(j, _)| j != i).map(|(_, o)| o.clone()).collect();
        if deserialize(file, &others, path)?.is_ok() {
            return Ok(SceneError::Override {
                path: path.into(),
                field: s.key.into(),
                setting: s.text.into(),
                message: error.message().to_string(),
            });
        }
    }
    if let Err(own) = toml::from_str::<Scene>(text) {
        return Ok(SceneError::Parse { path: path.into(), message: own.to_string() });
    }
    Ok(SceneError::Parse { path: path.into(), message: format!("after --set: {}", error.message()) })
}
