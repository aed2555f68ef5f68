//! The text-path loop with a fake guidance (no models): gradients flow from the image to x, the
//! reference's two Adam steps per render batch accumulate `g1`, then `g1 + g2`, at the same renders.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use csd::{Guidance, GuidanceError, GuidanceOutput};
use darap::Darap;
use optim::{Adam, AdamConfig, Schedule};
use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use raster_diff::{CameraConfig, CpuRenderer, Images, RenderError, Renderer, View};
use stylize::pipeline::{
    LoopSpec, LoopState, Objective, RecordIterations, StepEval, SubStepsOneByOne, TextObjective,
    ViewSettings, run_loop,
};

mod common;
use common::ok;

/// Loss = mean value of the RGB images (pushes pixels darker; grey images are taken as their RGB
/// expansion); its gradient is 1/N everywhere, scaled by a factor drawn from the RNG (so two
/// sub-steps give different gradients, like fresh noise), and for grey images the channel sums
/// of that. Its stage-II "loss" is the weight of its schedule at the iteration (as
/// `CascadedGuidance` reads it).
struct DarkerGuidance {
    calls: Arc<AtomicUsize>,
    random_scale: bool,
    stage2_weight: Schedule,
}

impl Guidance for DarkerGuidance {
    fn evaluate(
        &mut self,
        images: &Images,
        iteration: u64,
        rng: &mut dyn RngCore,
    ) -> Result<GuidanceOutput, GuidanceError> {
        self.calls.fetch_add(1, Ordering::SeqCst);
        let scale = if self.random_scale {
            0.5 + rng.random::<f64>()
        } else {
            1.0
        };
        let rgb = images.to_rgb();
        let n = rgb.rgb.len() as f64;
        let mean = rgb.rgb.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
        let stage2_weight = self.stage2_weight.at(iteration);
        let mut grad_rgb = rgb.zeros_like();
        // Four low mantissa bits cleared: the three channels' sum is then exact in f32, so a grey
        // render's gradient (dL/d(grey) in f32) holds the values an RGB renderer sums in f64.
        grad_rgb
            .rgb
            .fill(f32::from_bits(((scale / n) as f32).to_bits() & !0xF));
        let grad_images = if images.is_grey() {
            let sums = grad_rgb.channel_sums().iter().map(|&v| v as f32).collect();
            Images::with_channels(images.count, images.height, images.width, 1, sums)
                .map_err(|e| GuidanceError::InvalidInput(e.to_string()))?
        } else {
            grad_rgb
        };
        Ok(GuidanceOutput {
            loss_stage1: scale * mean,
            loss_stage2: stage2_weight,
            stage2_weight,
            denoiser_seconds: 0.0,
            grad_images,
        })
    }
}

/// The CPU renderer's grey renders as RGB images (each value in all three channels); its
/// backward takes RGB gradients and maps their channel sums back.
struct RgbRenderer(CpuRenderer);

impl Renderer for RgbRenderer {
    fn name(&self) -> String {
        "rgb cpu".into()
    }
    fn render(
        &mut self,
        vertices: &[[f64; 3]],
        faces: &[[u32; 3]],
        views: &[View],
        width: usize,
        height: usize,
    ) -> Result<Images, RenderError> {
        let grey = self.0.render(vertices, faces, views, width, height)?;
        assert_eq!(grey.channels, 1);
        Ok(grey.into_rgb())
    }
    fn backward(&mut self, d_images: &Images) -> Result<Vec<[f64; 3]>, RenderError> {
        assert_eq!(d_images.channels, 3);
        let sums = d_images.channel_sums().iter().map(|&v| v as f32).collect();
        let d_grey =
            Images::with_channels(d_images.count, d_images.height, d_images.width, 1, sums)?;
        self.0.backward(&d_grey)
    }
}

struct CountingRenderer {
    inner: CpuRenderer,
    renders: Arc<AtomicUsize>,
}

