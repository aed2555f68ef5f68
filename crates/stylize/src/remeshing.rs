//! Remeshing the input of a run (`[mesh] remesh`, `--remesh`): whether to, to what edge length,
//! and what it did — the layer between the setting and [`mesh_core::remesh`].
//!
//! The setting ([`RemeshSetting`]) is one of
//! - `auto` (the default): remesh when the prepared input's triangles are poor by
//!   [`remeshing_advised`], else keep it exactly;
//! - `on`: always remesh, to [`DEFAULT_EDGE_LENGTH`];
//! - `off`: never (the input's connectivity exactly);
//! - an edge length: always remesh to it, `0.03` in the side-2 frame the run optimizes in (the
//!   longest bounding-box side is 2) or `1.5%` of the bounding-box diagonal.
//!
//! Remeshing runs on the prepared mesh (repaired, side-2 normalized), with
//! [`mesh_core::remesh::RemeshOptions`]' defaults (10 rounds, feature angle 30°), and the
//! remeshed mesh is normalized again, so what is optimized, saved and re-applied is always a
//! side-2 mesh.
//!
//! **The criterion** ([`remeshing_advised`]): remeshing is advised when the edge-length standard
//! deviation over the mean exceeds [`ADVISED_ABOVE_EDGE_STD_OVER_MEAN`] (0.4) or more than
//! [`ADVISED_ABOVE_SHARE_BELOW_10_DEG`] (1 %) of the faces have a corner under 10°. The
//! thresholds sit between the even meshes the method is known to work on (the authors'
//! remeshed chair: std/mean 0.15; the bunny 0.24, fandisk 0.22, both with no corner under 10°)
//! and the meshes it gives artifacts on (the cow 0.64 and the triceratops 0.69, 3.6–3.8 % of the
//! faces under 10°; the CAD part `rotor_small.off` 0.89).

use std::fmt;
use std::str::FromStr;
use std::time::Instant;

use mesh_core::remesh::{Hausdorff, Quality, RemeshOptions, Remeshed};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Edge-length std/mean above which remeshing is advised.
pub const ADVISED_ABOVE_EDGE_STD_OVER_MEAN: f64 = 0.4;

/// Share of faces (0–1) with a corner under 10° above which remeshing is advised.
pub const ADVISED_ABOVE_SHARE_BELOW_10_DEG: f64 = 0.01;

/// The target edge length of `on` and of an advised `auto`: 1.5 % of the bounding-box diagonal
/// (the authors' remeshed inputs).
pub const DEFAULT_EDGE_LENGTH: EdgeLength = EdgeLength::PercentOfDiagonal(1.5);

/// A target edge length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EdgeLength {
    /// In the mesh's units (for a run: the side-2 frame).
    Absolute(f64),
    /// Percent of the bounding-box diagonal (`1.5%`).
    PercentOfDiagonal(f64),
}

impl EdgeLength {
    /// The length for a mesh whose bounding-box diagonal is `diagonal`.
    pub fn resolve(self, diagonal: f64) -> f64 {
        match self {
            EdgeLength::Absolute(l) => l,
            EdgeLength::PercentOfDiagonal(p) => p / 100.0 * diagonal,
        }
    }
}

impl fmt::Display for EdgeLength {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EdgeLength::Absolute(l) => write!(f, "{l}"),
            EdgeLength::PercentOfDiagonal(p) => write!(f, "{p}%"),
        }
    }
}

impl FromStr for EdgeLength {
    type Err = String;

    /// `0.03` or `1.5%`: a positive finite number (a percentage at most 100).
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let t = s.trim();
        let (number, percent) = match t.strip_suffix('%') {
            Some(n) => (n.trim(), true),
            None => (t, false),
        };
        let x: f64 = number
            .parse()
            .map_err(|_| format!("`{s}` is not an edge length (a number such as 0.03, or 1.5%)"))?;
        if !(x.is_finite() && x > 0.0) {
            return Err(format!(
                "the edge length must be a positive finite number, got `{s}`"
            ));
        }
        if percent {
            if x > 100.0 {
                return Err(format!(
                    "an edge length of `{s}` of the bounding-box diagonal is longer than the mesh"
                ));
            }
            Ok(EdgeLength::PercentOfDiagonal(x))
        } else {
            Ok(EdgeLength::Absolute(x))
        }
    }
}

