//! Batch manifests: many runs in one process (models loaded once), sharded across a job array.
//!
//! A manifest is TOML (`[[run]]` tables) or JSON Lines (one object per line; blank lines and lines
//! starting with `#` are ignored). Row fields:
//!
//! | field | type | meaning |
//! |---|---|---|
//! | `mesh` | path | input mesh (relative paths: from the manifest's folder) |
//! | `out` | path | run directory (relative: from the manifest's folder) |
//! | `prompt` *or* `style` | string | text path (needs `--model`) or model-free style (`exemplar:FILE` relative to the manifest's folder) |
//! | `negative_prompt` | string, optional | overrides `guidance.negative_prompt` |
//! | `seed` | integer, optional | overrides `run.seed` |
//! | `overrides` | list of `"section.key=value"`, optional | applied after the base config (`vertices:FILE` in `region.specs` relative to the manifest's folder) |
//! | `region` | list of region specs, optional | replaces `region.specs` (`vertices:FILE` relative to the manifest's folder) |
//! | `region_feather` | integer, optional | replaces `region.feather` |
//! | `remesh` | string or number, optional | replaces `mesh.remesh` (`auto`, `on`, `off`, `0.03`, `"1.5%"`) |
//! | `up` | string, optional | the mesh's up axis, replaces `mesh.up` (`+z`, `-x`, …) |
//! | `output_frame` | string, optional | `input` or `normalized`, replaces `run.output_frame` |
//! | `camera` | string, optional | `default`, `tall` or `auto`, replaces `camera.preset` |
//!
//! Rows are numbered from 0 in file order; shard `i` of `n` takes the rows with `index % n == i`.
//! At load time, an empty `out` and two rows writing the same run directory (after path
//! normalization: `.`/`..`, trailing slashes, links of existing folders) are errors naming the rows,
//! and so is a run directory inside another row's (`a` and `a/previews`, `a` and `a/b/c`).
//!
//! Each row takes its run directory's lock, then: **skipped** when the directory holds a complete
//! run of the same task (same identity, see [`stylize::identity`]); an **error** when it holds a
//! complete run of a different task (an edited row; `--force` redoes it); **resumed** when it
//! holds a checkpoint of the same task (a checkpoint of a different task is an error, never mixed
//! in); started otherwise. A failing row is reported and the batch goes on; a row locked by another
//! process is left to it ([`RowStatus::InUse`], naming the holder) and the batch goes on.
//! SIGINT/SIGTERM/SIGHUP stops the batch after the current row's checkpoint
//! ([`RowStatus::Interrupted`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use serde::Deserialize;

use crate::config::Config;
use crate::runner::{LogMode, execute_with};
use crate::signals::Interrupted;
use rundir::RunDir;
use stylize::models::ModelSet;
use stylize::runner::{RunOptions, RunRequest};
use stylize::style::Style;
use stylize::task::{ModelIdentity, Prompt, PromptTask};

/// One manifest row.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Row {
    /// Input mesh.
    pub mesh: PathBuf,
    /// Run directory.
    pub out: PathBuf,
    /// Text prompt.
    #[serde(default)]
    pub prompt: Option<String>,
    /// Model-free style.
    #[serde(default)]
    pub style: Option<String>,
    /// Negative prompt.
    #[serde(default)]
    pub negative_prompt: Option<String>,
    /// Seed.
    #[serde(default)]
    pub seed: Option<u64>,
    /// `section.key=value` overrides.
    #[serde(default)]
    pub overrides: Vec<String>,
    /// Region specs (replace `region.specs`).
    #[serde(default)]
    pub region: Vec<String>,
    /// Feather rings (replace `region.feather`).
    #[serde(default)]
    pub region_feather: Option<u32>,
    /// Remeshing (replaces `mesh.remesh`).
    #[serde(default)]
    pub remesh: Option<stylize::remeshing::RemeshSetting>,
    /// The mesh's up axis (replaces `mesh.up`).
    #[serde(default)]
    pub up: Option<String>,
    /// The frame of the mesh outputs (replaces `run.output_frame`).
    #[serde(default)]
    pub output_frame: Option<String>,
    /// The camera preset (replaces `camera.preset`).
    #[serde(default)]
    pub camera: Option<String>,
}

