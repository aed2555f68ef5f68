//! λ sanity: how far one re-application of a saved deformation at strength λ moved away from the
//! source's identity, and whether it is collapsing.
//!
//! For the rest mesh (normalized to the side-2 cube) and the dARAP result at λ:
//! - **flipped fraction**: the share of vertices whose local-step rotation `R_v` turns by more than
//!   90°, i.e. `tr R_v < 1` (the rotation angle θ satisfies `tr R = 1 + 2 cos θ`). Under the
//!   reference ("gis") rule rotations grow quickly with λ and past λ ≈ 10 some vertices flip by
//!   ~180° (spec §3.3); a flipped one-ring turns its neighbourhood inside out. Masked vertices keep
//!   `R = I` and never count as flipped.
//! - **volume ratio** and **face-area ratio** (mean and population standard deviation over faces):
//!   the identity metrics of spec §9, computed exactly as `stylize eval` does
//!   ([`stylize::eval::pair_ratios`]: the result recentred and rescaled to the source's bounding-box
//!   diagonal).
//!
//! - **self-intersections** ([`stylize::intersections`], exact): the result's intersecting face
//!   pairs and faces, and the **new** pairs — those the source does not have.
//!
//! [`LambdaSanity::warnings`] names each symptom of a collapsing result: a volume ratio below
//! [`COLLAPSE_VOLUME_RATIO`] (or above its inverse), more than [`FLIPPED_WARN_FRACTION`] of the
//! vertices flipped, a mean face-area ratio below [`COLLAPSE_AREA_RATIO`], or new
//! self-intersections. A result is **safe** ([`LambdaSanity::is_safe`]) when it has none of them;
//! `apply --lambda max-safe` searches the largest such λ.

use darap::Deformation;
use mesh_core::TriMesh;
use serde::Serialize;
use stylize::intersections::{IntersectionFigures, SourceIntersections};

/// A volume ratio below this (or above its inverse) is reported as collapsing (or inflating).
pub const COLLAPSE_VOLUME_RATIO: f64 = 0.5;
/// A mean face-area ratio below this is reported as shrinking.
pub const COLLAPSE_AREA_RATIO: f64 = 0.5;
/// More than this fraction of flipped vertices (rotation angle > 90°) is reported.
pub const FLIPPED_WARN_FRACTION: f64 = 0.01;

/// Diagnostics of the result at one strength λ (see the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LambdaSanity {
    /// The strength.
    pub lambda: f64,
    /// For a result of the strength control (`apply --strength`): its strength `s` (the result at
    /// `lambda` pushed `s` times as far; `docs/strength.md`). The lines then name `s`, not λ.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub strength: Option<f64>,
    /// Vertices whose rotation angle exceeds 90° (`tr R_v < 1`).
    pub flipped: usize,
    /// `flipped / vertices`.
    pub flipped_fraction: f64,
    /// Signed volume ratio result/source (NaN for a source of zero volume, e.g. an open sheet).
    pub volume_ratio: f64,
    /// Mean per-face area ratio result/source.
    pub area_ratio_mean: f64,
    /// Population standard deviation of the per-face area ratios.
    pub area_ratio_std: f64,
    /// Self-intersections of the result, and those new against the source.
    pub intersections: IntersectionFigures,
    /// The result's intersecting faces, sorted (for highlighting; not serialized).
    #[serde(skip)]
    pub intersecting_faces: Vec<u32>,
    /// The faces of the new pairs, sorted (not serialized).
    #[serde(skip)]
    pub new_intersecting_faces: Vec<u32>,
}

/// Whether a rotation (a proper 3×3 rotation, applied as `R·x`) turns by more than 90°.
pub fn is_flipped(r: &[[f64; 3]; 3]) -> bool {
    r[0][0] + r[1][1] + r[2][2] < 1.0
}

impl LambdaSanity {
    /// Diagnostics of `deformation` (the dARAP result at `lambda`) of the rest mesh `rest`;
    /// `source` is `rest` checked for self-intersections (built once, refitted per call).
    pub fn assess(
        rest: &TriMesh,
        source: &mut SourceIntersections,
        deformation: &Deformation,
        lambda: f64,
    ) -> anyhow::Result<Self> {
        let result = TriMesh::new(deformation.positions.clone(), rest.faces.clone());
        let (ratios, _skipped, volume_ratio) = stylize::eval::pair_ratios(rest, &result)?;
        let n = ratios.len().max(1) as f64;
        let mean = ratios.iter().sum::<f64>() / n;
        let var = ratios.iter().map(|r| (r - mean) * (r - mean)).sum::<f64>() / n;
        let flipped = deformation
            .rotations
            .iter()
            .filter(|r| is_flipped(r))
            .count();
        let checked = source.check(&deformation.positions)?;
        Ok(Self {
            lambda,
            strength: None,
            flipped,
            flipped_fraction: flipped as f64 / deformation.rotations.len().max(1) as f64,
            volume_ratio,
            area_ratio_mean: mean,
            area_ratio_std: var.sqrt(),
            intersections: checked.figures,
            intersecting_faces: checked.faces,
            new_intersecting_faces: checked.new_faces,
        })
    }

    /// Safe: no warning (no collapse, inflation, shrinking, flips over the limit, or new
    /// self-intersections).
    pub fn is_safe(&self) -> bool {
        self.problems().is_empty()
    }

    /// The same diagnostics, labelled as a result of the strength control at `strength` (the
    /// result at `self.lambda` pushed `strength` times as far).
    pub fn with_strength(mut self, strength: f64) -> Self {
        self.strength = Some(strength);
        self
    }

