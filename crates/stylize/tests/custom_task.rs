//! A third kind of task, defined here outside the crate: it needs no change to the runner, the
//! task identity or the command line's run/batch plumbing. It runs end to end through
//! `runner::execute_with` into a run directory, stops after `halt_after`, resumes to the same
//! result as an uninterrupted run, records its own identity fields in `task.json` (and only the
//! settings it reads), its label in `deformation.npz` and its loading warning in `run.json`, and a
//! resume with another direction is refused naming the field.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use mesh_core::TriMesh;
use rand_chacha::ChaCha8Rng;
use stylize::config::Config;
use stylize::pipeline::{Objective, StepEval};
use stylize::runner::{NoProgress, RunHooks, RunOptions, RunOutcome, RunRequest, execute_with};
use stylize::saved::SavedDeformation;
use stylize::task::{BuiltTask, Schedule, Task, TaskKind};

fn ok<T, E: std::fmt::Debug>(r: Result<T, E>) -> T {
    r.unwrap_or_else(|e| panic!("{e:?}"))
}

/// Squash the mesh along a unit direction `d`: ℓ = ½ Σ_v (p_v · d)², ∂ℓ/∂p_v = (p_v · d) d — every
/// vertex pulled toward the plane through the origin orthogonal to `d`.
#[derive(Clone, Debug)]
struct Squash {
    direction: [f64; 3],
}

impl TaskKind for Squash {
    fn identity_fields(&self) -> Vec<(String, String)> {
        let [x, y, z] = self.direction;
        vec![
            ("objective".into(), "squash".into()),
            ("squash.direction".into(), format!("[{x}, {y}, {z}]")),
        ]
    }

    /// Only the optimizer's iterations and learning rate (beyond what every run reads).
    fn reads(&self, _section: &str, name: &str) -> bool {
        name == "optim.iterations" || name == "optim.lr"
    }

    fn reads_summary(&self) -> String {
        "a squash run, which reads optim.iterations and optim.lr".into()
    }
}

const LOAD_WARNING: &str = "the squash direction was not normalized";

impl Task<'_> for Squash {
    fn label(&self) -> (&'static str, String) {
        let [x, y, z] = self.direction;
        ("squash", format!("{x},{y},{z}"))
    }

    fn warnings(&self) -> Vec<String> {
        vec![LOAD_WARNING.into()]
    }

    fn schedule(&self, config: &Config) -> Schedule {
        Schedule {
            iterations: config.optim.iterations,
            lr: config.optim.lr,
            steps_per_batch: 1,
        }
    }

    fn build(
        self: Box<Self>,
        _mesh: &TriMesh,
        _config: &Config,
    ) -> stylize::Result<BuiltTask<'static>> {
        Ok(BuiltTask {
            objective: Box::new(SquashObjective {
                direction: self.direction,
            }),
            renderer_choice: None,
            warnings: Vec::new(),
            alignment: None,
        })
    }
}

struct SquashObjective {
    direction: [f64; 3],
}

impl Objective for SquashObjective {
    fn describe(&self) -> String {
        format!("squash along {:?}", self.direction)
    }

    fn evaluate(
        &mut self,
        _iteration: u64,
        _substep: u32,
        deformed: &[[f64; 3]],
        _rng: &mut ChaCha8Rng,
    ) -> stylize::Result<StepEval> {
        let d = self.direction;
        let mut loss = 0.0;
        let grad = deformed
            .iter()
            .map(|p| {
                let h = p[0] * d[0] + p[1] * d[1] + p[2] * d[2];
                loss += 0.5 * h * h;
                d.map(|c| h * c)
            })
            .collect();
        Ok(StepEval {
            terms: vec![("loss", loss)],
            timings: Vec::new(),
            grad_positions: grad,
        })
    }
}

fn small_mesh(dir: &Path) -> PathBuf {
    let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
    let path = dir.join("sphere.obj");
    ok(mesh_core::io::write_mesh(&path, &TriMesh::new(p, f), None));
    path
}

fn config() -> Config {
    let mut c = Config::default();
    c.optim.iterations = 6;
    c.optim.lr = 0.02;
    c.run.checkpoint_every = 2;
    c.run.preview_every = 0;
    c.run.turntable_views = 1;
    c.run.turntable_size = 16;
    c.run.turntable_gif_frames = 0;
    c.run.snapshot_every = 0;
    c
}