/// `[mesh] remesh` (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum RemeshSetting {
    /// Remesh when [`remeshing_advised`].
    #[default]
    Auto,
    /// Always, to [`DEFAULT_EDGE_LENGTH`].
    On,
    /// Never.
    Off,
    /// Always, to this length.
    EdgeLength(EdgeLength),
}

impl fmt::Display for RemeshSetting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RemeshSetting::Auto => f.write_str("auto"),
            RemeshSetting::On => f.write_str("on"),
            RemeshSetting::Off => f.write_str("off"),
            RemeshSetting::EdgeLength(l) => write!(f, "{l}"),
        }
    }
}

impl FromStr for RemeshSetting {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.trim() {
            "auto" => Ok(RemeshSetting::Auto),
            "on" => Ok(RemeshSetting::On),
            "off" => Ok(RemeshSetting::Off),
            other => other
                .parse()
                .map(RemeshSetting::EdgeLength)
                .map_err(|e| format!("{e}; mesh.remesh is `auto`, `on`, `off` or an edge length")),
        }
    }
}

impl Serialize for RemeshSetting {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> Deserialize<'de> for RemeshSetting {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        // A bare number (`remesh = 0.03` in TOML) is an edge length too.
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Text(String),
            Number(f64),
        }
        match Raw::deserialize(d)? {
            Raw::Text(t) => t.parse().map_err(serde::de::Error::custom),
            Raw::Number(x) => x.to_string().parse().map_err(serde::de::Error::custom),
        }
    }
}

/// Why remeshing is advised for a mesh of quality `q` (`None`: its triangles are even enough).
pub fn remeshing_advised(q: &Quality) -> Option<String> {
    let mut why = Vec::new();
    if q.edge_std_over_mean() > ADVISED_ABOVE_EDGE_STD_OVER_MEAN {
        why.push(format!(
            "edge-length std/mean {:.3} > {ADVISED_ABOVE_EDGE_STD_OVER_MEAN}",
            q.edge_std_over_mean()
        ));
    }
    if q.share_below_10_deg > ADVISED_ABOVE_SHARE_BELOW_10_DEG {
        why.push(format!(
            "{:.1} % of the faces have a corner under 10° (> {} %)",
            100.0 * q.share_below_10_deg,
            100.0 * ADVISED_ABOVE_SHARE_BELOW_10_DEG
        ));
    }
    (!why.is_empty()).then(|| why.join(", "))
}

/// One line of quality figures: vertices, faces, edge mean (% of the diagonal) and std/mean,
/// minimum angle, shares of faces with a corner under 10° and 30°, valence-6 share.
pub fn quality_line(q: &Quality) -> String {
    format!(
        "{} vertices, {} faces; edge mean {:.2} % of the diagonal, std/mean {:.3}; min angle \
         {:.2}°, corners < 10°: {:.2} % of faces, < 30°: {:.1} %; valence 6: {:.1} %",
        q.vertices,
        q.faces,
        100.0 * q.edge_length_mean / q.diagonal.max(f64::MIN_POSITIVE),
        q.edge_std_over_mean(),
        q.min_angle_deg,
        100.0 * q.share_below_10_deg,
        100.0 * q.share_below_30_deg,
        100.0 * q.share_valence_6
    )
}

/// The quality figures as JSON (the keys of `run.json`'s `remesh.before/after` and of
/// `stylize remesh --json`).
pub fn quality_json(q: &Quality) -> serde_json::Value {
    serde_json::json!({
        "vertices": q.vertices,
        "faces": q.faces,
        "edge_length_mean": q.edge_length_mean,
        "edge_length_mean_percent_of_diagonal":
            100.0 * q.edge_length_mean / q.diagonal.max(f64::MIN_POSITIVE),
        "edge_std_over_mean": q.edge_std_over_mean(),
        "min_angle_deg": q.min_angle_deg,
        "share_below_10_deg": q.share_below_10_deg,
        "share_below_30_deg": q.share_below_30_deg,
        "share_valence_6": q.share_valence_6,
        "diagonal": q.diagonal,
    })
}

