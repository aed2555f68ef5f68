//! Config files: TOML (the format `stylize::config` defines) or, by extension `.json`, the
//! reference implementation's JSON layout ([`crate::reference_config`]). The settings themselves
//! (sections, defaults, validation, overrides) are the library's, re-exported here.

use std::path::Path;

use anyhow::Context;

pub use stylize::config::*;

/// Reads a TOML file, or (extension `.json`) the reference implementation's JSON layout (see
/// [`crate::reference_config`]; its notes about ignored keys are printed to stderr).
pub fn load(path: &Path) -> anyhow::Result<Config> {
    let text = crate::input::read_to_string(path)
        .with_context(|| format!("cannot read config {}", path.display()))?;
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
    {
        let (config, notes) = crate::reference_config::from_reference_json(&text)
            .with_context(|| format!("in reference config {}", path.display()))?;
        for n in notes {
            errln!("note: {}: {n}", path.display());
        }
        return Ok(config);
    }
    Config::from_toml_str(&text).with_context(|| format!("in config {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok<T>(r: anyhow::Result<T>) -> T {
        r.unwrap_or_else(|e| panic!("{e:#}"))
    }

    #[test]
    fn reference_fixture_equals_builtin_defaults() {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/configs/reference.toml");
        assert_eq!(ok(load(&path)), Config::default());
    }

    #[test]
    fn shipped_fixture_configs_parse() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/configs");
        let mut n = 0;
        for entry in ok(std::fs::read_dir(&dir).context("fixtures/configs")) {
            let path = ok(entry.context("dir entry")).path();
            if path.extension().is_some_and(|e| e == "toml") {
                ok(load(&path));
                n += 1;
            }
        }
        assert!(n >= 1, "no configs in {}", dir.display());
    }
}