impl Renderer for CountingRenderer {
    fn name(&self) -> String {
        "counting cpu".into()
    }
    fn render(
        &mut self,
        vertices: &[[f64; 3]],
        faces: &[[u32; 3]],
        views: &[View],
        width: usize,
        height: usize,
    ) -> Result<Images, RenderError> {
        self.renders.fetch_add(1, Ordering::SeqCst);
        self.inner.render(vertices, faces, views, width, height)
    }
    fn backward(&mut self, d_images: &Images) -> Result<Vec<[f64; 3]>, RenderError> {
        self.inner.backward(d_images)
    }
}

fn layer() -> Darap {
    let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
    let p: Vec<[f64; 3]> = p
        .iter()
        .map(|v| [0.9 * v[0], 0.7 * v[1], 0.8 * v[2]])
        .collect();
    ok(Darap::new(&p, &f, darap::DarapOptions::default()))
}

fn faces() -> Vec<[u32; 3]> {
    mesh_core::shapes::icosphere(2).into_parts().1
}

fn views() -> ViewSettings {
    ViewSettings {
        camera: CameraConfig::default(),
        views: 2,
        width: 40,
        height: 40,
        adapt_distance: true,
    }
}

fn text_objective(
    random_scale: bool,
) -> (TextObjective<'static>, Arc<AtomicUsize>, Arc<AtomicUsize>) {
    let renders = Arc::new(AtomicUsize::new(0));
    let calls = Arc::new(AtomicUsize::new(0));
    let obj = TextObjective::new(
        Box::new(CountingRenderer {
            inner: CpuRenderer::default(),
            renders: renders.clone(),
        }),
        Box::new(DarkerGuidance {
            calls: calls.clone(),
            random_scale,
            stage2_weight: ok(Schedule::parse("0.0>0.2:1000; 0.2>0.3:750")),
        }),
        &faces(),
        views(),
    );
    (obj, renders, calls)
}

#[test]
fn image_gradient_reaches_x_as_a_descent_direction() {
    let darap = layer();
    let x0 = darap.rest_normals().to_vec();
    let (mut obj, _, _) = text_objective(false);
    let seed = ChaCha8Rng::seed_from_u64(5);
    let def = ok(darap.forward(&x0));
    let ev = ok(obj.evaluate(1, 0, &def.positions, &mut seed.clone()));
    let loss0 = ev
        .terms
        .iter()
        .find(|t| t.0 == "loss_stage1")
        .map_or(f64::NAN, |t| t.1);
    let g = ok(darap.try_backward(&def, &ev.grad_positions));
    let norm = g.as_flattened().iter().map(|v| v * v).sum::<f64>().sqrt();
    assert!(norm.is_finite() && norm > 0.0, "|dL/dx| = {norm}");
    // Same views (same generator state), x moved against the gradient: the loss must drop.
    // Central difference of the whole chain x → dARAP → render → guidance along g/|g| (same views:
    // same generator state) must equal the adjoint's directional derivative |g|.
    let h = 1e-3;
    let shifted = |s: f64| -> Vec<[f64; 3]> {
        x0.iter()
            .zip(&g)
            .map(|(x, gi)| {
                [
                    x[0] + s * gi[0] / norm,
                    x[1] + s * gi[1] / norm,
                    x[2] + s * gi[2] / norm,
                ]
            })
            .collect()
    };
    let mut loss_at = |x: &[[f64; 3]]| -> f64 {
        let ev = ok(obj.evaluate(1, 0, &ok(darap.forward(x)).positions, &mut seed.clone()));
        ev.terms
            .iter()
            .find(|t| t.0 == "loss_stage1")
            .map_or(f64::NAN, |t| t.1)
    };
    let (plus, minus) = (loss_at(&shifted(h)), loss_at(&shifted(-h)));
    let central = (plus - minus) / (2.0 * h);
    assert!(
        (central - norm).abs() < 1e-3 * norm,
        "central difference {central} vs adjoint {norm}"
    );
    assert!(
        minus < loss0 && loss0 < plus,
        "not a descent direction: {minus} {loss0} {plus}"
    );
}

