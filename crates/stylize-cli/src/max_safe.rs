//! The strongest safe λ (`stylize apply SAVED --lambda max-safe[:UPPER]`, the viewer's button):
//! the largest λ below the first λ > 0 at which the re-applied result stops being safe
//! ([`crate::sanity::LambdaSanity::is_safe`]: new self-intersections, flips, volume, face area).
//!
//! Safety need not be monotone in λ (a fold can open and close again), so nothing assumes it:
//! 1. **Scan** λ = 0 and the grid `UPPER·i/STEPS`, `i = 1..=STEPS` ([`SCAN_STEPS`]), every point;
//! 2. **refine** the first crossing — the last safe grid point `lo` and the first unsafe one `hi`
//!    — by bisection, keeping `lo` safe and `hi` unsafe, until `hi − lo ≤ 1 % · lo`
//!    ([`RELATIVE_TOLERANCE`]);
//! 3. report every grid point after the crossing that is **safe again** (safety is then not
//!    monotone over the scan, and the answer is the first crossing, not the last).
//!
//! An unsafe stretch narrower than one grid step (`UPPER / STEPS`) can be missed by the scan; the
//! result is then still safe, but not the first crossing. The work is bounded: `STEPS + 1`
//! evaluations for the scan and at most [`MAX_BISECTIONS`] for the refinement.

/// Grid points of the scan above 0.
pub const SCAN_STEPS: usize = 32;
/// The refinement stops when the bracket is this narrow relative to its safe end.
pub const RELATIVE_TOLERANCE: f64 = 0.01;
/// The most bisection steps (reached only when the first grid point is unsafe and no λ > 0 is
/// safe: the bracket then shrinks towards 0 by 2⁻⁴⁰ of one grid step).
pub const MAX_BISECTIONS: usize = 40;

/// What the search found.
#[derive(Clone, Debug, PartialEq)]
pub struct SafeLambda {
    /// The answer: the largest λ found safe below the first crossing (UPPER when the whole scan
    /// is safe; 0 when no λ > 0 was found safe).
    pub lambda: f64,
    /// The unsafe end of the final bracket (None when the whole scan is safe):
    /// `lambda < first_unsafe ≤ lambda · (1 + RELATIVE_TOLERANCE)` unless `lambda` is 0.
    pub first_unsafe: Option<f64>,
    /// Grid points after the first crossing that are safe again (empty: monotone over the scan).
    pub safe_again: Vec<f64>,
    /// Evaluations made.
    pub evaluations: usize,
}

