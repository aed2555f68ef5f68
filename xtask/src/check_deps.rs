//! Dependency rules: crates that must stay light do not pull in heavy ones; and the narrower builds
//! of `scripts/test.sh` resolve every dependency with the workspace build's features, so they reuse
//! its artifacts (`crates/workspace-hack`).

use std::collections::{BTreeMap, BTreeSet};
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
    // Run directories (lock, durable writes, claims, checkpoint container): files and JSON only,
    // nothing numerical, no models, no renderer, no command line or terminal UI.
    (
        "rundir",
        &[
            "mesh-core",
            "cotan",
            "darap",
            "raster-diff",
            "csd",
            "optim",
            "diffusion-onnx",
            "npy",
            "image-batch",
            "rand",
            "rand_chacha",
            "faer",
            "glam",
            "rayon",
            "wgpu",
            "ort",
            "tokenizers",
            "zip",
            "clap",
            "indicatif",
            "console",
            "signal-hook",
            "tokio",
        ],
    ),
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
    // The README's quick-start build: no ONNX Runtime, tokenizer, wgpu stack, HTTP server or H.264
    // encoder.
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
            // the H.264 encoder (C++ compiled from source) and the MP4 box codec: feature `mp4`
            "openh264-sys2",
            "mp4-atom",
        ],
    ),
    (
        "stylize",
        &["--no-default-features"],
        &[
            "diffusion-onnx",
            "ort",
            "tokenizers",
            "wgpu",
            "naga",
            "openh264-sys2",
            "mp4-atom",
        ],
    ),
];

pub fn run() -> anyhow::Result<()> {
    let mut violations = Vec::new();
    let rules = RULES
        .iter()
        .map(|&(krate, forbidden)| (krate, &[][..], forbidden))
        .chain(FEATURE_RULES.iter().copied());
    for (krate, features, forbidden) in rules {
        let selection = [&["-p", krate][..], features].concat();
        let tree = cargo_tree(&["--edges", "normal", "--format", "{p}"], &selection)?;
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
    check_feature_unification()?;
    println!("check-deps: all rules hold");
    Ok(())
}

/// The builds `scripts/test.sh` runs after `cargo test --workspace --all-targets`, with the
/// selection that pins their dependencies' features to that build's.
const NARROWER_BUILDS: &[(&str, &[&str])] = &[
    (
        "the quick-start test build",
        &[
            "-p",
            "stylize-cli",
            "-p",
            "workspace-hack",
            "--no-default-features",
        ],
    ),
    (
        "the Python module (maturin)",
        &["-p", "darap-py", "--features", "workspace-hack"],
    ),
    ("xtask", &["-p", "xtask"]),
];

/// Dependencies allowed to differ in a narrower build, and why.
const UNIFICATION_EXEMPT: &[(&str, &str)] = &[(
    "tower",
    "a dev-dependency of stylize-cli's view tests; the workspace's features would pull tokio into \
     the quick-start test build, and it alone recompiles",
)];

/// Every external dependency of each narrower build must have the features it has in the
/// workspace build (`cargo tree` with the default edges, dev-dependencies included, as the
/// `--all-targets` builds): otherwise Cargo compiles it, and everything above it, a second time.
/// Host (build-script, proc-macro) and target resolutions of one package are compared as a set.
fn check_feature_unification() -> anyhow::Result<()> {
    let workspace = feature_sets(&["--workspace"])?;
    let mut drifted = Vec::new();
    for (build, args) in NARROWER_BUILDS {
        let narrower = feature_sets(args)?;
        let mut differing = 0;
        for (package, features) in &narrower {
            let name = package.split_whitespace().next().unwrap_or_default();
            let wanted = workspace.get(package);
            if wanted == Some(features) {
                continue;
            }
            if let Some((_, why)) = UNIFICATION_EXEMPT.iter().find(|(n, _)| *n == name) {
                println!("  {build}: {package} differs, exempt: {why}");
            } else {
                differing += 1;
                drifted.push(format!(
                    "{build}: {package} has features {features:?}, the workspace build {}",
                    wanted.map_or("does not build it".to_string(), |w| format!("{w:?}"))
                ));
            }
        }
        println!(
            "{build} ({}): {} external packages, {differing} with features other than the workspace build's, exemptions aside",
            args.join(" "),
            narrower.len()
        );
    }
    anyhow::ensure!(
        drifted.is_empty(),
        "the narrower builds would recompile dependencies the workspace build compiled:\n  {}\n\
         Give crates/workspace-hack/Cargo.toml (xtask/Cargo.toml for xtask) an entry for each \
         package with the workspace build's features ([build-dependencies] for proc-macro \
         dependencies such as syn); see crates/workspace-hack/src/lib.rs.",
        drifted.join("\n  ")
    );
    Ok(())
}

/// External packages ("name vX.Y.Z") of one `cargo tree` selection with the feature sets they are
/// resolved with (more than one when host and target resolutions differ).
fn feature_sets(selection: &[&str]) -> anyhow::Result<BTreeMap<String, BTreeSet<String>>> {
    let tree = cargo_tree(&["--format", "{p}|{f}"], selection)?;
    let mut sets: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for line in tree.lines().filter(|l| !l.trim().is_empty()) {
        let (package, features) = line
            .split_once('|')
            .ok_or_else(|| anyhow::anyhow!("unexpected `cargo tree` line {line:?}"))?;
        let features = features.trim_end_matches(" (*)");
        // Workspace members ("name vX (/path)") are compiled per build anyway.
        if package.contains(" (/") {
            continue;
        }
        let package = package.trim_end_matches(" (proc-macro)").trim();
        sets.entry(package.to_string())
            .or_default()
            .insert(features.to_string());
    }
    anyhow::ensure!(
        !sets.is_empty(),
        "cargo tree {} listed no external package; output format changed?",
        selection.join(" ")
    );
    Ok(sets)
}

/// `cargo tree --quiet --prefix none ARGS SELECTION`'s output.
fn cargo_tree(args: &[&str], selection: &[&str]) -> anyhow::Result<String> {
    let out = Command::new(env!("CARGO"))
        .args(["tree", "--quiet", "--prefix", "none"])
        .args(args)
        .args(selection)
        .output()?;
    anyhow::ensure!(
        out.status.success(),
        "cargo tree {} failed: {}",
        selection.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}
