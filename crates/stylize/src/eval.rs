//! Identity-preservation metrics (spec §9).
//!
//! For each pair (source, result) with the same faces:
//! - the source is normalized to the side-2 cube (bbox centred, longest side 2);
//! - the result is recentred to its vertex centroid and rescaled so its bbox diagonal equals the
//!   normalized source's (as dARAP's `recenter_rescale`), which makes the metric invariant to the
//!   result's placement and overall scale;
//! - per face, `r_f = area_result(f) / area_source(f)` (faces of zero source area are skipped and
//!   counted);
//! - per mesh, the signed volume ratio `V_result / V_source` (divergence theorem,
//!   `Σ_f p1·(p2 × p3)/6`).
//!
//! - per pair, the **self-intersections** ([`crate::intersections`], exact): the source's and the
//!   result's intersecting face pairs and faces, and the pairs of the result that the source does
//!   not have (computed on the meshes as given: intersection does not depend on placement).
//!
//! The area ratios of **all faces of all pairs are pooled**: the reported mean and standard
//! deviation (population, ddof = 0) are over that pool, as in the paper's table.
//!
//! **CLIP similarity** (spec §9, optional, [`add_clip_scores`]): for a mesh M and prompt text,
//! `clip(M) = (1/N) Σ_v cos(E_img(render_v(M)), E_txt(text))`, the mean over N orbit views (16 in the
//! paper) of the cosine between each view's image embedding and the prompt's text embedding. Each
//! mesh (source and result) is normalized to the side-2 cube and rendered with
//! [`crate::run_pictures::turntable`] (azimuth 360°·k/N, elevation 20°, head light, distance fitting the
//! bounding sphere in the field of view — the same framing for every mesh, so scores compare across
//! runs; a run's `turntable.png` is zoomed to fill its tiles instead) on the CPU renderer at
//! [`ClipSettings::render_size`] pixels; the CLIP model resizes the renders to its own size
//! (bicubic, antialiased; `diffusion_onnx::clip`). The prompt of a run directory is the `prompt` of
//! its `deformation.npz` `dataset_cfg` (what the run was given); a model-free run has none, and its
//! CLIP columns are empty with the reason.

use std::path::{Path, PathBuf};

use crate::error::{Context, Result, invalid};
#[cfg(feature = "text")]
use diffusion_onnx::{ClipModel, cosine_similarity};
use mesh_core::TriMesh;
use mesh_core::geometry::{bbox_diagonal, face_areas, signed_volume, vertex_centroid};
use serde::Serialize;

/// Metrics of one pair.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PairMetrics {
    /// Label (file or run directory).
    pub name: String,
    /// Faces compared.
    pub faces: usize,
    /// Faces skipped because their source area is zero.
    pub skipped_faces: usize,
    /// Mean of `r_f` over this pair's faces.
    pub area_ratio_mean: f64,
    /// Population standard deviation of `r_f` over this pair's faces.
    pub area_ratio_std: f64,
    /// `V_result / V_source` (NaN when the source volume is 0, e.g. an open sheet).
    pub volume_ratio: f64,
    /// Source faces whose smallest corner angle is below [`NEEDLE_ANGLE_DEGREES`] (and of
    /// non-zero area): needles, whose area ratio swings wildly under small vertex moves.
    pub needle_faces: usize,
    /// The share of the pooled area ratios' sum of squared deviations (from the pooled mean) that
    /// this pair's needle faces contribute, in [0, 1]: at [`NEEDLE_VARIANCE_WARNING`] or more the
    /// pair's needles dominate the reported standard deviation (see [`EvalReport::warnings`]).
    pub needle_variance_share: f64,
    /// Self-intersections of the source and the result, and the result's new pairs.
    pub intersections: crate::intersections::IntersectionFigures,
    /// CLIP similarity of source and result (only when a CLIP model was given).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clip: Option<ClipScore>,
}

/// A source face is a needle below this smallest corner angle, in degrees (the repair report's
/// default, `mesh_core::validate::RepairOptions::needle_angle_degrees`).
pub const NEEDLE_ANGLE_DEGREES: f64 = 1.0;

/// [`EvalReport::warnings`] names a pair whose needle faces contribute at least this share of
/// the pooled area ratios' variance: 0.5 (half of the reported spread comes from a handful of
/// faces that a remesh would remove).
pub const NEEDLE_VARIANCE_WARNING: f64 = 0.5;