#[test]
fn one_render_and_two_guidance_calls_per_iteration() {
    let darap = layer();
    let (mut obj, renders, calls) = text_objective(true);
    let (state, records) = three_iterations(&darap, &mut obj, 1);
    assert_eq!(renders.load(Ordering::SeqCst), 3);
    assert_eq!(calls.load(Ordering::SeqCst), 6);
    assert_eq!(state.adam.state().step, 6);
    assert_eq!(records.0.len(), 3);
    // The stage-II weight logged is the guidance schedule's value at each (1-indexed) iteration.
    let w: Vec<f64> = records
        .0
        .iter()
        .map(|r| {
            r.terms
                .iter()
                .find(|t| t.0 == "stage2_weight")
                .map_or(-1.0, |t| t.1)
        })
        .collect();
    assert_eq!(w, vec![0.0, 0.2 / 999.0, 0.4 / 999.0]);
    assert!(state.x != darap.rest_normals(), "x did not move");
}

/// An objective whose position gradient is `(substep + 1) · v` for a fixed field `v`.
struct Scaled(Vec<[f64; 3]>);

impl Objective for Scaled {
    fn describe(&self) -> String {
        "scaled".into()
    }
    fn evaluate(
        &mut self,
        _: u64,
        substep: u32,
        _: &[[f64; 3]],
        _: &mut ChaCha8Rng,
    ) -> stylize::Result<StepEval> {
        let s = f64::from(substep + 1);
        Ok(StepEval {
            grad_positions: self.0.iter().map(|v| v.map(|c| s * c)).collect(),
            ..Default::default()
        })
    }
}

#[test]
fn second_step_uses_accumulated_gradient_at_the_pre_step_x() {
    let darap = layer();
    let n = darap.num_vertices();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let v: Vec<[f64; 3]> = (0..n)
        .map(|_| {
            [
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
            ]
        })
        .collect();
    let x0 = darap.rest_normals().to_vec();
    let config = AdamConfig {
        lr: 0.01,
        ..AdamConfig::default()
    };

    // By hand: both gradients at x0's deformation; Adam with g1, then with g1 + g2.
    let def = ok(darap.forward(&x0));
    let g1 = ok(darap.try_backward(&def, &v));
    let v2: Vec<[f64; 3]> = v.iter().map(|r| r.map(|c| 2.0 * c)).collect();
    let g2 = ok(darap.try_backward(&def, &v2));
    let g12: Vec<[f64; 3]> = g1
        .iter()
        .zip(&g2)
        .map(|(a, b)| [a[0] + b[0], a[1] + b[1], a[2] + b[2]])
        .collect();
    let mut adam = ok(Adam::new(3 * n, config));
    let mut x_hand = x0.clone();
    ok(adam.step(x_hand.as_flattened_mut(), g1.as_flattened()));
    ok(adam.step(x_hand.as_flattened_mut(), g12.as_flattened()));

    let mut state = LoopState {
        iteration: 0,
        x: x0,
        adam: ok(Adam::new(3 * n, config)),
        rng,
    };
    let spec = LoopSpec {
        iterations: 1,
        steps_per_batch: 2,
        checkpoint_every: 0,
        preview_every: 0,
        halt_after: None,
    };
    ok(run_loop(
        &darap,
        &spec,
        &mut state,
        &mut Scaled(v),
        &mut RecordIterations::default(),
    ));
    assert!(
        state.x == x_hand,
        "loop's two-step update differs from g1 then g1 + g2"
    );
}

