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
//! The area ratios of **all faces of all pairs are pooled**: the reported mean and standard
//! deviation (population, ddof = 0) are over that pool, as in the paper's table.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
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
pub fn pair_ratios(source: &TriMesh, result: &TriMesh) -> anyhow::Result<(Vec<f64>, usize, f64)> {
    if source.faces != result.faces {
        bail!(
            "source and result must have the same faces (source {} faces, result {}): identity metrics compare face by face",
            source.faces.len(),
            result.faces.len()
        );
    }
    if source.positions.len() != result.positions.len() {
        bail!(
            "source has {} vertices, result {}",
            source.positions.len(),
            result.positions.len()
        );
    }
    let n = source.positions.len();
    if let Some(f) = source.faces.iter().flatten().find(|&&v| v as usize >= n) {
        bail!("face index {f} out of range ({n} vertices)");
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
        bail!("the result mesh has zero or non-finite extent");
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
pub fn evaluate(pairs: &[(String, TriMesh, TriMesh)]) -> anyhow::Result<EvalReport> {
    let mut pooled = Vec::new();
    let mut out = Vec::new();
    for (name, source, result) in pairs {
        let (ratios, skipped, volume) =
            pair_ratios(source, result).with_context(|| name.clone())?;
        let (m, s) = mean_std(&ratios);
        out.push(PairMetrics {
            name: name.clone(),
            faces: ratios.len(),
            skipped_faces: skipped,
            area_ratio_mean: m,
            area_ratio_std: s,
            volume_ratio: volume,
        });
        pooled.extend(ratios);
    }
    let (mean, std) = mean_std(&pooled);
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
    })
}

/// The pair stored in a run directory: source = `deformation.npz`'s `verts` (the normalized rest
/// mesh), result = `mesh.obj`.
pub fn load_run_pair(dir: &Path) -> anyhow::Result<(TriMesh, TriMesh)> {
    let saved = mesh_core::npz::SavedDeformation::read(dir.join("deformation.npz"))
        .with_context(|| format!("{} is not a complete run directory", dir.display()))?;
    let source = TriMesh::new(saved.verts_f64(), saved.faces.clone());
    let result = mesh_core::io::read_mesh(dir.join("mesh.obj"))
        .with_context(|| format!("cannot read {}", dir.join("mesh.obj").display()))?;
    Ok((source, result))
}

/// Loads a pair of mesh files.
pub fn load_file_pair(source: &Path, result: &Path) -> anyhow::Result<(TriMesh, TriMesh)> {
    let s = mesh_core::io::read_mesh(source)
        .with_context(|| format!("cannot read {}", source.display()))?;
    let r = mesh_core::io::read_mesh(result)
        .with_context(|| format!("cannot read {}", result.display()))?;
    Ok((s, r))
}

/// A human-readable table of a report.
pub fn table(report: &EvalReport) -> String {
    let mut s = format!(
        "{:<40} {:>8} {:>18} {:>10}\n",
        "pair", "faces", "area ratio", "volume"
    );
    for p in &report.pairs {
        s += &format!(
            "{:<40} {:>8} {:>8.3} ± {:<7.3} {:>10.3}\n",
            p.name, p.faces, p.area_ratio_mean, p.area_ratio_std, p.volume_ratio
        );
    }
    s += &format!(
        "{:<40} {:>8} {:>8.3} ± {:<7.3} {:>10.3}\n",
        "pooled",
        report.pairs.iter().map(|p| p.faces).sum::<usize>(),
        report.area_ratio_mean,
        report.area_ratio_std,
        report.volume_ratio_mean
    );
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
}
