//! Finite-difference gradient checks of every hand-written adjoint.
//!
//! Each check is a scalar loss ℓ(θ) = ⟨g, f(θ)⟩ with a fixed random cotangent g, so the hand-written
//! VJP gives ∇ℓ = J_fᵀ g. For several random unit directions d we compare ⟨∇ℓ, d⟩ with the central
//! difference (ℓ(θ + h d) − ℓ(θ − h d)) / 2h in f64. A direction passes when
//! `|fd − an| ≤ atol + rtol · max(|fd|, |an|)`. Every mismatch is collected and reported together;
//! the command exits non-zero if any check fails.

mod cotan;
mod csd;
mod darap;

mod raster;
mod style;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Tolerances and step of one check.
#[derive(Clone, Copy, Debug)]
pub struct Tolerance {
    /// Central-difference step.
    pub step: f64,
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance.
    pub atol: f64,
    /// Number of random directions.
    pub directions: usize,
}

impl Default for Tolerance {
    fn default() -> Self {
        Self {
            step: 1e-6,
            rtol: 1e-5,
            atol: 1e-9,
            directions: 4,
        }
    }
}

/// Outcome of one named check.
#[derive(Debug)]
pub struct CheckResult {
    pub name: String,
    pub worst_rel: f64,
    pub failures: Vec<String>,
}

/// Collects results of many checks.
#[derive(Debug, Default)]
pub struct Report {
    pub results: Vec<CheckResult>,
}

impl Report {
    /// Checks a VJP: `loss(θ)` is the scalar ⟨g, f(θ)⟩ and `grad` is the hand-written ∇ℓ at `theta`.
    pub fn check(
        &mut self,
        name: &str,
        theta: &[f64],
        grad: &[f64],
        tol: Tolerance,
        seed: u64,
        mut loss: impl FnMut(&[f64]) -> f64,
    ) {
        assert_eq!(theta.len(), grad.len(), "{name}: gradient length mismatch");
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut failures = Vec::new();
        let mut worst_rel: f64 = 0.0;
        for k in 0..tol.directions {
            let mut d: Vec<f64> = (0..theta.len())
                .map(|_| rng.random::<f64>() * 2.0 - 1.0)
                .collect();
            let norm = d.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
            d.iter_mut().for_each(|v| *v /= norm);
            let shifted =
                |s: f64| -> Vec<f64> { theta.iter().zip(&d).map(|(t, di)| t + s * di).collect() };
            let fd = (loss(&shifted(tol.step)) - loss(&shifted(-tol.step))) / (2.0 * tol.step);
            let an: f64 = grad.iter().zip(&d).map(|(g, di)| g * di).sum();
            let err = (fd - an).abs();
            let scale = fd.abs().max(an.abs());
            let rel = if scale > 0.0 { err / scale } else { 0.0 };
            if !fd.is_finite() || !an.is_finite() || err > tol.atol + tol.rtol * scale {
                failures.push(format!(
                    "direction {k}: finite difference {fd:.9e}, adjoint {an:.9e}, |diff| {err:.3e}"
                ));
            }
            if err > tol.atol {
                worst_rel = worst_rel.max(rel);
            }
        }
        self.results.push(CheckResult {
            name: name.to_string(),
            worst_rel,
            failures,
        });
    }

    /// Records a failure that is not a finite-difference mismatch (e.g. a NaN in a degenerate case).
    pub fn fail(&mut self, name: &str, why: String) {
        self.results.push(CheckResult {
            name: name.to_string(),
            worst_rel: f64::NAN,
            failures: vec![why],
        });
    }

    fn finish(&self) -> anyhow::Result<()> {
        let mut failed = 0;
        for r in &self.results {
            let status = if r.failures.is_empty() {
                "ok  "
            } else {
                "FAIL"
            };
            println!(
                "{status} {:<60} worst rel. error {:.2e}",
                r.name, r.worst_rel
            );
            for f in &r.failures {
                println!("       {f}");
            }
            failed += usize::from(!r.failures.is_empty());
        }
        println!(
            "gradcheck: {} passed, {} failed",
            self.results.len() - failed,
            failed
        );
        anyhow::ensure!(failed == 0, "{failed} gradient check(s) failed");
        Ok(())
    }
}

/// A suite of checks: registers its results in the report.
type Suite = fn(&mut Report) -> anyhow::Result<()>;

/// Runs every check whose name contains `filter` (all when `None`).
pub fn run(filter: Option<&str>) -> anyhow::Result<()> {
    let mut report = Report::default();
    let suites: &[(&str, Suite)] = &[
        // Each crate's checks live in a sibling module and register here.
        ("raster", raster::suite),
        ("csd", csd::suite),
        ("cotan", cotan::suite),
        ("darap", darap::suite),
        ("style", style::suite),
    ];
    for (name, suite) in suites {
        if filter.is_none_or(|f| name.contains(f)) {
            suite(&mut report)?;
        }
    }
    anyhow::ensure!(
        !report.results.is_empty(),
        "no gradient check matched the filter"
    );
    report.finish()
}