/// The text path through the run directory with the fake guidance: views, lights and the
/// guidance's draws all come from the run's generator, so a resumed run must restore its state.
#[test]
fn text_run_resumed_from_checkpoint_equals_uninterrupted_run() {
    use stylize::runner::RunRequest;
    use stylize::task::{Prompt, PromptTask};
    use stylize_cli::config::Config;
    use stylize_cli::runner::{LogMode, execute};

    let tmp = ok(tempfile::tempdir());
    let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
    let mesh = tmp.path().join("m.obj");
    ok(mesh_core::io::write_mesh(
        &mesh,
        &mesh_core::TriMesh::new(p, f),
        None,
    ));
    let mut config = Config::default();
    config.optim.iterations = 5;
    config.camera.views = 2;
    config.render.width = 32;
    config.render.height = 32;
    config.render.backend = stylize_cli::config::Backend::Cpu;
    config.run.checkpoint_every = 2;
    config.run.preview_every = 0;
    config.run.turntable_views = 1;
    config.run.turntable_size = 16;
    let task = || PromptTask {
        prompt: Prompt::new("darker"),
        guidance: Box::new(DarkerGuidance {
            calls: Arc::new(AtomicUsize::new(0)),
            random_scale: true,
            stage2_weight: ok(config.stage2_schedule()),
        }),
        warnings: Vec::new(),
    };
    let request = |out: &str, resume: bool, halt_after: Option<u64>| RunRequest {
        mesh: mesh.clone(),
        out: tmp.path().join(out),
        config: config.clone(),
        force: false,
        resume,
        halt_after,
    };
    ok(execute(&request("a", false, None), LogMode::Quiet, task()));
    let halted = ok(execute(
        &request("b", false, Some(3)),
        LogMode::Quiet,
        task(),
    ));
    assert!(!halted.complete);
    ok(execute(&request("b", true, None), LogMode::Quiet, task()));
    let load = |d: &str| {
        ok(stylize::checkpoint::Checkpoint::load(
            &tmp.path().join(d).join("checkpoint.json"),
        ))
    };
    let (a, b) = (load("a"), load("b"));
    assert_eq!((a.iteration, b.iteration), (5, 5));
    assert!(a.state.x == b.state.x, "x differs after resume");
    assert!(
        a.state.adam == b.state.adam,
        "Adam state differs after resume"
    );
}

#[test]
fn text_path_honours_a_feathered_region_adam_leaves_outside_targets_at_rest() {
    let mut darap = layer();
    let faces = faces();
    // Region: the upper half (y > 0) of the ellipsoid, feathered over 2 rings.
    let p = darap.rest_positions().to_vec();
    let free: Vec<bool> = p.iter().map(|q| q[1] > 0.0).collect();
    let weights = mesh_core::region::feather_weights(&free, &faces, 2);
    ok(darap.set_region_weights(Some(weights.clone())));
    let (mut obj, _, _) = text_objective(true);
    let mut state = LoopState {
        iteration: 0,
        x: darap.rest_normals().to_vec(),
        adam: ok(Adam::new(3 * darap.num_vertices(), AdamConfig::default())),
        rng: ChaCha8Rng::seed_from_u64(2),
    };
    let spec = LoopSpec {
        iterations: 4,
        steps_per_batch: 2,
        checkpoint_every: 0,
        preview_every: 0,
        halt_after: None,
    };
    ok(run_loop(
        &darap,
        &spec,
        &mut state,
        &mut obj,
        &mut RecordIterations::default(),
    ));
    let rest = darap.rest_normals();
    for v in 0..p.len() {
        if !free[v] {
            assert_eq!(state.x[v], rest[v], "target {v} outside the region moved");
        }
    }
    let moved = (0..p.len())
        .filter(|&v| weights[v] > 0.0 && state.x[v] != rest[v])
        .count();
    assert!(moved > 0, "no target inside the region moved");
    let def = ok(darap.forward(&state.x));
    for v in (0..p.len()).filter(|&v| !free[v]) {
        assert_eq!(
            def.rotations[v],
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            "vertex {v}"
        );
    }
}

/// A denoiser predicting half of its input's first three channels plus a per-channel offset
/// (IF-shaped output, 6 channels): its output depends on the renders, the noise and the timesteps.
struct Echo;

impl csd::Denoiser for Echo {
    fn predict(
        &mut self,
        sample: &csd::Tensor,
        _timesteps: &[i64],
        _embeddings: &[&csd::Embedding],
        _class_labels: Option<&[i64]>,
    ) -> Result<csd::Tensor, GuidanceError> {
        let (n, c_in) = (sample.shape[0], sample.shape[1]);
        let plane = sample.shape[2] * sample.shape[3];
        let mut data = vec![0.0f32; n * 6 * plane];
        for s in 0..n {
            for c in 0..3 {
                for p in 0..plane {
                    data[(s * 6 + c) * plane + p] =
                        0.5 * sample.data[(s * c_in + c) * plane + p] + 0.01 * c as f32;
                }
            }
        }
        Ok(csd::Tensor {
            shape: vec![n, 6, sample.shape[2], sample.shape[3]],
            data,
        })
    }
}

