//! `stylize apply`: re-apply a saved deformation (spec §8) at one or several strengths λ.
//!
//! After each output, one line of λ sanity ([`crate::sanity`]: volume ratio, face-area ratio,
//! share of vertices whose rotation flipped past 90°, self-intersecting pairs and faces and those
//! new against the source), and a warning on stderr when the result is collapsing or has new
//! self-intersections.
//!
//! **`--lambda max-safe[:UPPER]`** writes the result at the strongest safe λ in `(0, UPPER]`
//! (default UPPER: the saved λ), searched by [`crate::max_safe`] (a scan, then bisection of the
//! first crossing to 1 %; it says when safety is not monotone over the scan).
//!
//! **`--strength S[,S…]`** (each S ≥ 1) writes the result at λ (the saved one, or one `--lambda`
//! value) pushed S times as far by the strength control ([`darap::Darap::forward_at_strength`]:
//! the `procrustes` rule's increment from λ to S·λ on top of the result at λ; S = 1 is that
//! result exactly). Measured against re-applying the reference rule at S·λ in `docs/strength.md`:
//! it keeps the volume and does not flip rotations where the larger λ collapses the mesh.
//! `--strength max-safe[:UPPER]` (UPPER > 1, default 3) searches the strongest safe S in
//! `[1, UPPER]` as `--lambda max-safe` searches λ. Several strengths write `OUT_strength<S>.ext`.
//!
//! Reads the saved `.npz`, builds its dARAP layer ([`SavedDeformation::ready_layer`]: `verts`
//! normalized to the side-2 cube in f64) with the requested λ (default: the saved
//! `local_step_procrustes.lamb`), runs local step → global step → `recenter_rescale`, and writes
//! the deformed mesh with area-weighted vertex normals.
//!
//! **Frame** (`--output-frame`): by default the input's own coordinates, axes and scale, through
//! the file's `to_input_frame` (a run of ours records it; the result is placed as the run places
//! its `mesh.*`, see `stylize::frame`); `normalized` writes the reference's side-2 frame. A file
//! without `to_input_frame` (the reference's, or one written before output frames existed) is
//! written in the normalized frame with a note; `--output-frame input` on it is an error.
//!
//! **Mask file** (`--mask FILE`): plain text, one vertex index per line (0-based, the saved file's
//! vertex order) of the vertices that **may rotate**; every other vertex keeps `R = I`. Blank
//! lines and lines starting with `#` are ignored; a file that lists no vertex is an error.
//!
//! **Region.** A saved localized run (`region_weights` in the `.npz`) is re-applied with its
//! region by default. `--mask FILE` or `--region SPEC` (repeatable; boxes and spheres in the
//! normalized frame, `vertices:FILE` in the saved file's vertex order, `not:`) replace it, with
//! `--region-feather K` rings; `--no-region` applies to the whole mesh.
//!
//! **Several λ** (`--lambda 5,8,11`) write one file per λ next to `-o OUT.ext`:
//! `OUT_lambda5.ext`, `OUT_lambda8.ext`, … . Parent folders are created; existing outputs are
//! refused unless `--force` (all outputs are checked before any is written). An output that is
//! one of the inputs (the saved file, the mask — compared by file identity) is refused always,
//! `--force` included. Each output is written atomically and durably (`rundir::durable`).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail, ensure};
use darap::RotationRule;
use mesh_core::TriMesh;
use mesh_core::io::Format;
use stylize::frame::{InputFrame, OutputFrame};
use stylize::intersections::SourceIntersections;
use stylize::saved::{ReadyLayer, Region, SavedDeformation, SavedError};

