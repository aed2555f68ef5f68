//! `stylize apply` reports λ sanity per output and warns when the result collapses.

#![allow(clippy::unwrap_used)]

use std::path::PathBuf;
use std::process::Command;

fn apply(lambda: &str, out: &std::path::Path) -> (String, String) {
    let saved =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/golden/bunny_targets.npz");
    let o = Command::new(env!("CARGO_BIN_EXE_stylize"))
        .arg("apply")
        .arg(saved)
        .arg("-o")
        .arg(out)
        .args(["--lambda", lambda])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn moderate_lambda_reports_metrics_without_warning() {
    let dir = tempfile::tempdir().unwrap();
    let (stdout, stderr) = apply("5", &dir.path().join("b.obj"));
    assert!(stdout.contains("volume ratio"), "{stdout}");
    assert!(stdout.contains("face-area ratio"), "{stdout}");
    assert!(stdout.contains("flipped"), "{stdout}");
    assert!(!stderr.contains("warning"), "{stderr}");
}

#[test]
fn large_lambda_warns_once_per_output() {
    let dir = tempfile::tempdir().unwrap();
    let (stdout, stderr) = apply("5,20", &dir.path().join("b.obj"));
    assert_eq!(stdout.matches("volume ratio").count(), 2, "{stdout}");
    assert!(stderr.contains("warning: λ = 20"), "{stderr}");
    assert!(!stderr.contains("λ = 5:"), "{stderr}");
}