/// What remeshing did to a run's input.
#[derive(Clone, Debug, PartialEq)]
pub struct RemeshOutcome {
    /// The target edge length (side-2 units).
    pub edge_length: f64,
    /// The options it ran with.
    pub options: RemeshOptions,
    /// Quality of the remeshed mesh.
    pub after: Quality,
    /// Distance between the remeshed surface and the input (side-2 units).
    pub hausdorff: Hausdorff,
    /// Seconds spent remeshing (and measuring).
    pub seconds: f64,
}

/// What `[mesh] remesh` decided for a run's input and why.
#[derive(Clone, Debug, PartialEq)]
pub struct RemeshReport {
    /// The setting.
    pub setting: RemeshSetting,
    /// Quality of the prepared input.
    pub before: Quality,
    /// Why: the criterion's verdict for `auto`, "asked for" otherwise.
    pub reason: String,
    /// `Some` when the input was remeshed.
    pub remeshed: Option<RemeshOutcome>,
}

impl RemeshReport {
    /// The identity field of a remeshed input (`None` when the input was kept): the target
    /// length and options, so a resume with other remesh settings names what changed (the
    /// prepared mesh's hash changes too).
    pub fn identity_value(&self) -> Option<String> {
        self.remeshed.as_ref().map(|r| {
            format!(
                "edge length {:.6}, {} iterations, feature angle {}°",
                r.edge_length, r.options.iterations, r.options.feature_angle_deg
            )
        })
    }

    /// A warning for the run when `auto` advised remeshing but the remesher refused the mesh.
    pub fn warning(&self) -> Option<String> {
        (self.remeshed.is_none() && self.reason.contains("but not possible"))
            .then(|| self.reason.clone())
    }

    /// Lines for the start of a run.
    pub fn lines(&self) -> Vec<String> {
        match &self.remeshed {
            None => vec![format!(
                "mesh kept as it is (remesh {}: {})",
                self.setting, self.reason
            )],
            Some(r) => vec![
                format!(
                    "remeshed (remesh {}: {}) to edge length {:.4} in {:.1} s",
                    self.setting, self.reason, r.edge_length, r.seconds
                ),
                format!("  before: {}", quality_line(&self.before)),
                format!("  after:  {}", quality_line(&r.after)),
                format!(
                    "  Hausdorff distance to the input: {:.3} % / {:.3} % of the diagonal",
                    100.0 * r.hausdorff.a_to_b / self.before.diagonal,
                    100.0 * r.hausdorff.b_to_a / self.before.diagonal
                ),
            ],
        }
    }

    /// `run.json`'s `remesh` object.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "setting": self.setting.to_string(),
            "remeshed": self.remeshed.is_some(),
            "reason": self.reason,
            "before": quality_json(&self.before),
            "after": self.remeshed.as_ref().map(|r| quality_json(&r.after)),
            "edge_length": self.remeshed.as_ref().map(|r| r.edge_length),
            "iterations": self.remeshed.as_ref().map(|r| r.options.iterations),
            "feature_angle_deg": self.remeshed.as_ref().map(|r| r.options.feature_angle_deg),
            "hausdorff_out_to_in": self.remeshed.as_ref().map(|r| r.hausdorff.a_to_b),
            "hausdorff_in_to_out": self.remeshed.as_ref().map(|r| r.hausdorff.b_to_a),
            "seconds": self.remeshed.as_ref().map(|r| r.seconds),
        })
    }
}

/// The artifact measure of issue 40's end-to-end check (`docs/remeshing.md`, "End to end"): how
/// far a stylization pulled the triangulation it was given out of proportion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StretchedEdges {
    /// Distinct edges of the faces.
    pub edges: usize,
    /// Edges whose length in the result is more than [`STRETCH_LIMIT`]× or less than
    /// 1/[`STRETCH_LIMIT`]× their length in the rest mesh (a zero-length rest edge that got a
    /// length counts as stretched).
    pub stretched: usize,
    /// The largest ratio `max(r, 1/r)` over the edges, `r` = result length / rest length (1 when
    /// there is no edge).
    pub worst_ratio: f64,
}