impl Row {
    /// The row's `up`, `output_frame` and `camera` columns, parsed.
    pub fn view_flags(&self) -> anyhow::Result<crate::cmd::shared::ViewFlags> {
        fn parse<T: std::str::FromStr<Err = stylize::Error>>(
            column: &str,
            value: &Option<String>,
        ) -> anyhow::Result<Option<T>> {
            value
                .as_deref()
                .map(str::parse::<T>)
                .transpose()
                .with_context(|| format!("`{column}`"))
        }
        Ok(crate::cmd::shared::ViewFlags {
            up: parse("up", &self.up)?,
            output_frame: parse("output_frame", &self.output_frame)?,
            camera: parse("camera", &self.camera)?,
        })
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TomlManifest {
    run: Vec<Row>,
}

/// A region spec with a relative `vertices:FILE` (also under `not:`) resolved against `base`.
fn rebase_vertex_file(spec: &str, base: &Path) -> anyhow::Result<String> {
    use mesh_core::region::RegionSpec;
    fn rebase(s: RegionSpec, base: &Path) -> RegionSpec {
        match s {
            RegionSpec::VertexFile(p) if p.is_relative() => RegionSpec::VertexFile(base.join(p)),
            RegionSpec::Not(inner) => RegionSpec::Not(Box::new(rebase(*inner, base))),
            other => other,
        }
    }
    Ok(rebase(RegionSpec::parse(spec)?, base).to_string())
}

/// A row's `style` with a relative `exemplar:FILE` resolved against `base` (other styles as they
/// are).
fn rebase_style(style: &str, base: &Path) -> String {
    match style.trim().strip_prefix("exemplar:") {
        Some(file) if Path::new(file).is_relative() => {
            format!("exemplar:{}", base.join(file).display())
        }
        _ => style.to_string(),
    }
}

/// A row's `section.key=value` override with the relative `vertices:FILE` specs of a
/// `region.specs` array resolved against `base` (other overrides as they are; a malformed one is
/// left for the configuration to report).
fn rebase_override(assignment: &str, base: &Path) -> anyhow::Result<String> {
    let Some((key, raw)) = assignment.split_once('=') else {
        return Ok(assignment.to_string());
    };
    if key.trim() != "region.specs" {
        return Ok(assignment.to_string());
    }
    let Ok(doc) = toml::from_str::<toml::Table>(&format!("v = {raw}")) else {
        return Ok(assignment.to_string());
    };
    let Some(toml::Value::Array(specs)) = doc.get("v") else {
        return Ok(assignment.to_string());
    };
    let mut rebased = Vec::with_capacity(specs.len());
    for spec in specs {
        match spec {
            toml::Value::String(s) => {
                rebased.push(toml::Value::String(rebase_vertex_file(s, base)?));
            }
            other => rebased.push(other.clone()),
        }
    }
    Ok(format!("{}={}", key.trim(), toml::Value::Array(rebased)))
}

/// `path` with its symbolic links followed (at most 40, as the kernel does; a link whose target
/// does not exist yet is followed too), for comparing an input with the rows' outputs.
fn follow_links(path: &Path) -> PathBuf {
    let mut p = path.to_path_buf();
    for _ in 0..40 {
        let Ok(target) = std::fs::read_link(&p) else {
            break;
        };
        p = match p.parent() {
            Some(parent) if target.is_relative() => parent.join(target),
            _ => target,
        };
    }
    p
}

/// Reads a manifest; relative paths are resolved against its folder.
pub fn read_manifest(path: &Path) -> anyhow::Result<Vec<Row>> {
    let text = crate::input::read_to_string(path)
        .with_context(|| format!("cannot read manifest {}", path.display()))?;
    let is_toml = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"));
    let mut rows = if is_toml {
        toml::from_str::<TomlManifest>(&text)
            .with_context(|| format!("manifest {} (TOML: [[run]] tables)", path.display()))?
            .run
    } else {
        let mut rows = Vec::new();
        for (i, line) in text.lines().enumerate() {
            // A byte-order mark at a line's start (files concatenated from Windows editors).
            let line = line.trim_start_matches('\u{feff}').trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            rows.push(
                serde_json::from_str::<Row>(line)
                    .with_context(|| format!("manifest {} line {}", path.display(), i + 1))?,
            );
        }
        rows
    };
    let base = path.parent().unwrap_or(Path::new("."));
    // Normalized run directory → (row, `out` as written).
    let mut seen: std::collections::HashMap<PathBuf, (usize, PathBuf)> =
        std::collections::HashMap::new();
    let mut keys = Vec::with_capacity(rows.len());
    for (i, r) in rows.iter_mut().enumerate() {
        if r.prompt.is_some() == r.style.is_some() {
            bail!(
                "manifest {} row {i}: give exactly one of `prompt` or `style`",
                path.display()
            );
        }
        if r.out.to_str().is_some_and(|t| t.trim().is_empty()) {
            bail!(
                "manifest {} row {i}: `out` is empty (every row needs its own run directory)",
                path.display()
            );
        }
        if r.mesh.to_str().is_some_and(|t| t.trim().is_empty()) {
            bail!("manifest {} row {i}: `mesh` is empty", path.display());
        }
        r.view_flags()
            .with_context(|| format!("manifest {} row {i}", path.display()))?;
        let written = r.out.clone();
        if r.mesh.is_relative() {
            r.mesh = base.join(&r.mesh);
        }
        if r.out.is_relative() {
            r.out = base.join(&r.out);
        }
        for spec in &mut r.region {
            *spec = rebase_vertex_file(spec, base)
                .with_context(|| format!("manifest {} row {i}: region", path.display()))?;
        }
        if let Some(style) = &mut r.style {
            *style = rebase_style(style, base);
        }
        for o in &mut r.overrides {
            *o = rebase_override(o, base)
                .with_context(|| format!("manifest {} row {i}: overrides", path.display()))?;
        }
        let key = normalized_dir(&r.out);
        if let Some((j, other)) = seen.get(&key) {
            bail!(
                "manifest {}: rows {j} and {i} both write to the run directory {} (out = {:?} \
                 and {:?}); every row needs its own `out`",
                path.display(),
                key.display(),
                other.display().to_string(),
                written.display().to_string()
            );
        }
        seen.insert(key.clone(), (i, written));
        keys.push(key);
    }
    // A run directory inside another row's: the outer row's `--force` cleanup would meet the
    // inner run (its `previews/`, say), and the outer folder would look foreign to a fresh claim.
    for (i, key) in keys.iter().enumerate() {
        let mut ancestor = key.parent();
        while let Some(a) = ancestor {
            if let Some((j, outer)) = seen.get(a) {
                bail!(
                    "manifest {}: row {i}'s run directory {} lies inside row {j}'s {} (out = {:?} \
                     and {:?}); run directories must not nest — give each row its own folder",
                    path.display(),
                    key.display(),
                    a.display(),
                    seen[key].1.display().to_string(),
                    outer.display().to_string()
                );
            }
            ancestor = a.parent();
        }
    }
    // A row's input must not be another row's output (its mesh.obj, or anything in its previews/),
    // neither as written nor through a link to it (a file link, or links of folders).
    let writer_of = |mesh: &Path| {
        let name = mesh.file_name().and_then(|n| n.to_str())?;
        let parent = normalized_dir(mesh.parent().unwrap_or(Path::new(".")));
        if rundir::RUN_FILES.contains(&name)
            && let Some(w) = seen.get(&parent)
        {
            return Some(w);
        }
        (parent.file_name().is_some_and(|n| n == "previews"))
            .then(|| parent.parent().and_then(|p| seen.get(p)))
            .flatten()
    };
    for (i, r) in rows.iter().enumerate() {
        let writer = writer_of(&r.mesh).or_else(|| writer_of(&follow_links(&r.mesh)));
        if let Some((j, _)) = writer {
            bail!(
                "manifest {}: row {i}'s mesh {} is an output of row {j}; a run never replaces \
                 its inputs — copy the mesh elsewhere",
                path.display(),
                r.mesh.display()
            );
        }
    }
    Ok(rows)
}

/// `path` with `.` removed, `a/..` folded and trailing separators dropped (no file system access).
pub(crate) fn normalize_lexically(path: &Path) -> PathBuf {
    use std::path::Component;
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                let last = out.components().next_back();
                match last {
                    Some(Component::Normal(_)) => {
                        out.pop();
                    }
                    Some(Component::RootDir | Component::Prefix(_)) => {}
                    _ => out.push(".."),
                }
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

/// The run directory a row writes, for comparing rows: absolute, normalized, and with its longest
/// existing ancestor canonicalized (so links of existing folders compare equal).
fn normalized_dir(path: &Path) -> PathBuf {
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir()
            .map(|d| d.join(path))
            .unwrap_or_else(|_| path.to_path_buf())
    };
    let lexical = normalize_lexically(&absolute);
    let mut existing = lexical.clone();
    let mut rest = Vec::new();
    loop {
        if let Ok(c) = std::fs::canonicalize(&existing) {
            let mut out = c;
            for part in rest.iter().rev() {
                out.push(part);
            }
            return out;
        }
        match (
            existing.file_name().map(|n| n.to_os_string()),
            existing.parent(),
        ) {
            (Some(name), Some(parent)) => {
                rest.push(name);
                existing = parent.to_path_buf();
            }
            _ => return lexical,
        }
    }
}

/// A shard: `index` of `count` (0-based).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// This shard (0-based).
    pub index: usize,
    /// Number of shards.
    pub count: usize,
}

impl Shard {
    /// Every row.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Parses `i/n` (0-based `i < n`).
    pub fn parse(s: &str) -> anyhow::Result<Self> {
        let parsed = s
            .split_once('/')
            .and_then(|(i, n)| Some((i.trim().parse().ok()?, n.trim().parse().ok()?)));
        match parsed {
            Some((index, count)) if count > 0 && index < count => Ok(Self { index, count }),
            _ => bail!("invalid shard {s:?}: expected i/n with 0 <= i < n, e.g. 0/4"),
        }
    }

