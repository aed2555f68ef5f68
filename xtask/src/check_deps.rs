//! Dependency rules: crates that must stay light do not pull in heavy ones.

use std::process::Command;

/// (crate, forbidden dependencies in its normal dependency tree)
const RULES: &[(&str, &[&str])] = &[
    (
        "darap",
        &[
            "wgpu",
            "ort",
            "tokenizers",
            "tobj",
            "gltf",
            "naga",
            "tokio",
            // Python stays in crates/darap-py.
            "pyo3",
            "numpy",
        ],
    ),
    // The Python bindings: darap plus PyO3/NumPy, nothing heavy (mesh-core without io).
    (
        "darap-py",
        &[
            "wgpu",
            "ort",
            "tokenizers",
            "tobj",
            "gltf",
            "naga",
            "tokio",
            "zip",
        ],
    ),
    ("cotan", &["wgpu", "ort", "tokenizers", "tobj", "gltf"]),
    (
        "csd",
        &["ort", "wgpu", "tokenizers", "raster-diff", "mesh-core"],
    ),
    // The image batch between renderer and guidance: plain data.
    (
        "image-batch",
        &[
            "wgpu",
            "ort",
            "tokenizers",
            "mesh-core",
            "glam",
            "rayon",
            "png",
        ],
    ),
    ("optim", &["wgpu", "ort", "faer", "tokenizers"]),
    // mesh-core without `io` (geometry helpers only: bbox for the camera distance).
    ("raster-diff", &["ort", "tokenizers", "gltf", "zip", "tobj"]),
    // `.npy` only from the npy crate: no zip, and no mesh code.
    ("diffusion-onnx", &["wgpu", "mesh-core", "zip"]),
    // The optimization as a library: no command line, no terminal UI, no signal handling.
    (
        "stylize",
        &["clap", "indicatif", "console", "signal-hook", "crossterm"],
    ),
    // NumPy files: zip (feature npz, on here) and half, nothing heavy and nothing of ours.
    (
        "npy",
        &[
            "wgpu",
            "ort",
            "tokenizers",
            "gltf",
            "naga",
            "tokio",
            "faer",
            "glam",
            "rayon",
            "serde",
            "mesh-core",
        ],
    ),
];

/// (crate, its feature selection, forbidden dependencies): the builds without the heavy features
/// must really leave them out (docs/cli.md, "Builds and features").
const FEATURE_RULES: &[(&str, &[&str], &[&str])] = &[
    // The README's quick-start build: no ONNX Runtime, tokenizer, wgpu stack or HTTP server.
    (
        "stylize-cli",
        &["--no-default-features"],
        &[
            "diffusion-onnx",
            "ort",
            "tokenizers",
            "onig_sys",
            "wgpu",
            "naga",
            "axum",
            "tokio",
        ],
    ),
    (
        "stylize",
        &["--no-default-features"],
        &["diffusion-onnx", "ort", "tokenizers", "wgpu", "naga"],
    ),
];

pub fn run() -> anyhow::Result<()> {
    let mut violations = Vec::new();
    let rules = RULES
        .iter()
        .map(|&(krate, forbidden)| (krate, &[][..], forbidden))
        .chain(FEATURE_RULES.iter().copied());
    for (krate, features, forbidden) in rules {
        let out = Command::new(env!("CARGO"))
            .args([
                "tree", "--quiet", "--edges", "normal", "--prefix", "none", "--format", "{p}",
                "-p", krate,
            ])
            .args(features)
            .output()?;
        anyhow::ensure!(
            out.status.success(),
            "cargo tree -p {krate} failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let tree = String::from_utf8_lossy(&out.stdout);
        let mut names: Vec<&str> = tree
            .lines()
            .filter_map(|l| l.split_whitespace().next())
            .collect();
        names.sort_unstable();
        names.dedup();
        // Guard against a vacuous pass (an empty or unexpected `cargo tree` output).
        anyhow::ensure!(
            names.contains(&krate),
            "cargo tree -p {krate} did not list {krate} itself; output format changed?"
        );
        let build = if features.is_empty() {
            String::new()
        } else {
            format!(" ({})", features.join(" "))
        };
        for f in forbidden {
            if names.contains(f) {
                violations.push(format!("{krate}{build} depends on {f}"));
            }
        }
        println!(
            "{krate}{build}: {} distinct crates in its normal dependency tree, none forbidden: {}",
            names.len(),
            !names.iter().any(|n| forbidden.contains(n))
        );
    }
    anyhow::ensure!(
        violations.is_empty(),
        "dependency rules violated:\n  {}",
        violations.join("\n  ")
    );
    println!("check-deps: all rules hold");
    Ok(())
}
