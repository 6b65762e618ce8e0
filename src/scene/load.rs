//! Reading a TOML scene file: `[defaults]`, `-D` overrides and `"$name"` substitution, then the
//! typed parse.
//!
//! Substitution is textual: every `"$name"` token is replaced by the TOML form of the default's
//! value before the typed parse. Values are single-line, so line numbers in errors still point
//! at the file the user wrote.

use super::SceneError;
use super::desc::SceneDesc;
use std::path::Path;

/// Parses scene text; `path` names the file in errors.
pub(super) fn parse(
    path: &Path,
    source: &str,
    defines: &[(String, String)],
) -> Result<SceneDesc, SceneError> {
    let untyped: toml::Table = toml::from_str(source).map_err(|e| toml_error(path, source, &e))?;
    let mut defaults = match untyped.get("defaults") {
        None => toml::Table::new(),
        Some(toml::Value::Table(t)) => t.clone(),
        Some(_) => {
            return Err(SceneError::invalid(
                path,
                source,
                None,
                "defaults",
                "must be a table of named values",
            ));
        }
    };
    for (key, text) in defines {
        let Some(slot) = defaults.get_mut(key) else {
            let known: Vec<&str> = defaults.keys().map(String::as_str).collect();
            return Err(SceneError::Define {
                key: key.clone(),
                message: if known.is_empty() {
                    format!(
                        "{} has no [defaults] table, so nothing can be overridden",
                        path.display()
                    )
                } else {
                    format!("{} defines only: {}", path.display(), known.join(", "))
                },
            });
        };
        *slot = parse_value(text);
    }
    let substituted = substitute(path, source, &defaults)?;
    toml::from_str(&substituted).map_err(|e| toml_error(path, &substituted, &e))
}

/// A `-D` value: a TOML literal if it is one (numbers, booleans, arrays), else a string.
fn parse_value(text: &str) -> toml::Value {
    toml::from_str::<toml::Table>(&format!("v = {text}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(text.to_string()))
}

fn substitute(path: &Path, source: &str, defaults: &toml::Table) -> Result<String, SceneError> {
    let mut out = String::with_capacity(source.len());
    let mut rest = source;
    while let Some(start) = rest.find("\"$") {
        out.push_str(&rest[..start]);
        let after = &rest[start + 2..];
        let len = after.find(|c: char| !(c.is_alphanumeric() || c == '_')).unwrap_or(after.len());
        if !after[len..].starts_with('"') || len == 0 {
            // Not a whole-string reference: leave it alone.
            out.push_str("\"$");
            rest = after;
            continue;
        }
        let name = &after[..len];
        let Some(value) = defaults.get(name) else {
            let offset = source.len() - rest.len() + start;
            return Err(SceneError::invalid(
                path,
                source,
                Some(offset),
                &format!("\"${name}\""),
                "refers to no entry of [defaults]; add it there or fix the name",
            ));
        };
        out.push_str(&value.to_string());
        rest = &after[len + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

fn toml_error(path: &Path, source: &str, e: &toml::de::Error) -> SceneError {
    let (line, column) = e.span().map_or((0, 0), |s| line_col(source, s.start));
    SceneError::Parse { path: path.to_path_buf(), line, column, message: e.message().to_string() }
}

/// 1-based line and column of a byte offset.
pub(crate) fn line_col(source: &str, offset: usize) -> (usize, usize) {
    let before = &source[..offset.min(source.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
    (line, column)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCENE: &str = r#"
[defaults]
spp = 16
g = 0.5

[camera]
origin = [0, 0, 5]
target = [0, 0, 0]
fov = 40
resolution = [32, 32]

[render]
spp = "$spp"
"#;

    #[test]
    fn defaults_and_overrides() {
        let d = parse(Path::new("s.toml"), SCENE, &[]).unwrap();
        assert_eq!(d.render.spp, 16);
        let d = parse(Path::new("s.toml"), SCENE, &[("spp".into(), "4".into())]).unwrap();
        assert_eq!(d.render.spp, 4);
        let e = parse(Path::new("s.toml"), SCENE, &[("sp".into(), "4".into())]).unwrap_err();
        assert!(e.to_string().contains("defines only: g, spp"), "{e}");
    }

    #[test]
    fn errors_name_file_line_and_key() {
        let bad = SCENE.replace("fov = 40", "fov = 40\nfocus = 3");
        let e = parse(Path::new("s.toml"), &bad, &[]).unwrap_err().to_string();
        assert!(e.starts_with("s.toml:10:") && e.contains("focus"), "{e}");
        let bad = SCENE.replace("\"$spp\"", "\"$spq\"");
        let e = parse(Path::new("s.toml"), &bad, &[]).unwrap_err().to_string();
        assert!(e.starts_with("s.toml:13:") && e.contains("$spq"), "{e}");
        let e = parse(Path::new("s.toml"), "[camera\n", &[]).unwrap_err().to_string();
        assert!(e.starts_with("s.toml:1:"), "{e}");
    }
}