fn run(
    mesh: &Path,
    out: &Path,
    task: &Squash,
    resume: bool,
    halt: Option<u64>,
) -> stylize::Result<RunOutcome> {
    let request = RunRequest {
        mesh: mesh.to_path_buf(),
        out: out.to_path_buf(),
        config: config(),
        force: false,
        resume,
        halt_after: halt,
    };
    let never = AtomicBool::new(false);
    let hooks = RunHooks {
        progress: &mut NoProgress,
        cancel: &never,
    };
    execute_with(
        &request,
        task,
        || Ok(task.clone()),
        &RunOptions::default(),
        hooks,
    )
}

fn json_line(text: &str) -> serde_json::Value {
    ok(serde_json::from_str(text))
}

fn json(path: &Path) -> serde_json::Value {
    json_line(&ok(std::fs::read_to_string(path)))
}

#[test]
fn a_kind_defined_outside_the_crate_runs_resumes_and_records_its_identity() {
    let tmp = ok(tempfile::tempdir());
    let mesh = small_mesh(tmp.path());
    let task = Squash {
        direction: [0.0, 0.0, 1.0],
    };

    let whole = tmp.path().join("whole");
    let done = ok(run(&mesh, &whole, &task, false, None));
    assert!(done.complete && done.iteration == 6, "{done:?}");
    assert_eq!(done.alignment, None);
    assert!(done.warnings.iter().any(|w| w == LOAD_WARNING), "{done:?}");

    let halted_dir = tmp.path().join("halted");
    let halted = ok(run(&mesh, &halted_dir, &task, false, Some(2)));
    assert!(!halted.complete && halted.iteration == 2, "{halted:?}");
    let resumed = ok(run(&mesh, &halted_dir, &task, true, None));
    assert!(resumed.complete && resumed.iteration == 6, "{resumed:?}");

    // The resumed run is the uninterrupted one, to the bit.
    let saved = |dir: &Path| ok(SavedDeformation::read(dir.join("deformation.npz")));
    let (a, b) = (saved(&whole), saved(&halted_dir));
    assert_eq!(a.verts_normals, b.verts_normals);
    assert_eq!(
        ok(std::fs::read(whole.join("mesh.obj"))),
        ok(std::fs::read(halted_dir.join("mesh.obj")))
    );
    // The objective did something: the loss fell.
    let metrics = ok(std::fs::read_to_string(whole.join("metrics.jsonl")));
    let losses: Vec<f64> = metrics
        .lines()
        .map(|l| json_line(l)["loss"].as_f64().unwrap_or(f64::NAN))
        .collect();
    assert_eq!(losses.len(), 6);
    assert!(losses[5] < losses[0], "{losses:?}");

    // task.json: the kind's fields, the settings it reads, none it does not.
    let task_json = json(&halted_dir.join("task.json"));
    let fields = &task_json["identity"]["fields"];
    assert_eq!(fields["objective"], "squash");
    assert_eq!(fields["squash.direction"], "[0, 0, 1]");
    assert_eq!(fields["config.optim.iterations"], "6");
    assert_eq!(fields["config.optim.lr"], "0.02");
    assert_eq!(fields["config.run.seed"], "0");
    assert!(fields.get("config.darap.lambda").is_some(), "{fields}");
    for absent in [
        "config.optim.steps_per_batch",
        "config.style.iterations",
        "config.guidance.scale",
        "style",
        "prompt",
    ] {
        assert!(fields.get(absent).is_none(), "{absent} in {fields}");
    }

    // deformation.npz: the label and the schedule; run.json: the loading warning.
    let dataset: serde_json::Value = ok(serde_json::from_str(&b.dataset_cfg));
    assert_eq!(dataset["squash"], "0,0,1");
    let csd: serde_json::Value = ok(serde_json::from_str(&b.deform_by_csd_cfg));
    assert_eq!(csd["n_iters"], 6);
    assert_eq!(csd["lr"], 0.02);
    let summary = json(&halted_dir.join("run.json"));
    assert_eq!(summary["objective"], "squash along [0.0, 0.0, 1.0]");
    assert!(
        summary["warnings"]
            .as_array()
            .is_some_and(|w| w.iter().any(|w| w == LOAD_WARNING)),
        "{summary}"
    );

    // A resume of another task is refused, naming the kind's field.
    let again = tmp.path().join("again");
    ok(run(&mesh, &again, &task, false, Some(2)));
    let other = Squash {
        direction: [1.0, 0.0, 0.0],
    };
    let refused = run(&mesh, &again, &other, true, None).map(|_| ());
    let message = format!("{:#}", refused.err().unwrap_or_else(|| panic!("resumed")));
    assert!(
        message.contains("squash.direction: was [0, 0, 1], now [1, 0, 0]"),
        "{message}"
    );
}