/// Arguments of `stylize apply`.
#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Saved deformation (`.npz` in the reference's format).
    pub saved: PathBuf,
    /// Output mesh (`.obj`, `.ply` or `.glb`). With several λ: one file per λ, `OUT_lambda<λ>.ext`.
    #[arg(short, long = "out", alias = "output", value_name = "FILE")]
    pub output: PathBuf,
    /// Strength(s) λ in [0, 1000], comma separated (default: the λ saved in the file); or
    /// `max-safe[:UPPER]`: the strongest λ in (0, UPPER] whose result is safe (no new
    /// self-intersections, flips, collapse), UPPER defaulting to the saved λ.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true, value_parser = parse_lambda)]
    pub lambda: Vec<LambdaArg>,
    /// Strength(s) S ≥ 1, comma separated: the result at λ (the saved one, or one `--lambda`
    /// value) pushed S times as far by the strength control (docs/strength.md; S = 1 is that
    /// result exactly); or `max-safe[:UPPER]`: the strongest safe S in [1, UPPER] (default 3).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true, value_parser = parse_lambda)]
    pub strength: Vec<LambdaArg>,
    /// Rotation rule: `gis` (the reference's; what saved files and the paper's λ values assume) or
    /// `procrustes` (textbook Kabsch, needs a larger λ). Default: the file's `rotation_rule` key
    /// if present, else `gis`.
    #[arg(long, value_name = "gis|procrustes")]
    pub rotation_rule: Option<RotationRule>,
    /// Text file of vertex indices that may rotate, one per line (all others keep R = I).
    #[arg(long, conflicts_with = "region")]
    pub mask: Option<PathBuf>,
    /// Region specs (repeatable, union; see `stylize run --region`), instead of the saved region.
    #[arg(long, value_name = "SPEC")]
    pub region: Vec<String>,
    /// Feather rings for `--region` / `--mask` (default: the saved run's, else 0).
    #[arg(long, value_name = "K")]
    pub region_feather: Option<u32>,
    /// Ignore the saved region: every vertex may rotate.
    #[arg(long, conflicts_with_all = ["mask", "region"])]
    pub no_region: bool,
    /// The frame of the written mesh: `input` (the run's input file's coordinates, through the
    /// saved `to_input_frame`; the default when the file records it) or `normalized` (the
    /// reference's side-2 frame; the default for files without it).
    #[arg(long, value_name = "input|normalized")]
    pub output_frame: Option<OutputFrame>,
    /// Overwrite existing output files.
    #[arg(long)]
    pub force: bool,
}

/// The map to apply to results: `Some(frame)` for the input frame, `None` for the normalized one.
fn output_map(args: &Args, saved: &SavedDeformation) -> anyhow::Result<Option<InputFrame>> {
    let recorded = saved
        .input_frame()
        .with_context(|| format!("{}", args.saved.display()))?;
    Ok(match (args.output_frame, recorded) {
        (Some(OutputFrame::Normalized), _) => None,
        (_, Some(frame)) => Some(frame),
        (Some(OutputFrame::Input), None) => bail!(
            "--output-frame input: {} does not record its input's frame (`to_input_frame`: a \
             file from the reference, or from a run before output frames existed); use \
             --output-frame normalized",
            args.saved.display()
        ),
        (None, None) => {
            errln!(
                "note: {} does not record its input's frame (`to_input_frame`); writing the \
                 normalized side-2 frame",
                args.saved.display()
            );
            None
        }
    })
}

/// One `--lambda` value.
#[derive(Clone, Debug, PartialEq)]
pub enum LambdaArg {
    /// A strength.
    Value(f64),
    /// `max-safe[:UPPER]`: search the strongest safe λ up to UPPER (None: the saved λ).
    MaxSafe(Option<f64>),
}

/// Parses `8`, `max-safe` or `max-safe:12` (the ranges are checked by [`run`]).
pub fn parse_lambda(s: &str) -> Result<LambdaArg, String> {
    let s = s.trim();
    if let Some(rest) = s.strip_prefix("max-safe") {
        if rest.is_empty() {
            return Ok(LambdaArg::MaxSafe(None));
        }
        let Some(upper) = rest.strip_prefix(':') else {
            return Err(format!("`{s}`: write max-safe or max-safe:UPPER"));
        };
        let upper: f64 = upper
            .parse()
            .map_err(|_| format!("`{s}`: the upper end `{upper}` is not a number"))?;
        return Ok(LambdaArg::MaxSafe(Some(upper)));
    }
    s.parse()
        .map(LambdaArg::Value)
        .map_err(|_| format!("`{s}` is neither a number nor max-safe[:UPPER]"))
}