/// Searches the first crossing in `(0, upper]` (see the module documentation). `is_safe(λ)`
/// evaluates one λ; an error there ends the search with that error. Refuses an `upper` that is
/// not finite and positive, and a result unsafe at λ = 0 (no normal term: under the `gis` rule
/// not always the source, see the error).
pub fn search(
    upper: f64,
    mut is_safe: impl FnMut(f64) -> anyhow::Result<bool>,
) -> anyhow::Result<SafeLambda> {
    anyhow::ensure!(
        upper.is_finite() && upper > 0.0,
        "max-safe: the upper end λ must be a finite number > 0, got {upper}"
    );
    let mut evaluations = 0usize;
    let mut eval = |l: f64| -> anyhow::Result<bool> {
        evaluations += 1;
        is_safe(l)
    };
    anyhow::ensure!(
        eval(0.0)?,
        "max-safe: no λ is safe: even at λ = 0 (no normal term) the result fails the safety checks"
    );
    let grid: Vec<f64> = (1..=SCAN_STEPS)
        .map(|i| upper * i as f64 / SCAN_STEPS as f64)
        .collect();
    let mut safe = Vec::with_capacity(grid.len());
    for &l in &grid {
        safe.push(eval(l)?);
    }
    let Some(k) = safe.iter().position(|s| !s) else {
        return Ok(SafeLambda {
            lambda: upper,
            first_unsafe: None,
            safe_again: Vec::new(),
            evaluations,
        });
    };
    let safe_again: Vec<f64> = grid[k + 1..]
        .iter()
        .zip(&safe[k + 1..])
        .filter(|(_, s)| **s)
        .map(|(l, _)| *l)
        .collect();
    let (mut lo, mut hi) = (if k == 0 { 0.0 } else { grid[k - 1] }, grid[k]);
    for _ in 0..MAX_BISECTIONS {
        if lo > 0.0 && hi - lo <= RELATIVE_TOLERANCE * lo {
            break;
        }
        let mid = 0.5 * (lo + hi);
        if eval(mid)? {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(SafeLambda {
        lambda: lo,
        first_unsafe: Some(hi),
        safe_again,
        evaluations,
    })
}

/// [`search`] over each λ's sanity (`assess(λ)`), keeping the problems of every unsafe λ so that
/// reports and errors say why. A result unsafe already at λ = 0 is refused with its problems and
/// what causes them.
pub fn search_assessed(
    upper: f64,
    mut assess: impl FnMut(f64) -> anyhow::Result<crate::sanity::LambdaSanity>,
) -> anyhow::Result<Assessed> {
    let mut unsafe_problems: Vec<(f64, Vec<String>)> = Vec::new();
    let mut at_zero: Option<crate::sanity::LambdaSanity> = None;
    let searched = search(upper, |lambda| {
        let s = assess(lambda)?;
        let problems = s.problems();
        let safe = problems.is_empty();
        if !safe {
            unsafe_problems.push((lambda, problems));
        }
        if lambda == 0.0 {
            at_zero = Some(s);
        }
        Ok(safe)
    });
    match (searched, at_zero) {
        (Ok(found), _) => Ok(Assessed {
            found,
            unsafe_problems,
        }),
        (Err(_), Some(zero)) if !zero.is_safe() => Err(unsafe_at_zero(&zero)),
        (Err(e), _) => Err(e),
    }
}

/// The error for a result that is unsafe at λ = 0 (no normal term): the problems, and where each
/// kind comes from (the source's own intersections; the `gis` rule's rotations beside obtuse
/// triangles).
fn unsafe_at_zero(zero: &crate::sanity::LambdaSanity) -> anyhow::Error {
    let mut causes = Vec::new();
    if zero.flipped > 0 {
        causes.push(format!(
            "{} vert{} rotate{} by more than 90° without any target normal: under the `gis` rule \
             a vertex whose spokes and rims have negative cotangent weights (beside obtuse or \
             needle triangles) can, so a λ = 0 result need not be the source; an input with \
             better-shaped triangles (`--remesh on`, or a smaller `--remesh` edge length) has \
             fewer such vertices",
            zero.flipped,
            if zero.flipped == 1 { "ex" } else { "ices" },
            if zero.flipped == 1 { "s" } else { "" },
        ));
    }
    let f = &zero.intersections;
    if f.new_pairs > 0 && f.source_pairs > 0 {
        causes.push(format!(
            "the source intersects itself ({} pair{}): beside its own intersections a small \
             movement can make pairs it does not have; repairing the source mesh removes them",
            f.source_pairs,
            if f.source_pairs == 1 { "" } else { "s" }
        ));
    }
    let mut msg = format!(
        "max-safe: no λ is safe: even at λ = 0 (no normal term) the result fails the safety \
         checks: {}",
        zero.problems().join("; ")
    );
    if !causes.is_empty() {
        msg.push_str(&format!(". Why: {}", causes.join("; ")));
    }
    anyhow::anyhow!(msg)
}

/// What [`search_assessed`] found: the answer and the problems of every λ found unsafe.
#[derive(Clone, Debug)]
pub struct Assessed {
    /// The answer.
    pub found: SafeLambda,
    /// Each unsafe λ evaluated, with its problems ([`crate::sanity::LambdaSanity::problems`]).
    pub unsafe_problems: Vec<(f64, Vec<String>)>,
}

impl Assessed {
    /// The problems at `lambda` (empty when it was not found unsafe).
    pub fn problems_at(&self, lambda: f64) -> &[String] {
        self.unsafe_problems
            .iter()
            .find(|(l, _)| *l == lambda)
            .map_or(&[], |(_, p)| p.as_slice())
    }
}

/// The end of a run: when the result at the run's λ is not safe, one line with the strongest safe
/// λ below it (None when the result is safe — the common case costs one evaluation — or the run
/// saved no usable λ). Reads the run's `deformation.npz` (with its saved region) as `apply` does.
pub fn end_of_run(run_dir: &std::path::Path) -> anyhow::Result<Option<String>> {
    let npz = run_dir.join("deformation.npz");
    let saved = stylize::saved::SavedDeformation::read(&npz)?;
    let Ok(lambda) = saved.recorded_lambda() else {
        return Ok(None);
    };
    if lambda <= 0.0 {
        return Ok(None);
    }
    let mut ready = saved.ready_layer_as_saved(&npz)?;
    let mut source = stylize::intersections::SourceIntersections::new(&ready.rest)?;
    let mut assess = |l: f64| -> anyhow::Result<crate::sanity::LambdaSanity> {
        let d = ready.at_lambda(l)?;
        crate::sanity::LambdaSanity::assess(&ready.rest, &mut source, &d, l)
    };
    if assess(lambda)?.is_safe() {
        return Ok(None);
    }
    let found = search_assessed(lambda, assess)?.found;
    Ok(Some(format!(
        "the result at the run's λ = {lambda} is not safe (see the warnings); the strongest safe λ \
         up to it is {} — `stylize apply {} -o OUT.obj --lambda max-safe` writes it",
        found.lambda,
        npz.display()
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sanity::LambdaSanity;

    fn ok(r: anyhow::Result<SafeLambda>) -> SafeLambda {
        r.unwrap_or_else(|e| panic!("{e:#}"))
    }

    fn refused(r: anyhow::Result<SafeLambda>) -> String {
        match r {
            Ok(f) => panic!("accepted: {f:?}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn one_crossing_is_found_within_one_percent() {
        for crossing in [0.3, 4.9, 7.77, 9.99] {
            let r = ok(search(10.0, |l| Ok(l < crossing)));
            assert!(r.lambda < crossing, "{r:?}");
            let hi = r.first_unsafe.unwrap_or(f64::NAN);
            assert!(hi >= crossing && hi - r.lambda <= 0.01 * r.lambda, "{r:?}");
            assert!(r.lambda * 1.01 >= crossing, "{r:?}");
            assert!(r.safe_again.is_empty());
            assert!(r.evaluations <= 1 + SCAN_STEPS + MAX_BISECTIONS);
        }
    }

    #[test]
    fn two_crossings_give_the_first_and_say_it_is_not_monotone() {
        // Unsafe on [3, 4.5), safe again on [4.5, 8), unsafe from 8.
        let r = ok(search(10.0, |l| Ok(!(3.0..4.5).contains(&l) && l < 8.0)));
        assert!(r.lambda < 3.0 && r.lambda * 1.01 >= 3.0, "{r:?}");
        assert!(!r.safe_again.is_empty(), "{r:?}");
        assert!(r.safe_again.iter().all(|l| (4.5..8.0).contains(l)), "{r:?}");
    }

    #[test]
    fn all_safe_returns_the_upper_end_and_nothing_safe_returns_zero() {
        let r = ok(search(6.0, |_| Ok(true)));
        assert_eq!((r.lambda, r.first_unsafe), (6.0, None));
        assert_eq!(r.evaluations, 1 + SCAN_STEPS);
        let r = ok(search(6.0, |l| Ok(l == 0.0)));
        assert_eq!(r.lambda, 0.0);
        assert!(r.first_unsafe.is_some_and(|hi| hi > 0.0), "{r:?}");
        assert_eq!(r.evaluations, 1 + SCAN_STEPS + MAX_BISECTIONS);
    }

    #[test]
    fn bad_upper_ends_and_unsafe_sources_are_refused() {
        for upper in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(search(upper, |_| Ok(true)).is_err(), "{upper}");
        }
        let e = refused(search(5.0, |_| Ok(false)));
        assert!(e.contains("λ = 0"), "{e}");
        let e = refused(search(5.0, |l| {
            anyhow::ensure!(l < 2.0, "boom");
            Ok(true)
        }));
        assert_eq!(e, "boom");
    }

    /// A sanity with `flipped` of 100 vertices flipped, and `new_pairs` pairs the source (with
    /// `source_pairs`) does not have.
    fn sanity(lambda: f64, flipped: usize, new_pairs: usize, source_pairs: usize) -> LambdaSanity {
        LambdaSanity {
            lambda,
            strength: None,
            flipped,
            flipped_fraction: flipped as f64 / 100.0,
            volume_ratio: 1.0,
            area_ratio_mean: 1.0,
            area_ratio_std: 0.0,
            intersections: stylize::intersections::IntersectionFigures {
                source_pairs,
                source_faces: source_pairs,
                pairs: source_pairs + new_pairs,
                faces: source_pairs + new_pairs,
                new_pairs,
                new_faces: 2 * new_pairs,
            },
            intersecting_faces: Vec::new(),
            new_intersecting_faces: Vec::new(),
        }
    }

    #[test]
    fn an_assessed_search_keeps_why_each_lambda_was_unsafe() {
        let r = search_assessed(10.0, |l| Ok(sanity(l, usize::from(l >= 4.0) * 5, 0, 0)))
            .unwrap_or_else(|e| panic!("{e:#}"));
        let hi = r.found.first_unsafe.unwrap_or(f64::NAN);
        assert!(hi >= 4.0 && r.found.lambda < 4.0, "{:?}", r.found);
        let why = r.problems_at(hi);
        assert!(why.len() == 1 && why[0].contains("5.0%"), "{why:?}");
        assert!(r.problems_at(1.0).is_empty());
    }

    fn refused_assessed(r: anyhow::Result<Assessed>) -> String {
        match r {
            Ok(a) => panic!("accepted: {:?}", a.found),
            Err(e) => format!("{e:#}"),
        }
    }

    #[test]
    fn unsafe_at_zero_says_what_and_why() {
        // Flips at λ = 0: the `gis` rule beside obtuse triangles.
        let e = refused_assessed(search_assessed(5.0, |l| Ok(sanity(l, 3, 0, 0))));
        assert!(e.contains("λ = 0") && e.contains("3.0%"), "{e}");
        assert!(
            e.contains("3 vertices rotate") && e.contains("negative cotangent"),
            "{e}"
        );
        assert!(!e.contains("intersects itself"), "{e}");
        // New pairs at λ = 0 beside the source's own: no word of remeshing or flips.
        let e = refused_assessed(search_assessed(5.0, |l| Ok(sanity(l, 0, 1, 95))));
        assert!(e.contains("1 new self-intersecting face pair"), "{e}");
        assert!(e.contains("the source intersects itself (95 pairs)"), "{e}");
        assert!(!e.contains("rotate") && !e.contains("remesh on"), "{e}");
        // An error of the evaluation itself is passed on as it is.
        let e = refused_assessed(search_assessed(5.0, |l| {
            anyhow::ensure!(l < 2.0, "boom");
            Ok(sanity(l, 0, 0, 0))
        }));
        assert_eq!(e, "boom");
    }
}
