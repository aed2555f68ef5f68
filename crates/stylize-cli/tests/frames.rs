//! Output frames and orientation end to end (`stylize::frame`, docs/formats.md "Frames"): a z-up
//! mesh in millimetres far from the origin comes back from `run` and `apply` in its own frame —
//! the `--output-frame normalized` run's mesh mapped by the recorded `to_input_frame` — and at
//! λ = 0 it comes back as itself; `--up z` on a z-up mesh renders the views of the y-up mesh.
//! (The viewer's downloads: `view_api.rs`.)
//!
//! Cost: about a dozen model-free runs of 2–6 iterations on a 162-vertex icosphere (tiny
//! pictures): about a second.

use std::path::{Path, PathBuf};

use mesh_core::TriMesh;
use stylize::frame::{OutputFrame, UpAxis};
use stylize::runner::RunRequest;
use stylize::saved::SavedDeformation;
use stylize::style::Style;
use stylize_cli::config::Config;
use stylize_cli::runner::{LogMode, execute};

mod common;
use common::{ok, s, stderr, stylize};

/// An ellipsoid standing up along y (taller than wide: the icosphere of 2 subdivisions scaled).
fn standing() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
    (
        p.iter()
            .map(|v| [0.6 * v[0], 1.3 * v[1], 0.8 * v[2]])
            .collect(),
        f,
    )
}

/// The same shape as exported by a z-up tool: y-up `(x, y, z)` becomes `(x, −z, y)` (exact), then
/// (`scaled`) millimetres (× 1000) and an offset far from the origin.
fn z_up(scaled: bool) -> Vec<[f64; 3]> {
    standing()
        .0
        .iter()
        .map(|p| {
            let q = [p[0], -p[2], p[1]];
            if scaled {
                [
                    1000.0 * q[0] + 25_000.0,
                    1000.0 * q[1] - 3_000.0,
                    1000.0 * q[2] + 740.0,
                ]
            } else {
                q
            }
        })
        .collect()
}

fn write(dir: &Path, name: &str, positions: Vec<[f64; 3]>) -> PathBuf {
    let path = dir.join(name);
    ok(mesh_core::io::write_mesh(
        &path,
        &TriMesh::new(positions, standing().1),
        None,
    ));
    path
}

fn config(up: UpAxis, frame: OutputFrame) -> Config {
    let mut c = Config::default();
    c.style.iterations = 6;
    c.run.checkpoint_every = 0;
    c.run.preview_every = 0;
    c.run.turntable_views = 2;
    c.run.turntable_size = 48;
    c.run.turntable_gif_frames = 0;
    c.run.snapshot_every = 0;
    c.mesh.up = up;
    c.run.output_frame = frame;
    c
}

fn run(mesh: &Path, out: &Path, config: Config) {
    let request = RunRequest {
        mesh: mesh.to_path_buf(),
        out: out.to_path_buf(),
        config,
        force: false,
        resume: false,
        halt_after: None,
    };
    assert!(ok(execute(&request, LogMode::Quiet, Style::Cube)).complete);
}

fn positions(path: &Path) -> Vec<[f64; 3]> {
    ok(mesh_core::io::read_mesh(path)).positions
}

fn max_abs_diff(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs()))
        .fold(0.0, f64::max)
}