/// The largest UPPER `max-safe` accepts (the viewer's slider stops at 100).
pub const MAX_SAFE_UPPER_LIMIT: f64 = 1000.0;

/// The largest strength `--strength` accepts (the study of docs/strength.md goes to 3).
pub const MAX_STRENGTH: f64 = 100.0;

/// `--strength max-safe`'s UPPER when none is given.
pub const DEFAULT_STRENGTH_UPPER: f64 = 3.0;

/// What one output is: the result at a λ, or the strength control's result at a strength.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Setting {
    Lambda(f64),
    Strength { lambda: f64, strength: f64 },
}

impl Setting {
    fn label(&self) -> String {
        match self {
            Setting::Lambda(l) => format!("λ = {l}"),
            Setting::Strength { lambda, strength } => format!("strength {strength} (λ = {lambda})"),
        }
    }

    fn deform(&self, ready: &mut ReadyLayer) -> anyhow::Result<darap::Deformation> {
        match *self {
            Setting::Lambda(l) => ready.at_lambda(l),
            Setting::Strength { lambda, strength } => ready.at_strength(lambda, strength),
        }
        .with_context(|| format!("dARAP forward failed at {}", self.label()))
    }

    fn assess(
        &self,
        ready: &mut ReadyLayer,
        source: &mut SourceIntersections,
    ) -> anyhow::Result<(darap::Deformation, crate::sanity::LambdaSanity)> {
        let d = self.deform(ready)?;
        let (lambda, strength) = match *self {
            Setting::Lambda(l) => (l, None),
            Setting::Strength { lambda, strength } => (lambda, Some(strength)),
        };
        let mut s = crate::sanity::LambdaSanity::assess(&ready.rest, source, &d, lambda)?;
        if let Some(strength) = strength {
            s = s.with_strength(strength);
        }
        Ok((d, s))
    }
}

/// The output path for each λ (the path itself when there is one λ): a format written with
/// normals ([`Format::WITH_NORMALS`]); with several λ the extension is written in lower case.
pub fn output_paths(output: &Path, lambdas: &[f64]) -> anyhow::Result<Vec<PathBuf>> {
    output_paths_named(output, lambdas, "lambda")
}

/// [`output_paths`] with `OUT_<name><value>.ext` for several values.
fn output_paths_named(output: &Path, lambdas: &[f64], name: &str) -> anyhow::Result<Vec<PathBuf>> {
    let format = Format::from_path(output).filter(|f| Format::WITH_NORMALS.contains(f));
    let Some(format) = format else {
        bail!(
            "output {} must end in {}",
            output.display(),
            Format::list(&Format::WITH_NORMALS, ".", " or ")
        );
    };
    let ext = format.extension();
    if lambdas.len() == 1 {
        return Ok(vec![output.to_path_buf()]);
    }
    let stem = output
        .file_stem()
        .and_then(|s| s.to_str())
        .with_context(|| format!("output {} has no usable file name", output.display()))?;
    Ok(lambdas
        .iter()
        .map(|l| output.with_file_name(format!("{stem}_{name}{l}.{ext}")))
        .collect())
}

