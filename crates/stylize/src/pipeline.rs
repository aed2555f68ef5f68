//! The optimization loop (spec §5), shared by the text path and the model-free path.
//!
//! Per iteration `i` (1-indexed): `dARAP forward(x)` once, then `steps_per_batch` sub-steps. Sub-step
//! `s` asks the [`Objective`] for `∂ℓ_s/∂positions` at the **same** deformed mesh (for the text path:
//! the same renders, fresh timesteps and noise), maps it through the dARAP adjoint to `g_s`, adds it
//! to the accumulated gradient `G ← G + g_s`, and takes an Adam step with `G`. With the reference's
//! two steps: step 1 uses `g1`, step 2 uses `g1 + g2`, both evaluated at the pre-step `x` (spec §5,
//! `n_accum = 2`). Adam's step counter therefore advances by `steps_per_batch` per iteration.
//!
//! Since every sub-step sees the same deformed mesh, the loop asks for all of an iteration's
//! `∂ℓ_s/∂positions` at once ([`Objective::evaluate_batch`]) before its first Adam step: the text
//! objective then runs the guidance for every sub-step on one encoding of the renders and maps the
//! image gradients back in one renderer pass. The dARAP backward passes of the sub-steps are
//! independent too (same deformation) and run together; the Adam steps come after all of them,
//! so an error in any sub-step's objective or dARAP backward leaves `x` untouched.
//!
//! Everything random (views, lights, timesteps, noise) comes from one `ChaCha8Rng` that is saved
//! in checkpoints, so a resumed run continues bit-identically.

use std::time::Instant;

use crate::error::{Context, Result, invalid};
use csd::Guidance;
use darap::Darap;
use optim::Adam;
use rand_chacha::ChaCha8Rng;
use raster_diff::{CameraConfig, Images, Renderer};
use rayon::prelude::*;

use crate::style::{Style, alignment};