/// The loop evaluates an iteration's sub-steps together (one encoding of the renders in
/// `CascadedGuidance::evaluate_many`, one `CpuRenderer::backward_many` pass): the optimization
/// must be the sub-step-by-sub-step one, bit for bit, with both guidance stages running.
/// Three iterations of two sub-steps each from the rest normals (Adam, lr 0.05), the loop's RNG
/// seeded with `seed`: the final state and the per-iteration records.
fn three_iterations(
    darap: &Darap,
    obj: &mut dyn Objective,
    seed: u64,
) -> (LoopState, RecordIterations) {
    let spec = LoopSpec {
        iterations: 3,
        steps_per_batch: 2,
        checkpoint_every: 0,
        preview_every: 0,
        halt_after: None,
    };
    let mut state = LoopState {
        iteration: 0,
        x: darap.rest_normals().to_vec(),
        adam: ok(Adam::new(
            3 * darap.num_vertices(),
            AdamConfig {
                lr: 0.05,
                ..AdamConfig::default()
            },
        )),
        rng: ChaCha8Rng::seed_from_u64(seed),
    };
    let mut records = RecordIterations::default();
    ok(run_loop(darap, &spec, &mut state, obj, &mut records));
    (state, records)
}

#[test]
fn batched_sub_steps_equal_sub_steps_one_by_one_bit_for_bit() {
    let darap = layer();
    let objective = || {
        let embedding = |sign: f32| csd::Embedding {
            shape: [2, 3],
            data: (1..=6).map(|v| sign * v as f32).collect(),
        };
        let guidance = ok(csd::CascadedGuidance::new(
            Box::new(Echo),
            Some(Box::new(Echo)),
            embedding(1.0),
            embedding(-1.0),
            csd::GuidanceConfig::default(),
        ))
        .with_stage2_weight(Schedule::constant(0.25));
        TextObjective::new(
            Box::new(CpuRenderer::default()),
            Box::new(guidance),
            &faces(),
            views(),
        )
    };
    let (batched, batched_records) = three_iterations(&darap, &mut objective(), 8);
    let (one_by_one, one_by_one_records) =
        three_iterations(&darap, &mut SubStepsOneByOne(objective()), 8);
    assert!(batched.x == one_by_one.x, "x differs");
    assert!(batched.adam == one_by_one.adam, "Adam state differs");
    assert!(batched.x != darap.rest_normals(), "x did not move");
    let terms = |r: &RecordIterations| r.0.iter().map(|r| r.terms.clone()).collect::<Vec<_>>();
    assert_eq!(terms(&batched_records), terms(&one_by_one_records));
    assert!(
        batched_records.0[0]
            .terms
            .iter()
            .any(|t| t.0 == "loss_stage2" && t.1 > 0.0),
        "stage II ran"
    );
}

#[test]
fn a_grey_renderer_takes_grey_gradients_with_the_rgb_paths_results() {
    // The CPU renderer's output is grey (one channel), so the guidance returns dL/d(grey) and the
    // renderer maps it back; `RgbRenderer` hands the same renders over as RGB and sums the RGB
    // gradient's channels. `DarkerGuidance` forms dL/d(grey) as the channel sums of its RGB
    // gradient (exact here) — what the RGB renderer's backward sums — so the two runs agree bit
    // for bit.
    let darap = layer();
    let objective = |grey: bool| {
        let renderer: Box<dyn Renderer> = if grey {
            Box::new(CpuRenderer::default())
        } else {
            Box::new(RgbRenderer(CpuRenderer::default()))
        };
        TextObjective::new(
            renderer,
            Box::new(DarkerGuidance {
                calls: Arc::new(AtomicUsize::new(0)),
                random_scale: true,
                stage2_weight: Schedule::constant(0.0),
            }),
            &faces(),
            views(),
        )
    };
    let (grey, grey_records) = three_iterations(&darap, &mut objective(true), 3);
    let (rgb, rgb_records) = three_iterations(&darap, &mut objective(false), 3);
    assert!(grey.x == rgb.x, "x differs");
    assert!(grey.x != darap.rest_normals(), "x did not move");
    let terms = |r: &RecordIterations| r.0.iter().map(|r| r.terms.clone()).collect::<Vec<_>>();
    assert_eq!(terms(&grey_records), terms(&rgb_records));
}