/// Parses a mask file: one 0-based vertex index per line (`#` comments and blank lines ignored);
/// returns `free[v]` (true for listed vertices). A file that lists no vertex is an error, as a
/// `--region` that selects none.
pub fn read_mask(path: &Path, num_vertices: usize) -> anyhow::Result<Vec<bool>> {
    let text = crate::input::read_to_string(path)
        .with_context(|| format!("cannot read mask file {}", path.display()))?;
    let mut free = vec![false; num_vertices];
    for (lineno, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let v: usize = line.parse().with_context(|| {
            format!(
                "mask file {} line {}: `{line}` is not a vertex index",
                path.display(),
                lineno + 1
            )
        })?;
        ensure!(
            v < num_vertices,
            "mask file {} line {}: vertex {v} is out of range (the mesh has {num_vertices} vertices)",
            path.display(),
            lineno + 1
        );
        free[v] = true;
    }
    ensure!(
        free.contains(&true),
        "mask file {} lists no vertex: a localized apply would change nothing (one 0-based vertex \
         index per line; --no-region applies to the whole mesh)",
        path.display()
    );
    Ok(free)
}

/// The region to apply: `--mask` / `--region` (feathered by `--region-feather`, else the saved
/// rings), else the saved `region_weights`, else none (also with `--no-region`). `rest` is the
/// saved rest mesh in the side-2 cube frame (where `--region` boxes and spheres live).
fn region(args: &Args, saved: &SavedDeformation, rest: &[[f64; 3]]) -> anyhow::Result<Region> {
    if args.no_region {
        return Ok(Region::Whole);
    }
    let free = if let Some(mask_path) = &args.mask {
        read_mask(mask_path, rest.len())?
    } else if !args.region.is_empty() {
        let specs = stylize::runner::parse_region_specs(&args.region)?;
        let parts = mesh_core::region::Parts::default();
        let input = mesh_core::region::RegionInput::unrepaired(rest, &saved.faces, &parts);
        let region = mesh_core::region::select(&specs, &input)
            .context("--region (a saved file has no named parts: use box, sphere, vertices)")?;
        for w in &region.warnings {
            errln!("warning: {w}");
        }
        region.free
    } else {
        return Ok(Region::Saved);
    };
    Ok(Region::Free {
        free,
        feather: args.region_feather,
    })
}