/// Smallest corner angle of a triangle in degrees (0 when degenerate).
fn min_corner_angle_degrees(p: [[f64; 3]; 3]) -> f64 {
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let mut best = f64::INFINITY;
    for i in 0..3 {
        let a = sub(p[(i + 1) % 3], p[i]);
        let b = sub(p[(i + 2) % 3], p[i]);
        let c = cross(a, b);
        best = best.min(dot(c, c).sqrt().atan2(dot(a, b)));
    }
    if best.is_finite() {
        best.to_degrees()
    } else {
        0.0
    }
}

/// Whether each face of positive area of `mesh` (in the order of the ratios of [`pair_ratios`])
/// is a needle.
fn needle_flags(mesh: &TriMesh) -> Vec<bool> {
    let mut src = mesh.positions.clone();
    mesh_core::normalize::side2_cube(&mut src);
    let areas = face_areas(&src, &mesh.faces);
    mesh.faces
        .iter()
        .zip(&areas)
        .filter(|(_, a)| **a > 0.0)
        .map(|(f, _)| {
            let p = f.map(|v| src[v as usize]);
            min_corner_angle_degrees(p) < NEEDLE_ANGLE_DEGREES
        })
        .collect()
}

/// CLIP similarity of one pair: mean over views of cos(image_v, text) for the source and the result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ClipScore {
    /// The prompt scored against (None: no prompt, see `skipped`).
    pub prompt: Option<String>,
    /// Views per mesh.
    pub views: usize,
    /// Mean cosine of the source's views (None when skipped).
    pub source: Option<f64>,
    /// Mean cosine of the result's views (None when skipped).
    pub result: Option<f64>,
    /// Why there are no scores.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skipped: Option<String>,
}

/// The prompt a pair is scored against, or why it has none.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Prompt {
    /// The prompt text.
    Text(String),
    /// No prompt; the reason (shown in the table and the JSON).
    Missing(String),
}

/// How the CLIP similarity renders the meshes.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipSettings {
    /// Orbit views per mesh (N; the paper: 16).
    pub views: usize,
    /// Side of the square renders in pixels (512: the run's render size; the CLIP model resizes).
    pub render_size: usize,
    /// Vertical field of view in degrees (the configuration's default, 90°).
    pub fov_deg: f64,
}

impl Default for ClipSettings {
    fn default() -> Self {
        Self {
            views: 16,
            render_size: 512,
            fov_deg: raster_diff::CameraConfig::default().fov_y_deg,
        }
    }
}

/// Metrics of a set of pairs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EvalReport {
    /// Per pair.
    pub pairs: Vec<PairMetrics>,
    /// Mean of `r_f` pooled over every face of every pair.
    pub area_ratio_mean: f64,
    /// Population standard deviation of the pooled `r_f`.
    pub area_ratio_std: f64,
    /// Mean of the finite per-pair volume ratios.
    pub volume_ratio_mean: f64,
    /// Mean over the scored pairs of the source's CLIP similarity (only with a CLIP model).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clip_source_mean: Option<f64>,
    /// Mean over the scored pairs of the result's CLIP similarity (only with a CLIP model).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clip_result_mean: Option<f64>,
    /// Mean and population standard deviation of the pooled `r_f` without the needle faces
    /// (what the spread would be on well-shaped triangles).
    pub area_ratio_mean_without_needles: f64,
    /// See [`Self::area_ratio_mean_without_needles`].
    pub area_ratio_std_without_needles: f64,
    /// One line per pair whose needle faces dominate the pooled area ratio's variance
    /// ([`NEEDLE_VARIANCE_WARNING`]).
    pub warnings: Vec<String>,
}

fn mean_std(values: &[f64]) -> (f64, f64) {
    if values.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
    (mean, var.sqrt())
}