#[test]
fn a_z_up_millimetre_mesh_comes_back_from_run_and_apply_in_its_own_frame() {
    let tmp = ok(tempfile::tempdir());
    let input = z_up(true);
    let mesh = write(tmp.path(), "part_mm.obj", input.clone());
    let (own, normalized) = (tmp.path().join("own"), tmp.path().join("normalized"));
    run(&mesh, &own, config(UpAxis::PosZ, OutputFrame::Input));
    run(
        &mesh,
        &normalized,
        config(UpAxis::PosZ, OutputFrame::Normalized),
    );

    // The same optimization (the frame is presentation only): the same saved deformation.
    let saved = ok(SavedDeformation::read(own.join("deformation.npz")));
    let saved_n = ok(SavedDeformation::read(normalized.join("deformation.npz")));
    assert_eq!(
        (&saved.verts, &saved.verts_normals),
        (&saved_n.verts, &saved_n.verts_normals)
    );
    assert_eq!(ok(saved.output_frame()), OutputFrame::Input);
    assert_eq!(ok(saved_n.output_frame()), OutputFrame::Normalized);
    assert_eq!(ok(saved.up()), UpAxis::PosZ);
    let frame = ok(saved.input_frame()).unwrap_or_else(|| panic!("no to_input_frame"));
    assert_eq!(ok(saved_n.input_frame()), Some(frame));

    // run: mesh.obj in the input's frame = the normalized run's mesh mapped back.
    let rest = saved.rest_positions();
    let result_n = positions(&normalized.join("mesh.obj"));
    let expected = frame.place_result(&result_n, &rest, true);
    let result = positions(&own.join("mesh.obj"));
    let d = max_abs_diff(&result, &expected);
    assert!(d < 1e-9, "run: input frame vs mapped normalized: {d}");
    // It sits where the input was, at its scale: the bounding-box diagonal is the input's (dARAP's
    // post-process keeps the rest diagonal), the vertex centroid is the input's, and z is still
    // the long axis.
    let (lo, hi) = mesh_core::geometry::bbox(&result);
    let (ilo, ihi) = mesh_core::geometry::bbox(&input);
    let (diag, idiag) = (
        mesh_core::geometry::bbox_diagonal(&result),
        mesh_core::geometry::bbox_diagonal(&input),
    );
    assert!(
        (diag / idiag - 1.0).abs() < 1e-6,
        "diagonal {diag} vs {idiag}"
    );
    assert!(hi[2] - lo[2] > 1.5 * (hi[1] - lo[1]) && ihi[2] - ilo[2] > 1.5 * (ihi[1] - ilo[1]));
    let (c, ic) = (
        mesh_core::geometry::vertex_centroid(&result),
        mesh_core::geometry::vertex_centroid(&input),
    );
    assert!(
        max_abs_diff(&[c], &[ic]) < 1e-6 * 25_000.0,
        "{c:?} vs {ic:?}"
    );
    // The normalized run's mesh is the side-2 frame with +y up (z of the input).
    let (nlo, nhi) = mesh_core::geometry::bbox(&result_n);
    assert!(
        nhi[1] - nlo[1] > 1.5 && nhi[2] - nlo[2] < 1.5,
        "{nlo:?} {nhi:?}"
    );

    // apply: the input frame by default, the normalized one on request.
    let applied = tmp.path().join("applied.obj");
    let out = stylize(&["apply", s(&own.join("deformation.npz")), "-o", s(&applied)]);
    assert!(out.status.success(), "{}", stderr(&out));
    let d = max_abs_diff(&positions(&applied), &result);
    assert!(d < 1e-9, "apply vs the run's mesh.obj: {d}");
    let applied_n = tmp.path().join("applied_n.obj");
    let out = stylize(&[
        "apply",
        s(&own.join("deformation.npz")),
        "-o",
        s(&applied_n),
        "--output-frame",
        "normalized",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let d = max_abs_diff(&positions(&applied_n), &result_n);
    assert!(
        d < 1e-12,
        "apply --output-frame normalized vs the normalized run: {d}"
    );

    // eval does not depend on the output frame.
    let eval = |dir: &Path| {
        let out = stylize(&["eval", s(dir), "--json"]);
        assert!(out.status.success(), "{}", stderr(&out));
        let v: serde_json::Value = ok(serde_json::from_slice(&out.stdout));
        [
            v["area_ratio_mean"].as_f64().unwrap_or(f64::NAN),
            v["area_ratio_std"].as_f64().unwrap_or(f64::NAN),
            v["volume_ratio_mean"].as_f64().unwrap_or(f64::NAN),
        ]
    };
    let (a, b) = (eval(&own), eval(&normalized));
    for k in 0..3 {
        assert!((a[k] - b[k]).abs() < 1e-9, "eval {a:?} vs {b:?}");
    }
}

#[test]
fn at_lambda_zero_the_input_comes_back_as_itself() {
    let tmp = ok(tempfile::tempdir());
    let input = z_up(true);
    let mesh = write(tmp.path(), "part_mm.obj", input.clone());
    let out = tmp.path().join("run");
    let mut c = config(UpAxis::PosZ, OutputFrame::Input);
    c.darap.lambda = 0.0;
    run(&mesh, &out, c);
    // Up to the f32 rounding of the normalized rest mesh (2⁻²⁴ of a side of 2, in millimetres).
    let d = max_abs_diff(&positions(&out.join("mesh.obj")), &input);
    assert!(
        d < 2.6e3 * 2.0f64.powi(-22),
        "λ = 0 result vs the input: {d} mm"
    );
}

#[test]
fn up_z_on_a_z_up_mesh_renders_the_views_of_the_y_up_mesh() {
    let tmp = ok(tempfile::tempdir());
    let y_up = write(tmp.path(), "y_up.obj", standing().0);
    let z_up_mesh = write(tmp.path(), "z_up.obj", z_up(false));
    let run_dir = |name: &str, mesh: &Path, up: UpAxis| {
        let out = tmp.path().join(name);
        run(mesh, &out, config(up, OutputFrame::Normalized));
        out
    };
    let a = run_dir("y", &y_up, UpAxis::PosY);
    let b = run_dir("z_turned", &z_up_mesh, UpAxis::PosZ);
    let c = run_dir("z_as_is", &z_up_mesh, UpAxis::PosY);
    for picture in ["turntable.png", "before_after.png"] {
        let read = |d: &Path| ok(std::fs::read(d.join(picture)));
        assert!(read(&a) == read(&b), "{picture}: --up z differs from y-up");
        // The comparison can fail: the z-up mesh taken as y-up lies on its side.
        assert!(
            read(&a) != read(&c),
            "{picture}: the lying mesh renders the same"
        );
    }
    // The turn is exact, so the optimized result is the same too.
    assert_eq!(
        positions(&a.join("mesh.obj")),
        positions(&b.join("mesh.obj"))
    );
}

#[test]
fn camera_auto_picks_the_tall_preset_for_tall_slim_meshes_and_records_what_it_chose() {
    use stylize::config::CameraPreset;
    let tmp = ok(tempfile::tempdir());
    // Standing: height 1.3 / widest horizontal 0.8 = 1.6 ≥ 1.5 → tall. Lying (z-up, taken as
    // y-up): height 0.8 / 1.3 → default; the same file with --up z → tall again.
    let standing_mesh = write(tmp.path(), "standing.obj", standing().0);
    let lying_mesh = write(tmp.path(), "lying.obj", z_up(true));
    let prompt = stylize::task::Prompt::new("a 3d render of a knight in armor");
    let prepare = |mesh: &Path, preset: CameraPreset, up: UpAxis| {
        let mut config = config(up, OutputFrame::Input);
        config.camera.preset = preset;
        let request = RunRequest {
            mesh: mesh.to_path_buf(),
            out: tmp.path().join("unused"),
            config,
            force: false,
            resume: false,
            halt_after: None,
        };
        ok(stylize::runner::prepare(&request, &prompt))
    };
    let tall = prepare(&standing_mesh, CameraPreset::Auto, UpAxis::PosY);
    assert_eq!(tall.config.camera.preset, CameraPreset::Tall);
    assert_eq!(
        (
            tall.config.camera.sampler.elevation_deg,
            tall.config.camera.sampler.distance
        ),
        ([0.0, 30.0], [1.4, 2.6])
    );
    let why = tall.camera_choice.clone().unwrap_or_default();
    assert!(
        why.contains("auto → tall") && why.contains("height / widest horizontal extent = 1.6"),
        "{why}"
    );
    assert!(
        tall.config_toml.contains("preset = \"tall\""),
        "{}",
        tall.config_toml
    );
    // The identity records the resolved preset and ranges: the same task as `--camera tall`.
    let named = prepare(&standing_mesh, CameraPreset::Tall, UpAxis::PosY);
    assert_eq!(tall.identity, named.identity);
    assert_eq!(named.camera_choice, None);
    assert_eq!(
        tall.identity
            .fields
            .get("config.camera.preset")
            .map(String::as_str),
        Some("\"tall\"")
    );
    let lying = prepare(&lying_mesh, CameraPreset::Auto, UpAxis::PosY);
    assert_eq!(lying.config.camera.preset, CameraPreset::Default);
    assert!(
        lying
            .camera_choice
            .unwrap_or_default()
            .contains("auto → default")
    );
    // An auto that resolves to default is the same task as no preset at all.
    let plain = prepare(&lying_mesh, CameraPreset::Default, UpAxis::PosY);
    assert_eq!(lying.identity, plain.identity);
    assert!(!plain.identity.fields.contains_key("config.camera.preset"));
    let turned = prepare(&lying_mesh, CameraPreset::Auto, UpAxis::PosZ);
    assert_eq!(turned.config.camera.preset, CameraPreset::Tall);
    assert_eq!(
        turned
            .identity
            .fields
            .get("config.mesh.up")
            .map(String::as_str),
        Some("\"+z\"")
    );
}

#[test]
fn flags_and_manifest_columns_set_up_frame_and_camera() {
    let tmp = ok(tempfile::tempdir());
    let mesh = write(tmp.path(), "part_mm.obj", z_up(true));
    let small = [
        "--set",
        "style.iterations=2",
        "--set",
        "run.turntable_views=1",
        "--set",
        "run.turntable_size=16",
        "--set",
        "run.turntable_gif_frames=0",
        "--quiet",
    ];
    let summary = |dir: &Path| -> serde_json::Value {
        ok(serde_json::from_slice(&ok(std::fs::read(
            dir.join("run.json"),
        ))))
    };
    let run_dir = tmp.path().join("cli");
    let mut args = vec![
        "run",
        s(&mesh),
        "--style",
        "cube",
        "--out",
        s(&run_dir),
        "--up",
        "z",
        "--output-frame",
        "normalized",
        "--camera",
        "tall",
    ];
    args.extend(small);
    let out = stylize(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    let j = summary(&run_dir);
    assert_eq!(
        (&j["up"], &j["output_frame"], &j["camera_preset"]),
        (&"+z".into(), &"normalized".into(), &"tall".into())
    );
    let bad = stylize(&[
        "run",
        s(&mesh),
        "--style",
        "cube",
        "--out",
        "x",
        "--up",
        "w",
    ]);
    assert!(
        !bad.status.success() && stderr(&bad).contains("unknown up axis"),
        "{}",
        stderr(&bad)
    );

    let manifest = tmp.path().join("rows.jsonl");
    ok(std::fs::write(
        &manifest,
        "{\"mesh\": \"part_mm.obj\", \"style\": \"cube\", \"out\": \"runs/a\", \"up\": \"+z\", \
         \"output_frame\": \"normalized\", \"camera\": \"auto\"}\n",
    ));
    let mut args = vec!["batch", s(&manifest)];
    args.extend(small);
    let out = stylize(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    let j = summary(&tmp.path().join("runs/a"));
    assert_eq!(
        (&j["up"], &j["output_frame"]),
        (&"+z".into(), &"normalized".into())
    );
    // auto resolved on the turned mesh (tall and slim once z is up).
    assert_eq!(j["camera_preset"], "tall");
    ok(std::fs::write(
        &manifest,
        "{\"mesh\": \"part_mm.obj\", \"style\": \"cube\", \"out\": \"runs/a\", \"up\": \"sideways\"}\n",
    ));
    let out = stylize(&["batch", s(&manifest)]);
    let err = stderr(&out);
    assert!(
        !out.status.success() && err.contains("row 0") && err.contains("`up`"),
        "{err}"
    );
}

#[test]
fn a_batch_skipping_a_complete_run_rewrites_its_mesh_files_in_the_frame_asked_for() {
    let tmp = ok(tempfile::tempdir());
    write(tmp.path(), "part_mm.obj", z_up(true));
    let manifest = tmp.path().join("rows.jsonl");
    ok(std::fs::write(
        &manifest,
        "{\"mesh\": \"part_mm.obj\", \"style\": \"cube\", \"out\": \"runs/a\", \"up\": \"z\"}\n",
    ));
    let batch = |frame: &str| {
        let out = stylize(&[
            "batch",
            s(&manifest),
            "--output-frame",
            frame,
            "--set",
            "style.iterations=3",
            "--set",
            "run.turntable_views=1",
            "--set",
            "run.turntable_size=16",
            "--set",
            "run.turntable_gif_frames=0",
            "--quiet",
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
        stderr(&out)
    };
    let dir = tmp.path().join("runs/a");
    batch("normalized");
    let normalized = positions(&dir.join("mesh.obj"));
    let err = batch("input");
    assert!(
        err.contains("skipped") && err.contains("rewritten"),
        "{err}"
    );
    let saved = ok(SavedDeformation::read(dir.join("deformation.npz")));
    assert_eq!(ok(saved.output_frame()), OutputFrame::Input);
    let frame = ok(saved.input_frame()).unwrap_or_else(|| panic!("no to_input_frame"));
    let expected = frame.place_result(&normalized, &saved.rest_positions(), true);
    let d = max_abs_diff(&positions(&dir.join("mesh.obj")), &expected);
    assert!(d < 1e-9, "rewritten mesh vs the normalized one mapped: {d}");
    let summary: serde_json::Value = ok(serde_json::from_slice(&ok(std::fs::read(
        dir.join("run.json"),
    ))));
    assert_eq!(summary["output_frame"], "input");
    // And back: the normalized files again, exactly.
    batch("normalized");
    assert_eq!(positions(&dir.join("mesh.obj")), normalized);
}