    /// What the lines call the result: `λ = 8`, or `strength 1.5 (λ = 8)`.
    fn label(&self) -> String {
        match self.strength {
            None => format!("λ = {}", self.lambda),
            Some(s) => format!("strength {s} (λ = {})", self.lambda),
        }
    }

    /// The advice that ends a warning.
    fn advice(&self) -> &'static str {
        match self.strength {
            None => "try a smaller λ",
            Some(_) => "try a smaller strength",
        }
    }

    /// One line: `λ = 8: volume ratio 0.93, face-area ratio 0.98 ± 0.21, 0.0% of vertices
    /// flipped (rotation > 90°), self-intersections: 0 pairs (0 faces), 0 new`.
    pub fn summary(&self) -> String {
        format!(
            "{}: volume ratio {:.3}, face-area ratio {:.3} ± {:.3}, {:.1}% of vertices flipped (rotation > 90°), {}",
            self.label(),
            self.volume_ratio,
            self.area_ratio_mean,
            self.area_ratio_std,
            100.0 * self.flipped_fraction,
            self.intersections.summary()
        )
    }

    /// The symptoms of a collapsing result, each as one sentence labelled with the setting and
    /// ending in advice (empty when none): [`Self::problems`] as warning lines.
    pub fn warnings(&self) -> Vec<String> {
        self.problems()
            .into_iter()
            .map(|p| format!("{}: {p}; {}", self.label(), self.advice()))
            .collect()
    }

    /// The symptoms alone, without the setting's label or advice (empty when safe).
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        let v = self.volume_ratio;
        if v.is_finite() && v < COLLAPSE_VOLUME_RATIO {
            out.push(format!(
                "the result is collapsing: volume ratio {v:.3} (below {COLLAPSE_VOLUME_RATIO})"
            ));
        } else if v.is_finite() && v > 1.0 / COLLAPSE_VOLUME_RATIO {
            out.push(format!(
                "the result is inflating: volume ratio {v:.3} (above {})",
                1.0 / COLLAPSE_VOLUME_RATIO
            ));
        }
        if self.area_ratio_mean < COLLAPSE_AREA_RATIO {
            out.push(format!(
                "faces are shrinking: mean face-area ratio {:.3} (below {COLLAPSE_AREA_RATIO})",
                self.area_ratio_mean
            ));
        }
        if self.flipped_fraction > FLIPPED_WARN_FRACTION {
            out.push(format!(
                "{:.1}% of the vertices' rotations flipped (> 90°; the reference rule's behaviour at large λ)",
                100.0 * self.flipped_fraction
            ));
        }
        if let Some(w) = self.intersections.warning() {
            out.push(w);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sanity(volume_ratio: f64, area: f64, flipped_fraction: f64) -> LambdaSanity {
        LambdaSanity {
            lambda: 3.0,
            strength: None,
            flipped: 0,
            flipped_fraction,
            volume_ratio,
            area_ratio_mean: area,
            area_ratio_std: 0.1,
            intersections: IntersectionFigures::default(),
            intersecting_faces: Vec::new(),
            new_intersecting_faces: Vec::new(),
        }
    }

    #[test]
    fn a_strength_result_names_its_strength_and_asks_for_a_smaller_one() {
        let plain = sanity(0.3, 1.0, 0.0);
        assert!(plain.summary().starts_with("λ = 3: volume ratio"));
        assert!(plain.warnings()[0].ends_with("try a smaller λ"));
        let strong = plain.with_strength(1.5);
        assert!(
            strong
                .summary()
                .starts_with("strength 1.5 (λ = 3): volume ratio")
        );
        let w = strong.warnings();
        assert!(w[0].starts_with("strength 1.5 (λ = 3): the result is collapsing"));
        assert!(w[0].ends_with("try a smaller strength"));
    }

    #[test]
    fn flipped_means_rotation_angle_beyond_ninety_degrees() {
        let rot_z = |deg: f64| {
            let (s, c) = deg.to_radians().sin_cos();
            [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
        };
        assert!(!is_flipped(&rot_z(0.0)));
        assert!(!is_flipped(&rot_z(89.0)));
        assert!(is_flipped(&rot_z(91.0)));
        assert!(is_flipped(&rot_z(180.0)));
        assert!(is_flipped(&rot_z(-120.0)));
    }

    #[test]
    fn warnings_name_each_symptom_and_stay_quiet_when_healthy() {
        assert!(sanity(0.95, 0.97, 0.0).warnings().is_empty());
        let w = sanity(0.041, 0.97, 0.0).warnings();
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].contains("collapsing") && w[0].contains("0.041"),
            "{w:?}"
        );
        assert!(sanity(2.5, 1.0, 0.0).warnings()[0].contains("inflating"));
        assert!(sanity(1.0, 0.3, 0.0).warnings()[0].contains("shrinking"));
        assert!(sanity(1.0, 1.0, 0.2).warnings()[0].contains("20.0%"));
        // An open sheet has no volume: no volume verdict, no panic.
        assert!(sanity(f64::NAN, 1.0, 0.0).warnings().is_empty());
        assert!(sanity(0.95, 0.97, 0.0).is_safe());
        let mut crossing = sanity(0.95, 0.97, 0.0);
        crossing.intersections.new_pairs = 3;
        crossing.intersections.new_faces = 5;
        let w = crossing.warnings();
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].contains("3 new self-intersecting face pairs (5 faces)"),
            "{w:?}"
        );
        assert!(!crossing.is_safe());
    }
}