/// The per-face area ratios and the volume ratio of one pair (see the module docs).
pub fn pair_ratios(source: &TriMesh, result: &TriMesh) -> Result<(Vec<f64>, usize, f64)> {
    if source.faces != result.faces {
        invalid!(
            "source and result must have the same faces (source {} faces, result {}): identity metrics compare face by face",
            source.faces.len(),
            result.faces.len()
        );
    }
    if source.positions.len() != result.positions.len() {
        invalid!(
            "source has {} vertices, result {}",
            source.positions.len(),
            result.positions.len()
        );
    }
    let n = source.positions.len();
    if let Some(f) = source.faces.iter().flatten().find(|&&v| v as usize >= n) {
        invalid!("face index {f} out of range ({n} vertices)");
    }
    let mut src = source.positions.clone();
    mesh_core::normalize::side2_cube(&mut src);
    let centroid = vertex_centroid(&result.positions);
    let mut res: Vec<[f64; 3]> = result
        .positions
        .iter()
        .map(|p| [p[0] - centroid[0], p[1] - centroid[1], p[2] - centroid[2]])
        .collect();
    let (d_src, d_res) = (bbox_diagonal(&src), bbox_diagonal(&res));
    if !(d_res > 0.0 && d_res.is_finite()) {
        invalid!("the result mesh has zero or non-finite extent");
    }
    let s = d_src / d_res;
    for p in &mut res {
        *p = p.map(|c| c * s);
    }
    let a_src = face_areas(&src, &source.faces);
    let a_res = face_areas(&res, &source.faces);
    let mut ratios = Vec::with_capacity(a_src.len());
    let mut skipped = 0;
    for (a, b) in a_src.iter().zip(&a_res) {
        if *a > 0.0 {
            ratios.push(b / a);
        } else {
            skipped += 1;
        }
    }
    let v_src = signed_volume(&src, &source.faces);
    let v_res = signed_volume(&res, &source.faces);
    let volume = if v_src != 0.0 {
        v_res / v_src
    } else {
        f64::NAN
    };
    Ok((ratios, skipped, volume))
}

/// Evaluates named `(source, result)` pairs.
pub fn evaluate(pairs: &[(String, TriMesh, TriMesh)]) -> Result<EvalReport> {
    let mut pooled = Vec::new();
    let mut needles = Vec::new();
    let mut out = Vec::new();
    for (name, source, result) in pairs {
        let (ratios, skipped, volume) =
            pair_ratios(source, result).with_context(|| name.clone())?;
        let flags = needle_flags(source);
        let (m, s) = mean_std(&ratios);
        let intersections =
            crate::intersections::compare(source, result).with_context(|| name.clone())?;
        out.push(PairMetrics {
            name: name.clone(),
            faces: ratios.len(),
            skipped_faces: skipped,
            area_ratio_mean: m,
            area_ratio_std: s,
            volume_ratio: volume,
            needle_faces: flags.iter().filter(|&&n| n).count(),
            needle_variance_share: 0.0,
            intersections,
            clip: None,
        });
        pooled.extend(ratios);
        needles.push(flags);
    }
    let (mean, std) = mean_std(&pooled);
    // Each pair's needle faces' share of the pooled sum of squared deviations.
    let total: f64 = pooled.iter().map(|r| (r - mean) * (r - mean)).sum();
    let mut at = 0;
    let mut without = Vec::with_capacity(pooled.len());
    let mut warnings = Vec::new();
    for (pair, flags) in out.iter_mut().zip(&needles) {
        let ratios = &pooled[at..at + pair.faces];
        at += pair.faces;
        let mut needle_ss = 0.0;
        for (r, &needle) in ratios.iter().zip(flags) {
            if needle {
                needle_ss += (r - mean) * (r - mean);
            } else {
                without.push(*r);
            }
        }
        pair.needle_variance_share = if total > 0.0 { needle_ss / total } else { 0.0 };
        if pair.needle_variance_share >= NEEDLE_VARIANCE_WARNING {
            warnings.push(format!(
                "{}: {} needle face{} (smallest angle < {NEEDLE_ANGLE_DEGREES}°) make{} {:.0}% of \
                 the pooled area ratio's variance: the ± is theirs, not the stylization's; remesh \
                 the input (or compare the figures without needles)",
                pair.name,
                pair.needle_faces,
                if pair.needle_faces == 1 { "" } else { "s" },
                if pair.needle_faces == 1 { "s" } else { "" },
                100.0 * pair.needle_variance_share
            ));
        }
    }
    let (mean_without, std_without) = mean_std(&without);
    let volumes: Vec<f64> = out
        .iter()
        .map(|p| p.volume_ratio)
        .filter(|v| v.is_finite())
        .collect();
    let volume_ratio_mean = mean_std(&volumes).0;
    Ok(EvalReport {
        pairs: out,
        area_ratio_mean: mean,
        area_ratio_std: std,
        volume_ratio_mean,
        clip_source_mean: None,
        clip_result_mean: None,
        area_ratio_mean_without_needles: mean_without,
        area_ratio_std_without_needles: std_without,
        warnings,
    })
}