    /// The shard of a batch: `--shard` when given (`explicit`), every row otherwise — except
    /// inside a Slurm job array (`SLURM_ARRAY_TASK_ID` set), where a missing `--shard` is an
    /// error: the array's own variables cannot say how many shards the manifest was split into
    /// (re-submitting `--array=2` of `0-2` gives `SLURM_ARRAY_TASK_COUNT=1`, and shard 0/1 would
    /// be every row), so the count must be written down: `--shard "$SLURM_ARRAY_TASK_ID/16"`.
    pub fn resolve(
        explicit: Option<&str>,
        get: impl Fn(&str) -> Option<String>,
    ) -> anyhow::Result<Self> {
        if let Some(s) = explicit {
            return Self::parse(s);
        }
        if let Some(id) = get("SLURM_ARRAY_TASK_ID") {
            bail!(
                "this is task {} of a Slurm job array, but no --shard was given: pass the shard \
                 count explicitly, e.g. --shard \"$SLURM_ARRAY_TASK_ID/N\" with --array=0-(N-1) \
                 (the array's own variables change when a subset of it is re-submitted; see \
                 docs/cluster.md), or --shard 0/1 for every row",
                id.trim()
            );
        }
        Ok(Self::ALL)
    }

    /// Whether row `i` belongs to this shard.
    pub fn takes(&self, i: usize) -> bool {
        i % self.count == self.index
    }
}

/// What happened to one row.
#[derive(Clone, Debug, PartialEq)]
pub enum RowStatus {
    /// Already complete with the same task; nothing done.
    Skipped,
    /// Ran to completion (`resumed` when it continued from a checkpoint).
    Done {
        /// Continued from a checkpoint.
        resumed: bool,
    },
    /// Failed with this message.
    Failed(String),
    /// Another process holds the row's run directory lock (another task of an overlapping array,
    /// an earlier incarnation of a requeued task): left to it; the message names the holder.
    InUse(String),
    /// Stopped by a signal: its checkpoint is written and the next run of the batch resumes it
    /// (the message says where it stopped). The batch stops after such a row.
    Interrupted(String),
}

impl RowStatus {
    /// A one-word name of the outcome (`done`, `resumed`, `skipped`, `failed`, `in-use`,
    /// `interrupted`), as in the `outcome` field of the batch's JSON row lines.
    pub fn outcome(&self) -> &'static str {
        match self {
            RowStatus::Skipped => "skipped",
            RowStatus::Done { resumed: false } => "done",
            RowStatus::Done { resumed: true } => "resumed",
            RowStatus::Failed(_) => "failed",
            RowStatus::InUse(_) => "in-use",
            RowStatus::Interrupted(_) => "interrupted",
        }
    }