/// Runs `stylize apply`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let saved = SavedDeformation::read(&args.saved)
        .with_context(|| format!("cannot read saved deformation {}", args.saved.display()))?;
    if !saved.normalize_target_normals() {
        return Err(SavedError::NotNormalized {
            path: args.saved.clone(),
        }
        .into());
    }
    if let Some(kind) = saved.arap_energy_type()
        && kind != "spokes_and_rims_mine"
    {
        errln!(
            "warning: saved arap_energy_type is {kind:?}; applying with \"spokes_and_rims_mine\""
        );
    }
    if !saved.pin_first_vertex() {
        errln!(
            "warning: saved pin_first_vertex is false; applying with the first vertex (of each component) pinned"
        );
    }

    let recorded = || {
        saved
            .recorded_lambda()
            .map_err(|why| anyhow::anyhow!("{}: {why}; pass --lambda", args.saved.display()))
    };
    let mut max_safe_upper = None;
    let mut lambdas = Vec::new();
    for a in &args.lambda {
        match a {
            LambdaArg::Value(l) => lambdas.push(*l),
            LambdaArg::MaxSafe(upper) => {
                ensure!(
                    args.lambda.len() == 1,
                    "--lambda max-safe stands alone (not with other λ values)"
                );
                let upper = match upper {
                    Some(u) => *u,
                    None => recorded()?,
                };
                ensure!(
                    upper.is_finite() && upper > 0.0 && upper <= MAX_SAFE_UPPER_LIMIT,
                    "--lambda max-safe:{upper}: the upper end must be a number in (0, {MAX_SAFE_UPPER_LIMIT}]"
                );
                max_safe_upper = Some(upper);
                lambdas.push(upper);
            }
        }
    }
    if lambdas.is_empty() {
        lambdas.push(recorded()?);
    }
    for &l in &lambdas {
        let max = stylize::config::MAX_LAMBDA;
        ensure!(
            l.is_finite() && (0.0..=max).contains(&l),
            "--lambda {l}: the strength λ must be a finite number ≥ 0 and at most {max} (the \
             reference uses 5–10)"
        );
    }
    let mut strength_upper = None;
    let mut strengths = Vec::new();
    if !args.strength.is_empty() {
        ensure!(
            max_safe_upper.is_none() && lambdas.len() == 1,
            "--strength pushes the result at one λ further (the saved λ, or one --lambda value), \
             not at several λ or at --lambda max-safe"
        );
        for a in &args.strength {
            match a {
                LambdaArg::Value(s) => strengths.push(*s),
                LambdaArg::MaxSafe(upper) => {
                    ensure!(
                        args.strength.len() == 1,
                        "--strength max-safe stands alone (not with other strengths)"
                    );
                    let upper = upper.unwrap_or(DEFAULT_STRENGTH_UPPER);
                    ensure!(
                        upper.is_finite() && upper > 1.0 && upper <= MAX_STRENGTH,
                        "--strength max-safe:{upper}: the upper end must be a number in (1, {MAX_STRENGTH}]"
                    );
                    strength_upper = Some(upper);
                    strengths.push(upper);
                }
            }
        }
        for &s in &strengths {
            ensure!(
                s.is_finite() && (1.0..=MAX_STRENGTH).contains(&s),
                "--strength {s}: a strength must be a number in [1, {MAX_STRENGTH}] (1: the result \
                 at λ itself; for a weaker result, a smaller --lambda)"
            );
        }
    }
    let mut settings: Vec<Setting> = if strengths.is_empty() {
        lambdas.iter().map(|&l| Setting::Lambda(l)).collect()
    } else {
        strengths
            .iter()
            .map(|&strength| Setting::Strength {
                lambda: lambdas[0],
                strength,
            })
            .collect()
    };
    let rule = match args.rotation_rule {
        Some(r) => r,
        None => saved.rotation_rule()?.unwrap_or_default(),
    };

    let (values, name) = if strengths.is_empty() {
        (&lambdas, "lambda")
    } else {
        (&strengths, "strength")
    };
    let mut outputs = output_paths_named(&args.output, values, name)?;
    // Several values: the labelled comparison sheet too (cmd::apply_grid), checked like the meshes.
    let grid = if values.len() > 1 {
        let path = super::apply_grid::grid_path(&args.output)?;
        outputs.push(path.clone());
        Some(path)
    } else {
        None
    };
    let mut inputs = vec![("saved deformation".to_string(), args.saved.clone())];
    if let Some(m) = &args.mask {
        inputs.push(("mask file".into(), m.clone()));
    }
    for spec in &args.region {
        for file in mesh_core::region::RegionSpec::parse(spec)?.files() {
            inputs.push(("region vertex file".into(), file));
        }
    }
    rundir::refuse_overwriting_inputs(&outputs, &[], &inputs)?;
    for (i, a) in outputs.iter().enumerate() {
        if outputs[..i].contains(a) {
            bail!(
                "two outputs are the same file {} (a repeated --{} value)",
                a.display(),
                if strengths.is_empty() {
                    "lambda"
                } else {
                    "strength"
                }
            );
        }
    }
    if !args.force {
        let existing: Vec<String> = outputs
            .iter()
            .filter(|p| p.exists())
            .map(|p| p.display().to_string())
            .collect();
        ensure!(
            existing.is_empty(),
            "refusing to overwrite {} (pass --force)",
            existing.join(", ")
        );
    }

    let to_input = output_map(&args, &saved)?;
    let mut ready = saved.ready_layer(&args.saved, lambdas[0], Some(rule))?;
    let region = region(&args, &saved, &ready.rest.positions)?;
    ready.set_region(&saved, &args.saved, region)?;
    let mut source = stylize::intersections::SourceIntersections::new(&ready.rest)
        .context("self-intersection check of the saved rest mesh")?;
    // A closed stdout (`… | head -1`) does not stop the writing: every output is written, then the
    // command fails with the first write error (exit 141 for a broken pipe).
    let mut closed: Option<crate::output::OutputClosed> = None;
    if let Some(upper) = max_safe_upper {
        let (lambda, lines) = max_safe(&mut ready, &mut source, upper)?;
        for line in lines {
            if closed.is_none() {
                closed = outln!("{line}").err();
            }
        }
        settings = vec![Setting::Lambda(lambda)];
    }
    if let Some(upper) = strength_upper {
        let (strength, lines) = max_safe_strength(&mut ready, &mut source, lambdas[0], upper)?;
        for line in lines {
            if closed.is_none() {
                closed = outln!("{line}").err();
            }
        }
        settings = vec![Setting::Strength {
            lambda: lambdas[0],
            strength,
        }];
    }

    let mut columns = Vec::new();
    for (setting, out) in settings.iter().zip(&outputs) {
        let (deformed, sanity) = setting.assess(&mut ready, &mut source)?;
        if grid.is_some() {
            // The sheet's tiles are rendered in the side-2 frame, whatever frame the files use.
            let label = match setting {
                Setting::Lambda(l) => super::apply_grid::label_text(*l),
                Setting::Strength { strength, .. } => format!("s={strength}"),
            };
            columns.push((
                label,
                super::apply_grid::tiles(&deformed.positions, &saved.faces)?,
            ));
        }
        // `ready_layer` post-processes with `recenter_rescale`: the result is recentred.
        let positions = match &to_input {
            Some(frame) => frame.place_result(&deformed.positions, &ready.rest.positions, true),
            None => deformed.positions,
        };
        let mesh = TriMesh::new(positions, saved.faces.clone());
        let normals =
            mesh_core::normals::vertex_normals_area_weighted(&mesh.positions, &mesh.faces);
        if let Some(parent) = out.parent()
            && !parent.as_os_str().is_empty()
        {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("cannot create {}", parent.display()))?;
        }
        rundir::durable::replace_with(out, |tmp| {
            mesh_core::io::write_mesh(tmp, &mesh, Some(&normals)).map_err(stylize::Error::from)
        })
        .with_context(|| format!("cannot write {}", out.display()))?;
        if closed.is_none() {
            closed = outln!(
                "{}: wrote {}\n  {}",
                setting.label(),
                out.display(),
                sanity.summary()
            )
            .err();
        }
        for w in sanity.warnings() {
            errln!("warning: {w}");
        }
    }
    if let Some(path) = &grid {
        super::apply_grid::write_sheet_labelled(path, &columns)?;
        if closed.is_none() {
            let (what, l): (&str, Vec<String>) = if strengths.is_empty() {
                ("λ", lambdas.iter().map(f64::to_string).collect())
            } else {
                ("strength", strengths.iter().map(f64::to_string).collect())
            };
            closed = outln!(
                "wrote {} ({what} = {} by column)",
                path.display(),
                l.join(", ")
            )
            .err();
        }
    }
    closed.map_or(Ok(()), |e| Err(e.into()))
}