/// The report as CSV: a header, one line per pair and a `pooled` line. Columns: `name`, `faces`,
/// `skipped_faces`, `area_ratio_mean`, `area_ratio_std`, `volume_ratio`, `needle_faces`,
/// `needle_variance_share`, `source_intersecting_pairs`, `intersecting_pairs`,
/// `new_intersecting_pairs`, `new_intersecting_faces` ([`crate::intersections`]), `clip_prompt`,
/// `clip_source`, `clip_result` (empty cells where there is no value; the pooled line sums the
/// counts). Fields with a comma, quote or line break are quoted (RFC 4180).
pub fn csv(report: &EvalReport) -> String {
    fn field(s: &str) -> String {
        if s.contains([',', '"', '\n', '\r']) {
            format!("\"{}\"", s.replace('"', "\"\""))
        } else {
            s.to_string()
        }
    }
    let num = |v: Option<f64>| v.map(|x| format!("{x}")).unwrap_or_default();
    let sum = |f: fn(&crate::intersections::IntersectionFigures) -> usize| {
        report
            .pairs
            .iter()
            .map(|p| f(&p.intersections))
            .sum::<usize>()
            .to_string()
    };
    let mut s = String::from(
        "name,faces,skipped_faces,area_ratio_mean,area_ratio_std,volume_ratio,needle_faces,\
         needle_variance_share,source_intersecting_pairs,intersecting_pairs,\
         new_intersecting_pairs,new_intersecting_faces,clip_prompt,clip_source,clip_result\n",
    );
    for p in &report.pairs {
        let clip = p.clip.as_ref();
        s += &[
            field(&p.name),
            p.faces.to_string(),
            p.skipped_faces.to_string(),
            format!("{}", p.area_ratio_mean),
            format!("{}", p.area_ratio_std),
            format!("{}", p.volume_ratio),
            p.needle_faces.to_string(),
            format!("{}", p.needle_variance_share),
            p.intersections.source_pairs.to_string(),
            p.intersections.pairs.to_string(),
            p.intersections.new_pairs.to_string(),
            p.intersections.new_faces.to_string(),
            field(clip.and_then(|c| c.prompt.as_deref()).unwrap_or("")),
            num(clip.and_then(|c| c.source)),
            num(clip.and_then(|c| c.result)),
        ]
        .join(",");
        s += "\n";
    }
    s += &[
        "pooled".to_string(),
        report
            .pairs
            .iter()
            .map(|p| p.faces)
            .sum::<usize>()
            .to_string(),
        report
            .pairs
            .iter()
            .map(|p| p.skipped_faces)
            .sum::<usize>()
            .to_string(),
        format!("{}", report.area_ratio_mean),
        format!("{}", report.area_ratio_std),
        format!("{}", report.volume_ratio_mean),
        report
            .pairs
            .iter()
            .map(|p| p.needle_faces)
            .sum::<usize>()
            .to_string(),
        format!(
            "{}",
            report
                .pairs
                .iter()
                .map(|p| p.needle_variance_share)
                .sum::<f64>()
        ),
        sum(|x| x.source_pairs),
        sum(|x| x.pairs),
        sum(|x| x.new_pairs),
        sum(|x| x.new_faces),
        String::new(),
        num(report.clip_source_mean),
        num(report.clip_result_mean),
    ]
    .join(",");
    s += "\n";
    s
}

#[cfg(feature = "text")]
/// `(1/N) Σ_v cos(image_v, text)`: the paper's CLIP similarity of one mesh from its view embeddings.
pub fn mean_view_similarity(views: &[Vec<f32>], text: &[f32]) -> f64 {
    if views.is_empty() {
        return f64::NAN;
    }
    views
        .iter()
        .map(|v| cosine_similarity(v, text))
        .sum::<f64>()
        / views.len() as f64
}