    /// The outcome in words, as in the per-row line (`done (resumed)`, `FAILED: …`).
    pub fn describe(&self) -> String {
        match self {
            RowStatus::Skipped => "skipped (complete)".into(),
            RowStatus::Done { resumed: true } => "done (resumed)".into(),
            RowStatus::Done { resumed: false } => "done".into(),
            RowStatus::Failed(e) => format!("FAILED: {e}"),
            RowStatus::InUse(e) => format!("IN USE elsewhere, left to its holder: {e}"),
            RowStatus::Interrupted(e) => format!("INTERRUPTED, will resume: {e}"),
        }
    }
}

/// Options of a batch.
#[derive(Clone, Debug)]
pub struct BatchOptions {
    /// Base configuration (before each row's overrides).
    pub config: Config,
    /// The shard to run.
    pub shard: Shard,
    /// Model directory for prompt rows.
    pub model: Option<PathBuf>,
    /// Progress reporting of each run.
    pub log: LogMode,
    /// Redo complete rows (and start partial ones over).
    pub force: bool,
    /// Files every row reads besides its mesh (manifest, base config), with their role.
    pub inputs: Vec<(String, PathBuf)>,
}

/// One row's result: its index in the manifest, the row, what happened, and the warnings of the run
/// (mesh repairs, unsupported output formats; empty when the row failed).
pub type RowResult = (usize, Row, RowStatus, Vec<String>);