/// What one sub-step's objective evaluation returns.
#[derive(Clone, Debug, Default)]
pub struct StepEval {
    /// Named scalar terms for `metrics.jsonl` (e.g. `loss`, `loss_stage1`, `stage2_weight`).
    pub terms: Vec<(&'static str, f64)>,
    /// Named wall-clock timings in seconds (e.g. `render`, `guidance`).
    pub timings: Vec<(&'static str, f64)>,
    /// `∂ℓ/∂positions` of the deformed mesh, one row per vertex.
    pub grad_positions: Vec<[f64; 3]>,
}

/// A loss on the deformed mesh, evaluated at sub-step `substep` of `iteration`.
pub trait Objective {
    /// Short description for logs.
    fn describe(&self) -> String;
    /// Evaluates the loss gradient at the deformed positions. Sub-step 0 of an iteration sees a new
    /// `deformed`; later sub-steps of the same iteration see the same positions again.
    fn evaluate(
        &mut self,
        iteration: u64,
        substep: u32,
        deformed: &[[f64; 3]],
        rng: &mut ChaCha8Rng,
    ) -> Result<StepEval>;
    /// Sub-steps `0..count` of `iteration`, all at the same `deformed` positions, in order: the
    /// same results as `count` calls of [`Objective::evaluate`] with sub-steps 0, 1, … (the
    /// default makes exactly those calls). [`run_loop`] calls this once per iteration, before any
    /// Adam step, so that an objective can share work between the sub-steps.
    fn evaluate_batch(
        &mut self,
        iteration: u64,
        count: u32,
        deformed: &[[f64; 3]],
        rng: &mut ChaCha8Rng,
    ) -> Result<Vec<StepEval>> {
        (0..count)
            .map(|substep| self.evaluate(iteration, substep, deformed, rng))
            .collect()
    }
    /// The images of the current iteration, if the objective renders any (for previews).
    fn current_images(&self) -> Option<&Images> {
        None
    }
}

/// Loop lengths and cadences.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopSpec {
    /// Last iteration (1-indexed, inclusive).
    pub iterations: u64,
    /// Adam steps per iteration with accumulated gradients.
    pub steps_per_batch: u32,
    /// Checkpoint every N iterations (0: only after the last).
    pub checkpoint_every: u64,
    /// Preview every N iterations (0: never).
    pub preview_every: u64,
    /// Stop after this iteration without a final checkpoint (simulates a killed run in tests).
    pub halt_after: Option<u64>,
}

/// The mutable state of a run: what a checkpoint holds.
#[derive(Clone, Debug)]
pub struct LoopState {
    /// Last finished iteration (0 before the first).
    pub iteration: u64,
    /// Raw dARAP targets x (one row per vertex).
    pub x: Vec<[f64; 3]>,
    /// The optimizer.
    pub adam: Adam,
    /// The run's generator.
    pub rng: ChaCha8Rng,
}

/// One iteration's record (a line of `metrics.jsonl`).
#[derive(Clone, Debug, Default)]
pub struct IterationRecord {
    /// The iteration (1-indexed).
    pub iteration: u64,
    /// Named terms: `loss*` terms are summed over the sub-steps; others (`stage2_weight`,
    /// `alignment`) keep the last sub-step's value.
    pub terms: Vec<(&'static str, f64)>,
    /// Timings in seconds: `darap_forward`, `objective` parts, `darap_backward`, `adam`, `total`.
    pub timings: Vec<(&'static str, f64)>,
    /// Norm of the accumulated gradient with respect to x after the last sub-step.
    pub grad_norm: f64,
}

/// Receives progress from [`run_loop`].
pub trait Observer {
    /// After every iteration.
    fn iteration(&mut self, record: &IterationRecord) -> Result<()>;
    /// When a checkpoint is due (state after `state.iteration`).
    fn checkpoint(&mut self, state: &LoopState) -> Result<()>;
    /// When a preview is due.
    fn preview(
        &mut self,
        iteration: u64,
        deformed: &[[f64; 3]],
        images: Option<&Images>,
    ) -> Result<()>;
    /// After every iteration, before [`Observer::iteration`], with the state after it (the run
    /// directory's `snapshots.npz` of the deformed mesh). The default does nothing.
    fn after_iteration(&mut self, _state: &LoopState) -> Result<()> {
        Ok(())
    }
    /// Something the user should know that does not stop the loop (e.g. a streak of zero
    /// gradients). The default drops it; the command line prints it.
    fn warning(&mut self, _message: &str) {}
}

/// An [`Observer`] that keeps every iteration's record in memory and ignores checkpoints and
/// previews: for a program that drives [`run_loop`] itself and wants the records, not files.
#[derive(Clone, Debug, Default)]
pub struct RecordIterations(pub Vec<IterationRecord>);

impl Observer for RecordIterations {
    fn iteration(&mut self, record: &IterationRecord) -> Result<()> {
        self.0.push(record.clone());
        Ok(())
    }
    fn checkpoint(&mut self, _state: &LoopState) -> Result<()> {
        Ok(())
    }
    fn preview(&mut self, _: u64, _: &[[f64; 3]], _: Option<&Images>) -> Result<()> {
        Ok(())
    }
}

/// The wrapped objective evaluated one sub-step at a time: it forwards
/// [`Objective::evaluate`] (and `describe`, `current_images`) and keeps the trait's default
/// [`Objective::evaluate_batch`]. The reference an objective's own `evaluate_batch` must equal,
/// and the way to measure what sharing work between sub-steps saves.
#[derive(Debug)]
pub struct SubStepsOneByOne<O>(pub O);

impl<O: Objective> Objective for SubStepsOneByOne<O> {
    fn describe(&self) -> String {
        self.0.describe()
    }
    fn evaluate(
        &mut self,
        iteration: u64,
        substep: u32,
        deformed: &[[f64; 3]],
        rng: &mut ChaCha8Rng,
    ) -> Result<StepEval> {
        self.0.evaluate(iteration, substep, deformed, rng)
    }
    fn current_images(&self) -> Option<&Images> {
        self.0.current_images()
    }
}

fn add_term(terms: &mut Vec<(&'static str, f64)>, name: &'static str, value: f64, sum: bool) {
    match terms.iter_mut().find(|(n, _)| *n == name) {
        Some(t) if sum => t.1 += value,
        Some(t) => t.1 = value,
        None => terms.push((name, value)),
    }
}

/// Consecutive iterations with an exactly zero gradient after which [`run_loop`] warns.
pub const ZERO_GRADIENT_WARN_AFTER: u64 = 3;

/// Counts consecutive iterations whose accumulated gradient with respect to x is exactly zero: the
/// sign of an objective that silently does nothing (e.g. non-finite values turned into zeros by the
/// reference's `nan_to_num`). The streak is recorded in `metrics.jsonl` as `grad_zero_streak` (on
/// the iterations where it is ≥ 1) and warned about on stderr once per streak.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ZeroGradientWatch {
    streak: u64,
}

impl ZeroGradientWatch {
    /// Records one iteration's gradient norm; returns the warning to print when the streak reaches
    /// [`ZERO_GRADIENT_WARN_AFTER`] (once per streak).
    pub fn observe(&mut self, iteration: u64, grad_norm: f64) -> Option<String> {
        self.streak = if grad_norm == 0.0 { self.streak + 1 } else { 0 };
        (self.streak == ZERO_GRADIENT_WARN_AFTER).then(|| {
            format!(
                "warning: the gradient with respect to the deformation has been exactly zero for {} iterations \
                 (up to iteration {iteration}): the objective is not changing the mesh. Check darap.lambda \
                 (at 0 the target normals have no effect) and, for a prompt run, the prompt embeddings \
                 and the model (metrics.jsonl field grad_zero_streak)",
                self.streak
            )
        })
    }

    /// The current streak (0 after a non-zero gradient).
    pub fn streak(&self) -> u64 {
        self.streak
    }
}

/// Runs iterations `state.iteration + 1 ..= spec.iterations`.
pub fn run_loop(
    darap: &Darap,
    spec: &LoopSpec,
    state: &mut LoopState,
    objective: &mut dyn Objective,
    observer: &mut dyn Observer,
) -> Result<()> {
    if spec.steps_per_batch == 0 {
        invalid!("steps_per_batch must be at least 1");
    }
    let n = darap.num_vertices();
    if state.x.len() != n {
        invalid!("x has {} rows, the mesh {} vertices", state.x.len(), n);
    }
    let mut zero_watch = ZeroGradientWatch::default();
    while state.iteration < spec.iterations && spec.halt_after.is_none_or(|h| state.iteration < h) {
        let iteration = state.iteration + 1;
        let start = Instant::now();
        let deformation = darap.forward(&state.x).context("dARAP forward")?;
        let mut record = IterationRecord {
            iteration,
            ..Default::default()
        };
        record
            .timings
            .push(("darap_forward", start.elapsed().as_secs_f64()));
        let evals = objective
            .evaluate_batch(
                iteration,
                spec.steps_per_batch,
                &deformation.positions,
                &mut state.rng,
            )
            .with_context(|| format!("objective at iteration {iteration}"))?;
        if evals.len() != spec.steps_per_batch as usize {
            invalid!(
                "the objective returned {} sub-step gradients for {} sub-steps",
                evals.len(),
                spec.steps_per_batch
            );
        }
        // Every sub-step's gradient is taken at the same deformation, so the dARAP backward passes
        // are independent: they run together (each is deterministic, so the result does not depend
        // on the threads), and the Adam steps follow only when all of them succeeded.
        let t = Instant::now();
        let sub_grads = evals
            .par_iter()
            .map(|ev| darap.try_backward(&deformation, &ev.grad_positions))
            .collect::<Result<Vec<_>, _>>()
            .context("dARAP backward")?;
        let backward_seconds = t.elapsed().as_secs_f64();
        let mut grad = vec![[0.0; 3]; n];
        for (ev, g) in evals.iter().zip(&sub_grads) {
            for &(name, v) in &ev.terms {
                add_term(&mut record.terms, name, v, name.starts_with("loss"));
            }
            for &(name, v) in &ev.timings {
                add_term(&mut record.timings, name, v, true);
            }
            for (acc, gi) in grad.iter_mut().zip(g) {
                for c in 0..3 {
                    acc[c] += gi[c];
                }
            }
            let t = Instant::now();
            state
                .adam
                .step(state.x.as_flattened_mut(), grad.as_flattened())
                .with_context(|| format!("Adam step at iteration {iteration}"))?;
            add_term(&mut record.timings, "adam", t.elapsed().as_secs_f64(), true);
        }
        add_term(
            &mut record.timings,
            "darap_backward",
            backward_seconds,
            true,
        );
        record.grad_norm = grad
            .as_flattened()
            .iter()
            .map(|g| g * g)
            .sum::<f64>()
            .sqrt();
        if let Some(warning) = zero_watch.observe(iteration, record.grad_norm) {
            observer.warning(&warning);
        }
        if zero_watch.streak() > 0 {
            record
                .terms
                .push(("grad_zero_streak", zero_watch.streak() as f64));
        }
        state.iteration = iteration;
        record
            .timings
            .push(("total", start.elapsed().as_secs_f64()));
        observer.after_iteration(state)?;
        observer.iteration(&record)?;
        let due = |every: u64| every > 0 && iteration.is_multiple_of(every);
        if due(spec.preview_every) {
            observer.preview(
                iteration,
                &deformation.positions,
                objective.current_images(),
            )?;
        }
        if due(spec.checkpoint_every) || iteration == spec.iterations {
            observer.checkpoint(state)?;
        }
    }
    Ok(())
}

/// The model-free objective: `ℓ = Σ_f A_f (1 − n_f · t_f)` on the deformed mesh, `t_f` the style's
/// target for the rest face normal (see [`crate::style`]).
#[derive(Clone, Debug)]
pub struct StyleObjective {
    faces: Vec<[u32; 3]>,
    targets: Vec<[f64; 3]>,
    style: String,
}

impl StyleObjective {
    /// Targets from `style` applied to the rest mesh's face normals.
    pub fn new(style: &Style, rest_positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Self {
        Self {
            faces: faces.to_vec(),
            targets: style.face_targets(rest_positions, faces),
            style: style.name(),
        }
    }

    /// The per-face targets.
    pub fn targets(&self) -> &[[f64; 3]] {
        &self.targets
    }

    /// Area-weighted mean alignment of `positions` with the targets (1 = perfect).
    pub fn mean_alignment(&self, positions: &[[f64; 3]]) -> f64 {
        alignment::mean_alignment(positions, &self.faces, &self.targets)
    }
}

impl Objective for StyleObjective {
    fn describe(&self) -> String {
        format!("normal alignment with style {}", self.style)
    }

    fn evaluate(
        &mut self,
        _iteration: u64,
        _substep: u32,
        deformed: &[[f64; 3]],
        _rng: &mut ChaCha8Rng,
    ) -> Result<StepEval> {
        let t = Instant::now();
        let (loss, grad) = alignment::alignment_loss_and_grad(deformed, &self.faces, &self.targets);
        let alignment = alignment::mean_alignment(deformed, &self.faces, &self.targets);
        Ok(StepEval {
            terms: vec![("loss", loss), ("alignment", alignment)],
            timings: vec![("objective", t.elapsed().as_secs_f64())],
            grad_positions: grad,
        })
    }
}

/// Settings of the text objective's renders.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewSettings {
    /// The per-iteration view sampler.
    pub camera: CameraConfig,
    /// Views per iteration.
    pub views: usize,
    /// Render width.
    pub width: usize,
    /// Render height.
    pub height: usize,
    /// Adaptive camera distance from iteration 2 on.
    pub adapt_distance: bool,
}

/// The text path's objective: sample views, render, guidance, renderer adjoint.
///
/// Sub-step 0 of an iteration samples views (distance × [`raster_diff::adapt_multiplier`] of the
/// deformed mesh from iteration 2 on) and renders; every sub-step evaluates the guidance on those
/// renders with fresh randomness and maps dL/dimage back through the renderer.
pub struct TextObjective<'g> {
    renderer: Box<dyn Renderer>,
    guidance: Box<dyn Guidance + 'g>,
    faces: Vec<[u32; 3]>,
    views: ViewSettings,
    images: Option<Images>,
}

impl std::fmt::Debug for TextObjective<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TextObjective")
            .field("renderer", &self.renderer.name())
            .field("views", &self.views)
            .finish_non_exhaustive()
    }
}

