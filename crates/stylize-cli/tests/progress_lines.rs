//! `stylize run` with stderr not a terminal (a Slurm log, a pipe): plain progress lines instead of
//! an invisible progress bar.

use std::process::Command;

#[test]
fn a_run_logged_to_a_pipe_prints_plain_progress_lines() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let mesh = tmp.path().join("ball.obj");
    mesh_core::io::write_mesh(&mesh, &mesh_core::shapes::icosphere(2), None).expect("write mesh");
    let run = tmp.path().join("run");
    let out = Command::new(env!("CARGO_BIN_EXE_stylize"))
        .args([
            "run",
            mesh.to_str().unwrap_or_default(),
            "--style",
            "cube",
            "-o",
        ])
        .arg(&run)
        .args([
            "--set",
            "style.iterations=4",
            "--set",
            "run.turntable_size=16",
        ])
        .output()
        .expect("stylize runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    // The headline, the first iteration (always printed) and the last.
    assert!(stderr.contains("vertices)"), "{stderr}");
    assert!(stderr.contains("iter 1/4  loss "), "{stderr}");
    assert!(stderr.contains("iter 4/4  loss "), "{stderr}");
    assert!(stderr.contains("eta "), "{stderr}");
}