#[cfg(feature = "text")]
/// Image embeddings of `settings.views` orbit renders of `mesh` (normalized to the side-2 cube);
/// adds the time spent to `timings`.
pub fn view_embeddings(
    clip: &mut ClipModel,
    renderer: &mut raster_diff::CpuRenderer,
    mesh: &TriMesh,
    settings: &ClipSettings,
    timings: &mut ClipTimings,
) -> Result<Vec<Vec<f32>>> {
    let start = std::time::Instant::now();
    let mut positions = mesh.positions.clone();
    mesh_core::normalize::side2_cube(&mut positions);
    let images = crate::run_pictures::turntable(
        renderer,
        &positions,
        &mesh.faces,
        settings.views,
        settings.render_size,
        settings.fov_deg,
    )?;
    if images.width != images.height {
        invalid!(
            "the turntable render is {}×{}, CLIP needs square images",
            images.width,
            images.height
        );
    }
    let rendered = std::time::Instant::now();
    timings.render_s += (rendered - start).as_secs_f64();
    let embeddings = clip
        .embed_images(&images.rgb, images.count, images.width)
        .context("CLIP image embedding")?;
    timings.embed_images_s += rendered.elapsed().as_secs_f64();
    timings.meshes += 1;
    Ok(embeddings)
}

/// Wall-clock seconds spent by [`add_clip_scores`], by stage.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ClipTimings {
    /// Rendering the orbit views (CPU renderer).
    pub render_s: f64,
    /// Preprocessing and embedding the views.
    pub embed_images_s: f64,
    /// Tokenizing and embedding the prompts.
    pub embed_texts_s: f64,
    /// Meshes rendered.
    pub meshes: usize,
}

#[cfg(feature = "text")]
/// Adds the CLIP similarity of every pair to `report` (`pairs` and `prompts` in the order the report
/// was made from). Each distinct prompt is embedded once; pairs without a prompt get an empty score
/// with the reason. Also fills the report's means over the scored pairs.
pub fn add_clip_scores(
    report: &mut EvalReport,
    pairs: &[(String, TriMesh, TriMesh)],
    prompts: &[Prompt],
    clip: &mut ClipModel,
    settings: &ClipSettings,
) -> Result<ClipTimings> {
    if pairs.len() != report.pairs.len() || prompts.len() != pairs.len() {
        invalid!(
            "{} pairs, {} prompts, {} report rows: they must match",
            pairs.len(),
            prompts.len(),
            report.pairs.len()
        );
    }
    if settings.views == 0 || settings.render_size == 0 {
        invalid!("CLIP needs at least one view and a positive render size");
    }
    let mut renderer = raster_diff::CpuRenderer::default();
    let mut timings = ClipTimings::default();
    let mut texts: Vec<(String, Vec<f32>)> = Vec::new();
    let (mut sources, mut results) = (Vec::new(), Vec::new());
    for ((row, (name, source, result)), prompt) in report.pairs.iter_mut().zip(pairs).zip(prompts) {
        let text = match prompt {
            Prompt::Text(t) => t,
            Prompt::Missing(why) => {
                row.clip = Some(ClipScore {
                    prompt: None,
                    views: settings.views,
                    source: None,
                    result: None,
                    skipped: Some(why.clone()),
                });
                continue;
            }
        };
        let embedding = match texts.iter().find(|(t, _)| t == text) {
            Some((_, e)) => e.clone(),
            None => {
                let start = std::time::Instant::now();
                let e = clip
                    .embed_texts(&[text])
                    .with_context(|| format!("CLIP text embedding of {text:?}"))?
                    .pop()
                    .ok_or_else(|| {
                        crate::Error::Invalid("the CLIP text encoder returned nothing".into())
                    })?;
                texts.push((text.clone(), e.clone()));
                timings.embed_texts_s += start.elapsed().as_secs_f64();
                e
            }
        };
        let mut score = |mesh: &TriMesh, which: &str| {
            view_embeddings(clip, &mut renderer, mesh, settings, &mut timings)
                .map(|v| mean_view_similarity(&v, &embedding))
                .with_context(|| format!("{name}: CLIP similarity of the {which}"))
        };
        let s = score(source, "source")?;
        let r = score(result, "result")?;
        sources.push(s);
        results.push(r);
        row.clip = Some(ClipScore {
            prompt: Some(text.clone()),
            views: settings.views,
            source: Some(s),
            result: Some(r),
            skipped: None,
        });
    }
    let mean = |v: &[f64]| (!v.is_empty()).then(|| mean_std(v).0);
    report.clip_source_mean = mean(&sources);
    report.clip_result_mean = mean(&results);
    Ok(timings)
}