/// Runs the rows of `manifest` that belong to the shard; returns a [`RowResult`] per row.
/// A row interrupted by a signal is the last one (its status is [`RowStatus::Interrupted`];
/// [`run_batch_until_interrupted`] also returns the interruption).
pub fn run_batch(rows: &[Row], options: &BatchOptions) -> Vec<RowResult> {
    run_batch_until_interrupted(rows, options).0
}

/// [`run_batch`], also returning the interruption that stopped the batch, if any.
pub fn run_batch_until_interrupted(
    rows: &[Row],
    options: &BatchOptions,
) -> (Vec<RowResult>, Option<Interrupted>) {
    run_batch_reporting(rows, options, &mut |_, _| {})
}

/// [`run_batch_until_interrupted`], calling `row_ended` with each row's result and its wall time as
/// soon as the row ends (so a long job's log shows every finished row, and a killed job's log
/// says which rows finished).
pub fn run_batch_reporting(
    rows: &[Row],
    options: &BatchOptions,
    row_ended: &mut dyn FnMut(&RowResult, std::time::Duration),
) -> (Vec<RowResult>, Option<Interrupted>) {
    let mut models: Option<anyhow::Result<ModelSet>> = None;
    let mut out = Vec::new();
    for (i, row) in rows
        .iter()
        .enumerate()
        .filter(|(i, _)| options.shard.takes(*i))
    {
        let started = std::time::Instant::now();
        let (status, warnings, stop) = match run_row(i, row, options, &mut models) {
            Ok((s, warnings)) => (s, warnings, None),
            Err(e) => {
                let stop = e.downcast_ref::<Interrupted>().map(|i| Interrupted {
                    signal: i.signal,
                    dir: i.dir.clone(),
                    checkpoint_iteration: i.checkpoint_iteration,
                });
                let message = format!("{e:#}");
                let status = if stop.is_some() {
                    RowStatus::Interrupted(message)
                } else if crate::signals::exit_code(&e) == crate::signals::EXIT_IN_USE {
                    RowStatus::InUse(message)
                } else {
                    RowStatus::Failed(message)
                };
                (status, Vec::new(), stop)
            }
        };
        out.push((i, row.clone(), status, warnings));
        if let Some(last) = out.last() {
            row_ended(last, started.elapsed());
        }
        if stop.is_some() {
            return (out, stop);
        }
        if let Some(signal) = crate::signals::pending() {
            return (
                out,
                Some(Interrupted {
                    signal,
                    dir: row.out.clone(),
                    checkpoint_iteration: None,
                }),
            );
        }
    }
    (out, None)
}