impl StretchedEdges {
    /// `stretched / edges` (0 without edges).
    pub fn share(&self) -> f64 {
        if self.edges == 0 {
            0.0
        } else {
            self.stretched as f64 / self.edges as f64
        }
    }
}

/// An edge stretched or shrunk past this factor is an artifact ([`stretched_edges`]): the cube
/// style flattens and straightens, which keeps an even mesh's edges within it, while spikes and
/// crumples pull edges far past it.
pub const STRETCH_LIMIT: f64 = 2.0;

/// [`StretchedEdges`] of the deformation `rest → result` of `faces` (both in the same frame, e.g.
/// from [`crate::eval::load_run_pair`]: `deformation.npz`'s `verts` and `mesh.obj`).
pub fn stretched_edges(
    rest: &[[f64; 3]],
    result: &[[f64; 3]],
    faces: &[[u32; 3]],
) -> Result<StretchedEdges> {
    let n = rest.len();
    if result.len() != n {
        return Err(Error::Invalid(format!(
            "the result has {} vertices, the rest mesh {n}",
            result.len()
        )));
    }
    if let Some(f) = faces.iter().find(|f| f.iter().any(|&v| v as usize >= n)) {
        return Err(Error::Invalid(format!(
            "face {f:?} names a vertex beyond the {n} of the mesh"
        )));
    }
    let mut edges: Vec<[u32; 2]> = faces
        .iter()
        .flat_map(|f| [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]])
        .map(|[a, b]| [a.min(b), a.max(b)])
        .filter(|[a, b]| a != b)
        .collect();
    edges.sort_unstable();
    edges.dedup();
    let len = |p: &[[f64; 3]], [a, b]: [u32; 2]| {
        mesh_core::geometry::norm(mesh_core::geometry::sub(p[a as usize], p[b as usize]))
    };
    let (mut stretched, mut worst) = (0usize, 1.0f64);
    for &e in &edges {
        let (l0, l1) = (len(rest, e), len(result, e));
        let r = if l0 == l1 {
            1.0
        } else if l0 == 0.0 || l1 == 0.0 {
            f64::INFINITY
        } else {
            (l1 / l0).max(l0 / l1)
        };
        // NaN (a non-finite coordinate) counts as stretched too.
        if r > STRETCH_LIMIT || r.is_nan() {
            stretched += 1;
        }
        worst = worst.max(if r.is_nan() { f64::INFINITY } else { r });
    }
    Ok(StretchedEdges {
        edges: edges.len(),
        stretched,
        worst_ratio: worst,
    })
}

fn remesh_error(e: mesh_core::remesh::RemeshError) -> Error {
    Error::Invalid(format!(
        "cannot remesh the input: {e} (`--remesh off` keeps it as it is)"
    ))
}