/// The prompt recorded in a saved deformation's `dataset_cfg` JSON (`{"mesh": …, "prompt": …}` for
/// the text path, `{"mesh": …, "style": …}` for the model-free path).
pub fn prompt_of_dataset_cfg(dataset_cfg: &str) -> Prompt {
    let value: serde_json::Value = match serde_json::from_str(dataset_cfg) {
        Ok(v) => v,
        Err(e) => {
            return Prompt::Missing(format!(
                "deformation.npz dataset_cfg is not JSON ({e}); no prompt"
            ));
        }
    };
    match (value.get("prompt"), value.get("style")) {
        (Some(serde_json::Value::String(p)), _) => Prompt::Text(p.clone()),
        (_, Some(style)) => Prompt::Missing(format!(
            "model-free run (style {style}): no prompt to score against"
        )),
        _ => Prompt::Missing("deformation.npz dataset_cfg has no \"prompt\"".into()),
    }
}

/// The pair stored in a run directory: source = `deformation.npz`'s `verts` (the normalized rest
/// mesh), result = `mesh.obj`, mapped back to the normalized frame when the run wrote it in the
/// input's frame (`deformation.npz`'s `output_frame` and `to_input_frame`, [`crate::frame`]), so
/// that the metrics and the CLIP renders (which turn with the orientation `mesh.up`) do not depend
/// on the output frame.
pub fn load_run_pair(dir: &Path) -> Result<(TriMesh, TriMesh)> {
    load_run(dir).map(|(s, r, _)| (s, r))
}

/// [`load_run_pair`] plus the run's prompt ([`prompt_of_dataset_cfg`]).
pub fn load_run(dir: &Path) -> Result<(TriMesh, TriMesh, Prompt)> {
    let saved = crate::saved::SavedDeformation::read(dir.join("deformation.npz"))
        .with_context(|| format!("{} is not a complete run directory", dir.display()))?;
    let source = TriMesh::new(saved.verts_f64(), saved.faces.clone());
    let mut result = mesh_core::io::read_mesh(dir.join("mesh.obj"))
        .with_context(|| format!("cannot read {}", dir.join("mesh.obj").display()))?;
    let npz = dir.join("deformation.npz");
    if saved.output_frame().context(npz.display().to_string())? == crate::frame::OutputFrame::Input
    {
        let Some(frame) = saved.input_frame().context(npz.display().to_string())? else {
            invalid!(
                "{}: `output_frame` is \"input\" but `to_input_frame` is missing",
                npz.display()
            );
        };
        if result.positions.len() != source.positions.len() {
            invalid!(
                "{} has {} vertices, the saved rest mesh {}",
                dir.join("mesh.obj").display(),
                result.positions.len(),
                source.positions.len()
            );
        }
        // The run's post-process is not recorded in the file; the centroid shift is a translation,
        // which the metrics remove anyway (the result is recentred) and the CLIP renders too.
        result.positions =
            frame.unplace_result(&result.positions, &saved.rest_positions(), true)?;
    }
    Ok((source, result, prompt_of_dataset_cfg(&saved.dataset_cfg)))
}

/// Loads a pair of mesh files.
pub fn load_file_pair(source: &Path, result: &Path) -> Result<(TriMesh, TriMesh)> {
    let s = mesh_core::io::read_mesh(source)
        .with_context(|| format!("cannot read {}", source.display()))?;
    let r = mesh_core::io::read_mesh(result)
        .with_context(|| format!("cannot read {}", result.display()))?;
    Ok((s, r))
}