fn run_row(
    index: usize,
    row: &Row,
    options: &BatchOptions,
    models: &mut Option<anyhow::Result<ModelSet>>,
) -> anyhow::Result<(RowStatus, Vec<String>)> {
    let dir = RunDir::new(&row.out);
    let resumed = !options.force && dir.has_checkpoint() && !dir.is_complete();
    let mut config = options.config.clone().with_overrides(&row.overrides)?;
    if let Some(s) = row.seed {
        config.run.seed = s;
    }
    if let Some(n) = &row.negative_prompt {
        config.guidance.negative_prompt = n.clone();
    }
    if let Some(r) = row.remesh {
        config.mesh.remesh = r;
    }
    let config = config.with_region_flags(&row.region, row.region_feather, false)?;
    let config = crate::cmd::shared::with_view_flags(config, row.view_flags()?)?;
    let request = RunRequest {
        mesh: row.mesh.clone(),
        out: row.out.clone(),
        config: config.clone(),
        force: options.force,
        resume: false,
        halt_after: None,
    };
    let mut run_options = RunOptions {
        resume_if_checkpoint: !options.force,
        skip_complete: !options.force,
        inputs: options.inputs.clone(),
    };
    // Progress lines of a batch name their row.
    let log = options.log.for_row(index);
    let outcome = match (&row.style, &row.prompt) {
        (Some(style), _) => {
            let style = Style::parse(style)?;
            execute_with(&request, log, &style, || Ok(style.clone()), &run_options)?
        }
        (None, Some(prompt)) => {
            if !cfg!(feature = "text") {
                return Err(crate::features::not_built("text", "a prompt row"));
            }
            let Some(model) = &options.model else {
                bail!("prompt rows need --model DIR (docs/models.md)");
            };
            let (g, whole) = (&config.guidance, &options.config.guidance);
            if g.onnx_memory_arena != whole.onnx_memory_arena
                || g.onnx_low_memory != whole.onnx_low_memory
                || g.onnx_io_binding != whole.onnx_io_binding
                || g.stage1_device != whole.stage1_device
                || g.stage2_device != whole.stage2_device
                || g.text_encoder_device != whole.text_encoder_device
                || g.cuda_conv_search != whole.cuda_conv_search
                || g.cuda_arena_growth != whole.cuda_arena_growth
                || g.cuda_memory_limit_gib != whole.cuda_memory_limit_gib
                || g.cuda_tf32 != whole.cuda_tf32
            {
                bail!(
                    "guidance.onnx_memory_arena, guidance.onnx_low_memory, guidance.onnx_io_binding, the \
                     devices (guidance.*_device) and the CUDA options (guidance.cuda_*) cannot be overridden \
                     per row: the batch opens its models once (set them for the whole batch with --set)"
                );
            }
            let kind = Prompt {
                text: prompt.clone(),
                model: Some(ModelIdentity::of_dir(model)?),
            };
            run_options
                .inputs
                .push(("model manifest".into(), model.join("manifest.toml")));
            let config = &config;
            let prompt_kind = &kind;
            execute_with(
                &request,
                log,
                &kind,
                // `move`: the closure takes the `&mut` to the model set, so the guidance it builds
                // may borrow the UNets for the whole run.
                move || {
                    let set = models.get_or_insert_with(|| {
                        let set = ModelSet::open(model, &options.config);
                        if let Ok(s) = &set {
                            if let Some(w) = s.cpu_time_warning(&options.config) {
                                errln!("warning: {w}");
                            }
                            for w in s.memory_warnings() {
                                errln!("warning: {w}");
                            }
                        }
                        set.map_err(anyhow::Error::from)
                    });
                    let set = set.as_mut().map_err(|e| anyhow::anyhow!("{e:#}"))?;
                    let warnings = set.prompt_warnings(prompt, config)?;
                    Ok(PromptTask {
                        prompt: prompt_kind.clone(),
                        guidance: Box::new(set.guidance_for(prompt, config)?),
                        warnings,
                    })
                },
                &run_options,
            )?
        }
        (None, None) => bail!("row has neither prompt nor style"),
    };
    let status = if outcome.already_complete {
        RowStatus::Skipped
    } else {
        RowStatus::Done { resumed }
    };
    Ok((status, outcome.warnings))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_parsing_and_membership() {
        let s = Shard::parse("1/3").unwrap_or(Shard::ALL);
        assert_eq!(s, Shard { index: 1, count: 3 });
        let taken: Vec<usize> = (0..8).filter(|&i| s.takes(i)).collect();
        assert_eq!(taken, vec![1, 4, 7]);
        for bad in ["3/3", "1", "a/2", "0/0", "-1/2"] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_shard_is_explicit_inside_a_job_array() {
        let env = |vars: &'static [(&'static str, &'static str)]| {
            move |k: &str| {
                vars.iter()
                    .find(|(n, _)| *n == k)
                    .map(|(_, v)| v.to_string())
            }
        };
        assert_eq!(Shard::resolve(None, env(&[])).ok(), Some(Shard::ALL));
        // A re-submitted subset (`--array=2` of 0-2): the array says 1 task, the flag says 3.
        let resubmitted: &[(&str, &str)] = &[
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "1"),
            ("SLURM_ARRAY_TASK_MIN", "2"),
        ];
        let e = Shard::resolve(None, env(resubmitted))
            .map(|_| ())
            .expect_err("an error");
        assert!(format!("{e:#}").contains("--shard"), "{e:#}");
        assert_eq!(
            Shard::resolve(Some("2/3"), env(resubmitted)).ok(),
            Some(Shard { index: 2, count: 3 })
        );
        assert!(Shard::resolve(Some("3/3"), env(resubmitted)).is_err());
    }

    #[test]
    fn region_columns_are_read_and_vertex_files_rebased_on_the_manifest_folder() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("m.toml");
        std::fs::write(
            &path,
            "[[run]]\nmesh = \"a.obj\"\nstyle = \"cube\"\nout = \"a\"\nregion = [\"box:-1,-1,-1,0,1,1\", \"not:vertices:head.txt\", \"vertices:/abs/v.txt\"]\nregion_feather = 2\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let rows = read_manifest(&path).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(rows[0].region_feather, Some(2));
        assert_eq!(rows[0].region[0], "box:-1,-1,-1,0,1,1");
        assert_eq!(
            rows[0].region[1],
            format!("not:vertices:{}", dir.path().join("head.txt").display())
        );
        assert_eq!(rows[0].region[2], "vertices:/abs/v.txt");
        std::fs::write(
            &path,
            "[[run]]\nmesh = \"a.obj\"\nstyle = \"cube\"\nout = \"a\"\nregion = [\"cube:1\"]\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let e = read_manifest(&path).map(|_| ()).expect_err("an error");
        assert!(
            format!("{e:#}").contains("row 0") && format!("{e:#}").contains("cube:1"),
            "{e:#}"
        );
        let config = Config::default()
            .with_region_flags(&rows[0].region[..1], rows[0].region_feather, false)
            .unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(config.region.specs, ["box:-1,-1,-1,0,1,1"]);
        assert_eq!(config.region.feather, 2);
        let e = Config::default().with_region_flags(&["box:1".to_string()], None, false);
        assert!(format!("{:#}", e.expect_err("an error")).contains("region.specs"));
    }

    #[test]
    fn the_remesh_column_takes_settings_and_lengths_and_refuses_others() {
        use stylize::remeshing::{EdgeLength, RemeshSetting};
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let jsonl = dir.path().join("m.jsonl");
        std::fs::write(
            &jsonl,
            "{\"mesh\": \"a.obj\", \"style\": \"cube\", \"out\": \"a\", \"remesh\": \"off\"}\n\
             {\"mesh\": \"a.obj\", \"style\": \"cube\", \"out\": \"b\", \"remesh\": 0.03}\n\
             {\"mesh\": \"a.obj\", \"style\": \"cube\", \"out\": \"c\", \"remesh\": \"2%\"}\n\
             {\"mesh\": \"a.obj\", \"style\": \"cube\", \"out\": \"d\"}\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let rows = read_manifest(&jsonl).unwrap_or_else(|e| panic!("{e:#}"));
        let got: Vec<Option<RemeshSetting>> = rows.iter().map(|r| r.remesh).collect();
        assert_eq!(
            got,
            [
                Some(RemeshSetting::Off),
                Some(RemeshSetting::EdgeLength(EdgeLength::Absolute(0.03))),
                Some(RemeshSetting::EdgeLength(EdgeLength::PercentOfDiagonal(
                    2.0
                ))),
                None
            ]
        );
        std::fs::write(
            &jsonl,
            "{\"mesh\": \"a.obj\", \"style\": \"cube\", \"out\": \"a\", \"remesh\": \"maybe\"}\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let e = read_manifest(&jsonl)
            .err()
            .map(|e| format!("{e:#}"))
            .unwrap_or_default();
        assert!(e.contains("line 1") && e.contains("auto"), "{e}");
    }

    #[test]
    fn manifests_in_toml_and_jsonl_resolve_relative_paths() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let toml_path = dir.path().join("m.toml");
        std::fs::write(
            &toml_path,
            "[[run]]\nmesh = \"a.obj\"\nstyle = \"cube\"\nout = \"runs/a\"\nseed = 3\noverrides = [\"darap.lambda=5\"]\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let rows = read_manifest(&toml_path).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].mesh, dir.path().join("a.obj"));
        assert_eq!(rows[0].seed, Some(3));
        let jsonl = dir.path().join("m.jsonl");
        std::fs::write(
            &jsonl,
            "# comment\n{\"mesh\": \"/abs/b.obj\", \"prompt\": \"a cat\", \"out\": \"b\"}\n\n{\"mesh\": \"c.obj\", \"style\": \"octahedron\", \"out\": \"c\"}\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let rows = read_manifest(&jsonl).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].mesh, PathBuf::from("/abs/b.obj"));
        assert_eq!(rows[1].out, dir.path().join("c"));
        std::fs::write(&jsonl, "{\"mesh\": \"c.obj\", \"out\": \"c\"}\n")
            .unwrap_or_else(|e| panic!("{e}"));
        let e = read_manifest(&jsonl)
            .err()
            .map(|e| format!("{e:#}"))
            .unwrap_or_default();
        assert!(e.contains("exactly one of"), "{e}");
        std::fs::write(
            &jsonl,
            "{\"mesh\": \"c.obj\", \"out\": \"c\", \"styel\": \"cube\"}\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let e = read_manifest(&jsonl)
            .err()
            .map(|e| format!("{e:#}"))
            .unwrap_or_default();
        assert!(e.contains("line 1") && e.contains("styel"), "{e}");
    }

    /// Every file a row names is found from the manifest's folder, wherever the batch starts:
    /// an exemplar (`style = "exemplar:…"`) and the `vertices:` specs of a `region.specs`
    /// override used to be resolved against the current directory.
    #[test]
    fn rows_resolve_every_file_against_the_manifest_folder_bom_or_not() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let jsonl = dir.path().join("m.jsonl");
        std::fs::write(
            &jsonl,
            "\u{feff}{\"mesh\": \"a.obj\", \"out\": \"a\", \"style\": \"exemplar:shapes/e.obj\", \"overrides\": [\"region.specs=[\\\"vertices:v.txt\\\", \\\"not:vertices:/abs/w.txt\\\", \\\"box:0,0,0,1,1,1\\\"]\", \"darap.lambda=5\"]}\r\n\u{feff}{\"mesh\": \"b.obj\", \"out\": \"b\", \"style\": \"exemplar:/abs/e.obj\"}\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let rows = read_manifest(&jsonl).unwrap_or_else(|e| panic!("{e:#}"));
        let d = dir.path().display();
        assert_eq!(
            rows[0].style.as_deref(),
            Some(format!("exemplar:{d}/shapes/e.obj").as_str())
        );
        assert_eq!(rows[1].style.as_deref(), Some("exemplar:/abs/e.obj"));
        assert_eq!(
            rows[0].overrides,
            [
                format!(
                    "region.specs=[\"vertices:{d}/v.txt\", \"not:vertices:/abs/w.txt\", \
                     \"box:0,0,0,1,1,1\"]"
                ),
                "darap.lambda=5".to_string()
            ]
        );
        // The rebased override still applies.
        let config = Config::default()
            .with_overrides(&rows[0].overrides)
            .unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(config.region.specs[0], format!("vertices:{d}/v.txt"));
    }

    /// A row whose mesh is a file link to another row's output (existing or not yet) is refused
    /// like the folder-link and the plain forms.
    #[test]
    fn a_mesh_linking_to_another_rows_output_is_refused() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        std::os::unix::fs::symlink(
            dir.path().join("runs/a/mesh.obj"),
            dir.path().join("in.obj"),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        std::os::unix::fs::symlink("in.obj", dir.path().join("in2.obj"))
            .unwrap_or_else(|e| panic!("{e}"));
        for mesh in ["in.obj", "in2.obj"] {
            let path = dir.path().join("m.toml");
            std::fs::write(
                &path,
                format!(
                    "[[run]]\nmesh = \"x.obj\"\nstyle = \"cube\"\nout = \"runs/a\"\n\n[[run]]\nmesh = \"{mesh}\"\nstyle = \"cube\"\nout = \"runs/b\"\n"
                ),
            )
            .unwrap_or_else(|e| panic!("{e}"));
            let e = read_manifest(&path).map(|_| ()).expect_err("refused");
            assert!(
                format!("{e:#}").contains("row 1's mesh")
                    && format!("{e:#}").contains("output of row 0"),
                "{mesh}: {e:#}"
            );
        }
    }
}
