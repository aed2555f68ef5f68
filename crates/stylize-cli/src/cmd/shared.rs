//! Arguments `stylize run` and `stylize batch` share (flattened into both), so each option has one
//! name, one help text and one meaning.

use std::path::PathBuf;

use crate::config::Config;
use crate::runner::LogMode;
use stylize::config::CameraPreset;
use stylize::frame::{OutputFrame, UpAxis};

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
    /// The input's up axis (`+y`, `-y`, `+x`, `-x`, `+z`, `-z`; `z` = `+z`): turned to +y before
    /// normalization and back on output (same as `--set mesh.up=…`). CAD files and scans are
    /// often `+z`; `stylize mesh check` hints when a mesh seems to lie on its side.
    #[arg(long, value_name = "AXIS", allow_hyphen_values = true)]
    pub up: Option<UpAxis>,
    /// Frame of the mesh outputs: `input` (the input's own coordinates, axes and scale; the
    /// default) or `normalized` (the reference's side-2 frame). Same as `--set
    /// run.output_frame=…`.
    #[arg(long, value_name = "input|normalized")]
    pub output_frame: Option<OutputFrame>,
    /// The view sampler's ranges by name: `default` (the paper's: elevation 0–60°, distance
    /// 2.5–3.0), `tall` (the paper's for tall, slender shapes: elevation 0–30°, distance
    /// 1.4–2.6) or `auto` (`tall` when the mesh's height is at least 1.5× its larger horizontal
    /// extent; the choice is printed). Same as `--set camera.preset=…`.
    #[arg(long, value_name = "default|tall|auto")]
    pub camera: Option<CameraPreset>,
}

/// The mesh and view flags of `run` and `batch` (and the manifest columns of the same names).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ViewFlags {
    /// `--up`: replaces `mesh.up`.
    pub up: Option<UpAxis>,
    /// `--output-frame`: replaces `run.output_frame`.
    pub output_frame: Option<OutputFrame>,
    /// `--camera`: replaces `camera.preset`.
    pub camera: Option<CameraPreset>,
}

impl RunSettings {
    /// `--up`, `--output-frame` and `--camera`.
    pub fn view_flags(&self) -> ViewFlags {
        ViewFlags {
            up: self.up,
            output_frame: self.output_frame,
            camera: self.camera,
        }
    }
}

/// `--up`, `--output-frame` and `--camera` on top of a resolved configuration.
pub fn with_view_flags(mut config: Config, flags: ViewFlags) -> anyhow::Result<Config> {
    if let Some(u) = flags.up {
        config.mesh.up = u;
    }
    if let Some(f) = flags.output_frame {
        config.run.output_frame = f;
    }
    if let Some(c) = flags.camera {
        config.camera.preset = c;
    }
    config.validate()?;
    Ok(config)
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

/// `--threads N` of the ONNX commands: a count within `1..=`the session's bound
/// (`diffusion_onnx::runtime::max_intra_threads`), refused before any model is loaded.
pub fn thread_count(s: &str) -> Result<usize, String> {
    let n: usize = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a thread count (a positive integer)"))?;
    #[cfg(feature = "text")]
    let n = diffusion_onnx::runtime::check_intra_threads(n)?;
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `embed --threads 100000` crashed inside ONNX Runtime: counts are bounded before any
    /// model loads.
    #[cfg(feature = "text")]
    #[test]
    fn thread_counts_are_bounded_before_any_session() {
        assert_eq!(thread_count("1"), Ok(1));
        for bad in ["0", "100000", "2000", "-1", "many"] {
            assert!(thread_count(bad).is_err(), "{bad}");
        }
        let max = diffusion_onnx::runtime::max_intra_threads();
        assert_eq!(thread_count(&max.to_string()), Ok(max));
    }

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