/// A human-readable table of a report. With CLIP scores, two more columns (source and result mean
/// cosine) and, below the table, the prompt of each pair or why it has none.
pub fn table(report: &EvalReport) -> String {
    let with_clip = report.pairs.iter().any(|p| p.clip.is_some());
    let clip_cell = |v: Option<f64>| match v {
        Some(x) => format!(" {x:>9.4}"),
        None => format!(" {:>9}", "—"),
    };
    let mut s = format!(
        "{:<40} {:>8} {:>18} {:>10} {:>17}",
        "pair", "faces", "area ratio", "volume", "self-∩ faces (new)"
    );
    if with_clip {
        s += &format!(" {:>9} {:>9}", "CLIP src", "CLIP res");
    }
    s += "\n";
    for p in &report.pairs {
        let x = &p.intersections;
        s += &format!(
            "{:<40} {:>8} {:>8.3} ± {:<7.3} {:>10.3} {:>17}",
            p.name,
            p.faces,
            p.area_ratio_mean,
            p.area_ratio_std,
            p.volume_ratio,
            format!("{} ({})", x.faces, x.new_faces)
        );
        if with_clip {
            let c = p.clip.as_ref();
            s += &clip_cell(c.and_then(|c| c.source));
            s += &clip_cell(c.and_then(|c| c.result));
        }
        s += "\n";
    }
    s += &format!(
        "{:<40} {:>8} {:>8.3} ± {:<7.3} {:>10.3} {:>17}",
        "pooled",
        report.pairs.iter().map(|p| p.faces).sum::<usize>(),
        report.area_ratio_mean,
        report.area_ratio_std,
        report.volume_ratio_mean,
        format!(
            "{} ({})",
            report
                .pairs
                .iter()
                .map(|p| p.intersections.faces)
                .sum::<usize>(),
            report
                .pairs
                .iter()
                .map(|p| p.intersections.new_faces)
                .sum::<usize>()
        )
    );
    if with_clip {
        s += &clip_cell(report.clip_source_mean);
        s += &clip_cell(report.clip_result_mean);
    }
    s += "\n";
    if report.pairs.iter().any(|p| p.needle_faces > 0) {
        s += &format!(
            "{:<40} {:>8} {:>8.3} ± {:<7.3}\n",
            "pooled without needle faces",
            report
                .pairs
                .iter()
                .map(|p| p.faces - p.needle_faces)
                .sum::<usize>(),
            report.area_ratio_mean_without_needles,
            report.area_ratio_std_without_needles
        );
    }
    for w in &report.warnings {
        s += &format!("warning: {w}\n");
    }
    if with_clip {
        for p in &report.pairs {
            match &p.clip {
                Some(ClipScore {
                    prompt: Some(t),
                    views,
                    ..
                }) => s += &format!("CLIP {}: {t:?}, {views} views\n", p.name),
                Some(ClipScore {
                    skipped: Some(why), ..
                }) => s += &format!("CLIP {}: empty: {why}\n", p.name),
                _ => {}
            }
        }
    }
    s
}

