//! Arguments `stylize run` and `stylize batch` share (flattened into both), so each option has one
//! name, one help text and one meaning.

use std::path::PathBuf;

use crate::runner::LogMode;

/// Progress output format.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormat {
    /// Progress for people on stderr (a progress bar on a terminal).
    #[default]
    #[value(alias = "bar")]
    Text,
    /// One JSON object per iteration on stdout (the `metrics.jsonl` line).
    Jsonl,
}

/// Options of `run` and `batch`.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct RunSettings {
    /// ONNX model directory for text prompts (see docs/models.md); a batch loads it once.
    #[arg(long, value_name = "DIR")]
    pub model: Option<PathBuf>,
    /// Configuration file (TOML); defaults are the reference's.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Override a config key, e.g. `--set darap.lambda=5` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE", allow_hyphen_values = true)]
    pub set: Vec<String>,
    /// Remesh the input first: `auto` (when its triangles are uneven; see `stylize mesh check`),
    /// `on` (to 1.5 % of the bounding-box diagonal), `off` (keep its triangles exactly), or a
    /// target edge length (`0.03` in the side-2 frame, or `1.5%` of the diagonal). Same as `--set
    /// mesh.remesh=…`; the default is the configuration's (`auto`).
    #[arg(long, value_name = "auto|on|off|LENGTH")]
    pub remesh: Option<stylize::remeshing::RemeshSetting>,
    /// No progress output.
    #[arg(long, short)]
    pub quiet: bool,
    /// Progress format: `text` (a progress bar on a terminal) or `jsonl` (one JSON object per
    /// iteration on stdout).
    #[arg(long, value_enum, value_name = "FORMAT", default_value = "text")]
    pub log_format: LogFormat,
}

impl RunSettings {
    /// `--remesh` on top of `config` (unchanged without it).
    pub fn apply_remesh(&self, mut config: stylize::config::Config) -> stylize::config::Config {
        if let Some(r) = self.remesh {
            config.mesh.remesh = r;
        }
        config
    }

    /// How the runner reports progress.
    pub fn log_mode(&self) -> LogMode {
        match (self.quiet, self.log_format) {
            (true, _) => LogMode::Quiet,
            (false, LogFormat::Text) => LogMode::Bar,
            (false, LogFormat::Jsonl) => LogMode::Jsonl,
        }
    }
}

/// "1 row", "2 rows": `count` and the noun, plural unless the count is 1.
pub fn count_noun(count: usize, singular: &str, plural: &str) -> String {
    if count == 1 {
        format!("1 {singular}")
    } else {
        format!("{count} {plural}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn count_noun_is_singular_only_for_one() {
        assert_eq!(count_noun(0, "row", "rows"), "0 rows");
        assert_eq!(count_noun(1, "row", "rows"), "1 row");
        assert_eq!(count_noun(2, "row", "rows"), "2 rows");
    }

    #[test]
    fn quiet_wins_over_the_log_format() {
        let s = |quiet, log_format| RunSettings {
            quiet,
            log_format,
            ..RunSettings::default()
        };
        assert_eq!(s(true, LogFormat::Jsonl).log_mode(), LogMode::Quiet);
        assert_eq!(s(false, LogFormat::Jsonl).log_mode(), LogMode::Jsonl);
        assert_eq!(s(false, LogFormat::Text).log_mode(), LogMode::Bar);
    }
}