/// Applies `setting` to a prepared mesh: the remeshed mesh (`None`: kept) and the report.
/// `on` and an edge length fail when the remesher refuses the mesh; `auto` keeps it then, with
/// the refusal in [`RemeshReport::reason`] (see [`RemeshReport::warning`]).
pub fn remesh_input(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    setting: RemeshSetting,
) -> Result<(Option<Remeshed>, RemeshReport)> {
    let before = mesh_core::remesh::quality(positions, faces).map_err(remesh_error)?;
    let (length, reason) = match setting {
        RemeshSetting::Off => (None, "asked for".to_string()),
        RemeshSetting::Auto => match remeshing_advised(&before) {
            Some(why) => (Some(DEFAULT_EDGE_LENGTH), why),
            None => (
                None,
                format!(
                    "even enough: edge-length std/mean {:.2} ≤ {ADVISED_ABOVE_EDGE_STD_OVER_MEAN}, \
                     {:.2} % of the faces with a corner under 10° ≤ {} %",
                    before.edge_std_over_mean(),
                    100.0 * before.share_below_10_deg,
                    100.0 * ADVISED_ABOVE_SHARE_BELOW_10_DEG
                ),
            ),
        },
        RemeshSetting::On => (Some(DEFAULT_EDGE_LENGTH), "asked for".to_string()),
        RemeshSetting::EdgeLength(l) => (Some(l), "asked for".to_string()),
    };
    let Some(length) = length else {
        return Ok((
            None,
            RemeshReport {
                setting,
                before,
                reason,
                remeshed: None,
            },
        ));
    };
    let start = Instant::now();
    let l = length.resolve(before.diagonal);
    let options = RemeshOptions::new(l);
    let out = match mesh_core::remesh::remesh(positions, faces, &options) {
        Ok(out) => out,
        // `auto` only advises: an input the remesher refuses (non-manifold, say) is used as it
        // is, as before remeshing existed, and the report says why (a warning of the run).
        Err(e) if setting == RemeshSetting::Auto => {
            return Ok((
                None,
                RemeshReport {
                    setting,
                    before,
                    reason: format!(
                        "remeshing advised ({reason}) but not possible: {e}; the input is used as it is"
                    ),
                    remeshed: None,
                },
            ));
        }
        Err(e) => return Err(remesh_error(e)),
    };
    let after = mesh_core::remesh::quality(&out.positions, &out.faces).map_err(remesh_error)?;
    let hausdorff = mesh_core::remesh::hausdorff(&out.positions, &out.faces, positions, faces)
        .map_err(remesh_error)?;
    let report = RemeshReport {
        setting,
        before,
        reason,
        remeshed: Some(RemeshOutcome {
            edge_length: l,
            options,
            after,
            hausdorff,
            seconds: start.elapsed().as_secs_f64(),
        }),
    };
    Ok((Some(out), report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::MeshSection;

    #[test]
    fn settings_parse_and_print_back() {
        for (text, want) in [
            ("auto", RemeshSetting::Auto),
            ("on", RemeshSetting::On),
            ("off", RemeshSetting::Off),
            (
                "0.03",
                RemeshSetting::EdgeLength(EdgeLength::Absolute(0.03)),
            ),
            (
                "1.5%",
                RemeshSetting::EdgeLength(EdgeLength::PercentOfDiagonal(1.5)),
            ),
        ] {
            let got: RemeshSetting = text.parse().unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(got, want);
            assert_eq!(got.to_string(), text);
        }
        for bad in [
            "", "yes", "0", "-1", "nan", "inf", "1e400", "101%", "%", "0%",
        ] {
            let e = bad
                .parse::<RemeshSetting>()
                .err()
                .unwrap_or_else(|| panic!("expected an error"));
            assert!(e.contains("auto"), "{bad}: {e}");
        }
    }

    #[test]
    fn the_section_reads_strings_and_numbers() {
        let s: MeshSection = toml::from_str("remesh = 0.05").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            s.remesh,
            RemeshSetting::EdgeLength(EdgeLength::Absolute(0.05))
        );
        let s: MeshSection = toml::from_str("remesh = \"2%\"").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            s.remesh,
            RemeshSetting::EdgeLength(EdgeLength::PercentOfDiagonal(2.0))
        );
        assert!(toml::from_str::<MeshSection>("remesh = \"sometimes\"").is_err());
        assert!(
            toml::to_string(&MeshSection::default())
                .unwrap_or_else(|e| panic!("{e}"))
                .lines()
                .any(|l| l == "remesh = \"auto\"")
        );
    }

    fn q(std_over_mean: f64, below10: f64) -> Quality {
        Quality {
            vertices: 10,
            faces: 10,
            edge_length_mean: 1.0,
            edge_length_std: std_over_mean,
            min_angle_deg: 20.0,
            share_below_10_deg: below10,
            share_below_30_deg: 0.5,
            share_valence_6: 0.5,
            diagonal: 10.0,
        }
    }

    #[test]
    fn stretched_edges_counts_ratios_past_two_either_way() {
        // Two triangles sharing edge (1, 2): five edges.
        let rest = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ];
        let faces = [[0, 1, 2], [1, 3, 2]];
        let same = stretched_edges(&rest, &rest, &faces).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((same.edges, same.stretched, same.worst_ratio), (5, 0, 1.0));
        // Vertex 3 pulled out to (4, 4, 0): edges (1, 3) and (2, 3) go from 1 to 5 (5×); scaling
        // everything by 1.9 stretches nothing, by 0.4 everything (2.5× shorter).
        let mut spike = rest;
        spike[3] = [4.0, 4.0, 0.0];
        let s = stretched_edges(&rest, &spike, &faces).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((s.edges, s.stretched), (5, 2));
        assert!((s.worst_ratio - 5.0).abs() < 1e-12 && (s.share() - 0.4).abs() < 1e-12);
        let scaled = |k: f64| rest.map(|p| p.map(|c| c * k));
        let s = stretched_edges(&rest, &scaled(1.9), &faces).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s.stretched, 0);
        let s = stretched_edges(&rest, &scaled(0.4), &faces).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s.stretched, 5);
        assert!(stretched_edges(&rest, &rest[..3], &faces).is_err());
        assert!(stretched_edges(&rest, &rest, &[[0, 1, 9]]).is_err());
    }

    #[test]
    fn the_criterion_has_two_independent_thresholds() {
        assert_eq!(remeshing_advised(&q(0.4, 0.01)), None);
        assert!(
            remeshing_advised(&q(0.41, 0.0))
                .unwrap_or_default()
                .contains("std/mean")
        );
        assert!(
            remeshing_advised(&q(0.1, 0.011))
                .unwrap_or_default()
                .contains("10°")
        );
    }

    #[test]
    fn auto_keeps_an_even_mesh_and_off_never_remeshes() {
        let m = mesh_core::shapes::icosphere(2);
        let (p, f) = (m.positions, m.faces);
        for s in [RemeshSetting::Auto, RemeshSetting::Off] {
            let (out, report) = remesh_input(&p, &f, s).unwrap_or_else(|e| panic!("{e}"));
            assert!(
                out.is_none() && report.remeshed.is_none() && report.identity_value().is_none()
            );
        }
        let (out, report) =
            remesh_input(&p, &f, RemeshSetting::On).unwrap_or_else(|e| panic!("{e}"));
        let out = out.unwrap_or_else(|| panic!("remeshed"));
        let r = report
            .remeshed
            .as_ref()
            .unwrap_or_else(|| panic!("remeshed"));
        assert!((r.edge_length - 0.015 * report.before.diagonal).abs() < 1e-15);
        assert_eq!(r.after.faces, out.faces.len());
        assert!(
            report
                .identity_value()
                .unwrap_or_default()
                .contains("10 iterations")
        );
    }

    #[test]
    fn auto_remeshes_needles_and_errors_name_the_way_out() {
        // A strip of needle triangles: every face has a corner far under 10°.
        let mut p = Vec::new();
        let mut f = Vec::new();
        for i in 0..20u32 {
            p.push([f64::from(i) * 0.05, 0.0, 0.0]);
            p.push([f64::from(i) * 0.05, 1.0, 0.0]);
            if i > 0 {
                let (a, b, c, d) = (2 * i - 2, 2 * i - 1, 2 * i, 2 * i + 1);
                f.push([a, c, d]);
                f.push([a, d, b]);
            }
        }
        let (out, report) =
            remesh_input(&p, &f, RemeshSetting::Auto).unwrap_or_else(|e| panic!("{e}"));
        assert!(out.is_some(), "{}", report.reason);
        assert!(report.reason.contains("under 10°"), "{}", report.reason);
        // A fin (three faces on one edge) the remesher refuses: `auto` keeps the mesh and warns,
        // `on` fails.
        let mut fin_p = p.clone();
        fin_p.push([0.0, 0.5, 1.0]);
        let mut fin_f = f.clone();
        fin_f.push([0, 3, 40]);
        let (kept, report) =
            remesh_input(&fin_p, &fin_f, RemeshSetting::Auto).unwrap_or_else(|e| panic!("{e}"));
        assert!(kept.is_none());
        let w = report.warning().unwrap_or_default();
        assert!(w.contains("non-manifold"), "{w}");
        assert!(remesh_input(&fin_p, &fin_f, RemeshSetting::On).is_err());
        let e = remesh_input(
            &p,
            &f,
            RemeshSetting::EdgeLength(EdgeLength::Absolute(1e-6)),
        )
        .err()
        .unwrap_or_else(|| panic!("expected an error"));
        let m = e.to_string();
        assert!(m.contains("faces") && m.contains("--remesh off"), "{m}");
    }
}