/// `--strength max-safe:UPPER`: the strongest safe strength in `[1, UPPER]` at λ = `lambda`,
/// searched by [`crate::max_safe::search`] over `t = s − 1 ∈ [0, UPPER − 1]` (so the bisection
/// stops within 1 % of `s − 1`, finer than 1 % of `s`). Refuses when the result at λ itself
/// (s = 1) is not safe.
fn max_safe_strength(
    ready: &mut ReadyLayer,
    source: &mut SourceIntersections,
    lambda: f64,
    upper: f64,
) -> anyhow::Result<(f64, Vec<String>)> {
    let mut unsafe_warnings: Vec<(f64, Vec<String>)> = Vec::new(); // the problems of each unsafe strength
    let searched = crate::max_safe::search(upper - 1.0, |t| {
        let setting = Setting::Strength {
            lambda,
            strength: 1.0 + t,
        };
        let (_, s) = setting.assess(ready, source)?;
        let problems = s.problems();
        let safe = problems.is_empty();
        if !safe {
            unsafe_warnings.push((1.0 + t, problems));
        }
        Ok(safe)
    });
    let found = match searched {
        Ok(f) => f,
        Err(e) => {
            let why: Vec<String> = unsafe_warnings
                .iter()
                .filter(|(s, _)| *s == 1.0)
                .flat_map(|(_, w)| w.iter().cloned())
                .collect();
            if why.is_empty() {
                return Err(e);
            }
            bail!(
                "max-safe: no strength is safe: the result at λ = {lambda} itself (strength 1) \
                 is not safe: {}; find a safe λ first (--lambda max-safe)",
                why.join("; ")
            );
        }
    };
    let strength = 1.0 + found.lambda;
    let mut lines = Vec::new();
    match found.first_unsafe {
        None => lines.push(format!(
            "max-safe: every strength scanned up to {upper} is safe ({} evaluations): strength {upper}",
            found.evaluations
        )),
        Some(hi) => {
            let hi = 1.0 + hi;
            let why = unsafe_warnings
                .iter()
                .find(|(s, _)| *s == hi)
                .map(|(_, w)| w.join("; "))
                .unwrap_or_default();
            lines.push(format!(
                "max-safe: strength {strength} (the first unsafe strength is {hi}; {} evaluations up to {upper})",
                found.evaluations
            ));
            lines.push(format!("  unsafe at strength {hi}: {why}"));
        }
    }
    if !found.safe_again.is_empty() {
        let list: Vec<String> = found
            .safe_again
            .iter()
            .take(5)
            .map(|t| format!("{}", 1.0 + t))
            .collect();
        errln!(
            "warning: max-safe: safety is not monotone over the scan: after the first crossing the result is safe again at strength {} (the answer is the first crossing)",
            list.join(", ")
        );
    }
    Ok((strength, lines))
}