impl<'g> TextObjective<'g> {
    /// Joins a renderer and a guidance (which owns any iteration-dependent weights, such as
    /// the stage-II weight schedule of `csd::CascadedGuidance`).
    pub fn new(
        renderer: Box<dyn Renderer>,
        guidance: Box<dyn Guidance + 'g>,
        faces: &[[u32; 3]],
        views: ViewSettings,
    ) -> Self {
        Self {
            renderer,
            guidance,
            faces: faces.to_vec(),
            views,
            images: None,
        }
    }

    /// Samples the iteration's views (distance × [`raster_diff::adapt_multiplier`] of the deformed
    /// mesh from iteration 2 on) and renders them.
    fn render(
        &mut self,
        iteration: u64,
        deformed: &[[f64; 3]],
        rng: &mut ChaCha8Rng,
        timings: &mut Vec<(&'static str, f64)>,
    ) -> Result<()> {
        let t = Instant::now();
        let v = &self.views;
        let multiplier = if v.adapt_distance && iteration >= 2 {
            raster_diff::adapt_multiplier(deformed)
        } else {
            1.0
        };
        let views = raster_diff::sample_views(&v.camera, v.views, multiplier, rng);
        self.images = None;
        let images = self
            .renderer
            .render(deformed, &self.faces, &views, v.width, v.height)
            .context("render")?;
        self.images = Some(images);
        timings.push(("render", t.elapsed().as_secs_f64()));
        Ok(())
    }

    /// `count` guidance evaluations on the current renders and their position gradients;
    /// `timings` (the render's, if any) and the shared work's go with the first result.
    fn guide(
        &mut self,
        iteration: u64,
        count: u32,
        rng: &mut ChaCha8Rng,
        mut timings: Vec<(&'static str, f64)>,
    ) -> Result<Vec<StepEval>> {
        let Some(images) = &self.images else {
            invalid!("no renders")
        };
        let t = Instant::now();
        let outs = self
            .guidance
            .evaluate_many(images, iteration, count as usize, rng)
            .context("guidance")?;
        timings.push(("guidance", t.elapsed().as_secs_f64()));
        timings.push((
            "guidance_denoiser",
            outs.iter().map(|o| o.denoiser_seconds).sum(),
        ));
        if outs.len() != count as usize {
            invalid!(
                "guidance returned {} evaluations for {count} sub-steps",
                outs.len()
            );
        }
        for out in &outs {
            if !out.grad_images.same_shape(images) {
                invalid!(
                    "guidance returned {} gradient values for {} image values",
                    out.grad_images.rgb.len(),
                    images.rgb.len()
                );
            }
        }
        let t = Instant::now();
        let d_images: Vec<&Images> = outs.iter().map(|o| &o.grad_images).collect();
        let grads = self
            .renderer
            .backward_many(&d_images)
            .context("renderer backward")?;
        timings.push(("render_backward", t.elapsed().as_secs_f64()));
        if grads.len() != outs.len() {
            invalid!(
                "the renderer returned {} gradients for {} image gradients",
                grads.len(),
                outs.len()
            );
        }
        Ok(outs
            .iter()
            .zip(grads)
            .enumerate()
            .map(|(k, (out, grad_positions))| StepEval {
                terms: vec![
                    ("loss", out.loss_stage1 + out.loss_stage2),
                    ("loss_stage1", out.loss_stage1),
                    ("loss_stage2", out.loss_stage2),
                    ("stage2_weight", out.stage2_weight),
                ],
                timings: if k == 0 {
                    std::mem::take(&mut timings)
                } else {
                    Vec::new()
                },
                grad_positions,
            })
            .collect())
    }
}

impl Objective for TextObjective<'_> {
    fn describe(&self) -> String {
        format!(
            "score distillation, {} views rendered with {}",
            self.views.views,
            self.renderer.name()
        )
    }

    fn evaluate(
        &mut self,
        iteration: u64,
        substep: u32,
        deformed: &[[f64; 3]],
        rng: &mut ChaCha8Rng,
    ) -> Result<StepEval> {
        let mut timings = Vec::new();
        if substep == 0 || self.images.is_none() {
            self.render(iteration, deformed, rng, &mut timings)?;
        }
        let Some(ev) = self.guide(iteration, 1, rng, timings)?.pop() else {
            invalid!("the guidance evaluated no sub-step")
        };
        Ok(ev)
    }

    /// Renders once, evaluates the guidance `count` times on those renders
    /// ([`Guidance::evaluate_many`]: one encoding of the renders) and maps all the image
    /// gradients back in one renderer pass ([`Renderer::backward_many`]). The timings of the
    /// shared work are reported with sub-step 0.
    fn evaluate_batch(
        &mut self,
        iteration: u64,
        count: u32,
        deformed: &[[f64; 3]],
        rng: &mut ChaCha8Rng,
    ) -> Result<Vec<StepEval>> {
        if count == 0 {
            return Ok(Vec::new());
        }
        let mut timings = Vec::new();
        self.render(iteration, deformed, rng, &mut timings)?;
        self.guide(iteration, count, rng, timings)
    }

    fn current_images(&self) -> Option<&Images> {
        self.images.as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// An objective whose gradient is zero on the iterations in `zero` and constant elsewhere, and
    /// one entry short (a wrong length, which dARAP's backward rejects) on sub-step
    /// `short_substep`.
    struct Flat {
        zero: std::ops::RangeInclusive<u64>,
        short_substep: Option<u32>,
    }

    impl Objective for Flat {
        fn describe(&self) -> String {
            "flat".into()
        }
        fn evaluate(
            &mut self,
            iteration: u64,
            substep: u32,
            deformed: &[[f64; 3]],
            _rng: &mut ChaCha8Rng,
        ) -> Result<StepEval> {
            let g = if self.zero.contains(&iteration) {
                0.0
            } else {
                1e-3
            };
            let n = deformed.len() - usize::from(self.short_substep == Some(substep));
            Ok(StepEval {
                terms: vec![("loss", 0.0)],
                timings: Vec::new(),
                grad_positions: vec![[g, 0.0, 0.0]; n],
            })
        }
    }

    /// dARAP on an icosphere, a loop state at its rest normals and a loop of `iterations` ×
    /// `steps_per_batch` steps without checkpoints or previews.
    fn icosphere_loop(
        iterations: u64,
        steps_per_batch: u32,
    ) -> Result<(Darap, LoopState, LoopSpec)> {
        let (p, f) = mesh_core::shapes::icosphere(1).into_parts();
        let darap = Darap::new(&p, &f, darap::DarapOptions::default())?;
        let state = LoopState {
            iteration: 0,
            x: darap.rest_normals().to_vec(),
            adam: Adam::new(3 * p.len(), optim::AdamConfig::default())?,
            rng: ChaCha8Rng::seed_from_u64(0),
        };
        let spec = LoopSpec {
            iterations,
            steps_per_batch,
            checkpoint_every: 0,
            preview_every: 0,
            halt_after: None,
        };
        Ok((darap, state, spec))
    }

    #[test]
    fn zero_gradient_watch_warns_once_per_streak() {
        let mut w = ZeroGradientWatch::default();
        let warned: Vec<bool> = [0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
            .iter()
            .enumerate()
            .map(|(i, &g)| w.observe(i as u64 + 1, g).is_some())
            .collect();
        assert_eq!(
            warned,
            [false, false, true, false, false, false, false, true]
        );
        assert_eq!(w.streak(), 3);
    }

    #[test]
    fn zero_gradient_streak_is_recorded_in_the_iteration_records() -> Result<()> {
        let (darap, mut state, spec) = icosphere_loop(6, 1)?;
        let mut records = RecordIterations::default();
        let mut objective = Flat {
            zero: 2..=5,
            short_substep: None,
        };
        run_loop(&darap, &spec, &mut state, &mut objective, &mut records)?;
        let streaks: Vec<Option<f64>> = records
            .0
            .iter()
            .map(|r| {
                r.terms
                    .iter()
                    .find(|t| t.0 == "grad_zero_streak")
                    .map(|t| t.1)
            })
            .collect();
        assert_eq!(
            streaks,
            [None, Some(1.0), Some(2.0), Some(3.0), Some(4.0), None]
        );
        Ok(())
    }

    #[test]
    fn a_darap_backward_error_in_a_later_sub_step_leaves_x_and_adam_untouched() -> Result<()> {
        let (darap, mut state, spec) = icosphere_loop(1, 2)?;
        let (x0, adam0) = (state.x.clone(), state.adam.state().clone());
        // Sub-step 0's gradient is fine (nonzero: iterations count from 1), sub-step 1's has
        // the wrong length.
        let mut objective = Flat {
            zero: 0..=0,
            short_substep: Some(1),
        };
        let err = run_loop(
            &darap,
            &spec,
            &mut state,
            &mut objective,
            &mut RecordIterations::default(),
        )
        .expect_err("a gradient of the wrong length");
        assert!(format!("{err:#}").contains("dARAP backward"), "{err:#}");
        assert_eq!(state.iteration, 0);
        assert!(state.x == x0, "x moved although the iteration failed");
        assert_eq!(state.adam.state(), &adam0);
        Ok(())
    }
}