/// Convenience for callers holding paths: a label for a path.
pub fn label(path: &Path) -> String {
    PathBuf::from(path).display().to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cube [−1, 1]³, 12 outward triangles.
    fn cube() -> TriMesh {
        let p = vec![
            [-1.0, -1.0, -1.0],
            [1.0, -1.0, -1.0],
            [1.0, 1.0, -1.0],
            [-1.0, 1.0, -1.0],
            [-1.0, -1.0, 1.0],
            [1.0, -1.0, 1.0],
            [1.0, 1.0, 1.0],
            [-1.0, 1.0, 1.0],
        ];
        let f = vec![
            [0, 2, 1],
            [0, 3, 2],
            [4, 5, 6],
            [4, 6, 7],
            [0, 1, 5],
            [0, 5, 4],
            [3, 6, 2],
            [3, 7, 6],
            [0, 4, 7],
            [0, 7, 3],
            [1, 2, 6],
            [1, 6, 5],
        ];
        TriMesh::new(p, f)
    }

    #[test]
    fn identity_and_similarity_transforms_give_unit_ratios() {
        let c = cube();
        assert!(
            signed_volume(&c.positions, &c.faces) > 0.0,
            "fixture must be outward"
        );
        let moved = TriMesh::new(
            c.positions
                .iter()
                .map(|p| [3.0 * p[0] + 5.0, 3.0 * p[1] - 1.0, 3.0 * p[2]])
                .collect(),
            c.faces.clone(),
        );
        let r = evaluate(&[
            ("same".into(), c.clone(), c.clone()),
            ("moved".into(), c.clone(), moved),
        ])
        .unwrap_or_else(|e| panic!("{e:#}"));
        assert!((r.area_ratio_mean - 1.0).abs() < 1e-12 && r.area_ratio_std < 1e-12);
        assert!((r.volume_ratio_mean - 1.0).abs() < 1e-12);
    }

    #[test]
    fn stretch_matches_closed_form() {
        // Result = cube stretched ×2 along x. Rescale to the source diagonal: s = √12/√24 = 1/√2.
        // ±x faces: area × s² = 1/2 (4 triangles); ±y, ±z faces: × 2s² = 1 (8 triangles).
        // Pooled mean 5/6, population std √(1/18); volume ratio 2 s³ = 1/√2.
        let c = cube();
        let stretched = TriMesh::new(
            c.positions
                .iter()
                .map(|p| [2.0 * p[0], p[1], p[2]])
                .collect(),
            c.faces.clone(),
        );
        let r = evaluate(&[("x2".into(), c, stretched)]).unwrap_or_else(|e| panic!("{e:#}"));
        assert!(
            (r.area_ratio_mean - 5.0 / 6.0).abs() < 1e-12,
            "{}",
            r.area_ratio_mean
        );
        assert!(
            (r.area_ratio_std - (1.0f64 / 18.0).sqrt()).abs() < 1e-12,
            "{}",
            r.area_ratio_std
        );
        assert!((r.volume_ratio_mean - 0.5f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn pooled_statistics_weight_every_face_not_every_mesh() {
        let c = cube();
        let stretched = TriMesh::new(
            c.positions
                .iter()
                .map(|p| [2.0 * p[0], p[1], p[2]])
                .collect(),
            c.faces.clone(),
        );
        let r = evaluate(&[
            ("a".into(), c.clone(), c.clone()),
            ("b".into(), c, stretched),
        ])
        .unwrap_or_else(|e| panic!("{e:#}"));
        // 12 ones + (4 × 0.5, 8 × 1): mean = (12 + 2 + 8)/24.
        assert!((r.area_ratio_mean - 22.0 / 24.0).abs() < 1e-12);
    }

    #[test]
    fn different_faces_are_rejected() {
        let c = cube();
        let mut other = c.clone();
        other.faces.pop();
        assert!(evaluate(&[("x".into(), c, other)]).is_err());
    }

    #[test]
    fn prompt_comes_from_dataset_cfg_or_says_why_not() {
        assert_eq!(
            prompt_of_dataset_cfg(r#"{"mesh": "a.obj", "prompt": "a cactus"}"#),
            Prompt::Text("a cactus".into())
        );
        let Prompt::Missing(why) = prompt_of_dataset_cfg(r#"{"mesh": "a.obj", "style": "cube"}"#)
        else {
            panic!("a style run has no prompt")
        };
        assert!(why.contains("model-free") && why.contains("cube"), "{why}");
        assert!(matches!(
            prompt_of_dataset_cfg(r#"{"mesh": "a.obj"}"#),
            Prompt::Missing(w) if w.contains("\"prompt\"")
        ));
        assert!(matches!(
            prompt_of_dataset_cfg("not json"),
            Prompt::Missing(w) if w.contains("not JSON")
        ));
    }

    #[cfg(feature = "text")]
    #[test]
    fn mean_view_similarity_is_the_mean_of_per_view_cosines() {
        let text = [1.0f32, 0.0];
        // cos = 1, 0, −1 → mean 0; scaling a view does not change its cosine.
        let views = vec![vec![3.0f32, 0.0], vec![0.0, 2.0], vec![-0.5, 0.0]];
        assert!(mean_view_similarity(&views, &text).abs() < 1e-12);
        let views = vec![vec![1.0f32, 1.0], vec![5.0, 0.0]];
        let want = (0.5f64.sqrt() + 1.0) / 2.0;
        assert!((mean_view_similarity(&views, &text) - want).abs() < 1e-7);
        assert!(mean_view_similarity(&[], &text).is_nan());
    }

    #[test]
    fn table_shows_clip_columns_and_reasons() {
        let c = cube();
        let mut r = evaluate(&[
            ("a".into(), c.clone(), c.clone()),
            ("b".into(), c.clone(), c),
        ])
        .unwrap_or_else(|e| panic!("{e:#}"));
        assert!(!table(&r).contains("CLIP"));
        r.pairs[0].clip = Some(ClipScore {
            prompt: Some("a cat".into()),
            views: 16,
            source: Some(0.25),
            result: Some(0.3125),
            skipped: None,
        });
        r.pairs[1].clip = Some(ClipScore {
            prompt: None,
            views: 16,
            source: None,
            result: None,
            skipped: Some("model-free run".into()),
        });
        let t = table(&r);
        assert!(
            t.contains("CLIP src") && t.contains("0.2500") && t.contains("0.3125"),
            "{t}"
        );
        assert!(t.contains("b: empty: model-free run"), "{t}");
    }
}