/// `--lambda max-safe:UPPER`: searches ([`crate::max_safe::search`]); returns the λ to write and
/// the lines that report what it found, for stdout (warnings go to stderr here).
fn max_safe(
    ready: &mut ReadyLayer,
    source: &mut SourceIntersections,
    upper: f64,
) -> anyhow::Result<(f64, Vec<String>)> {
    let mut lines = Vec::new();
    let assessed = crate::max_safe::search_assessed(upper, |lambda| {
        let deformed = ready
            .at_lambda(lambda)
            .with_context(|| format!("dARAP forward failed at λ = {lambda}"))?;
        crate::sanity::LambdaSanity::assess(&ready.rest, source, &deformed, lambda)
    })?;
    let found = &assessed.found;
    match found.first_unsafe {
        None => lines.push(format!(
            "max-safe: every λ scanned up to {upper} is safe ({} evaluations): λ = {upper}",
            found.evaluations
        )),
        Some(hi) => {
            let why = assessed.problems_at(hi).join("; ");
            lines.push(format!(
                "max-safe: λ = {} (within {}% of the first unsafe λ = {hi}; {} evaluations up to {upper})",
                found.lambda,
                100.0 * crate::max_safe::RELATIVE_TOLERANCE,
                found.evaluations
            ));
            lines.push(format!("  unsafe at λ = {hi}: {why}"));
            if found.lambda == 0.0 {
                errln!(
                    "warning: max-safe: no λ > 0 was found safe (unsafe down to λ = {hi}); writing the result at λ = 0"
                );
            }
        }
    }
    if !found.safe_again.is_empty() {
        const SHOWN: usize = 5;
        let mut list: Vec<String> = found
            .safe_again
            .iter()
            .take(SHOWN)
            .map(|l| format!("{l}"))
            .collect();
        if found.safe_again.len() > SHOWN {
            list.push(format!("… ({} grid points in all)", found.safe_again.len()));
        }
        errln!(
            "warning: max-safe: safety is not monotone over the scan: after the first crossing the result is safe again at λ = {} (the answer is the first crossing)",
            list.join(", ")
        );
    }
    Ok((found.lambda, lines))
}
