//! What this binary was built with: the crate features `text`, `gpu`, `view` and `mp4` (all
//! default).
//!
//! A quick-start build (the README's first command: `--no-default-features`)
//! keeps every subcommand and option, so scripts and `--help` read the same; what needs a missing
//! feature fails before any work with [`not_built`], which names the commands that build the full
//! binary or add just that feature ([`cargo_run_adding`]); the library's `stylize::models`
//! refuses to load models in such a build too (`stylize::Error::NotBuilt`), after these checks.
//! Without `gpu`, `render.backend = "auto"` uses the CPU renderer and says so in the run's log,
//! as on a machine without a GPU; `"gpu"` fails with raster-diff's error naming the missing
//! feature.

/// Every feature, and whether this binary was built with it.
pub const ENABLED: &[(&str, bool)] = &[
    ("text", cfg!(feature = "text")),
    ("gpu", cfg!(feature = "gpu")),
    ("view", cfg!(feature = "view")),
    ("mp4", cfg!(feature = "mp4")),
];

/// The names of this binary's features plus `extra` (if any), in [`ENABLED`]'s order.
fn names_with(extra: Option<&str>) -> Vec<&'static str> {
    ENABLED
        .iter()
        .filter_map(|&(name, on)| (on || extra == Some(name)).then_some(name))
        .collect()
}

/// This binary's features for `stylize --version`: `text, gpu, view`, or `none`; a build with
/// the non-default `cuda` feature (ONNX Runtime's CUDA provider) adds `cuda`.
pub fn summary() -> String {
    let mut names = names_with(None);
    if cfg!(feature = "cuda") {
        names.push("cuda");
    }
    if names.is_empty() {
        "none".to_owned()
    } else {
        names.join(", ")
    }
}

/// The `cargo run` prefix (ending in `--`) that builds, in the repository, this binary's features
/// plus `feature`: `cargo run --release --no-default-features --features view --bin stylize --`
/// from the quick-start build; the plain `cargo run --release --bin stylize --` once that is every
/// feature.
pub fn cargo_run_adding(feature: &str) -> String {
    let wanted = names_with(Some(feature));
    if wanted.len() == ENABLED.len() {
        "cargo run --release --bin stylize --".to_owned()
    } else {
        format!(
            "cargo run --release --no-default-features --features {} --bin stylize --",
            wanted.join(",")
        )
    }
}

/// The error of a command or option (`what`) that needs `feature`, in a binary built without it.
pub fn not_built(feature: &str, what: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{what} needs the `{feature}` feature, and this stylize was built without it (a quick-start \
         build, as the README's first command makes). Build the full command line with \
         `cargo install --locked --path crates/stylize-cli`, or run it in place with \
         `cargo run --release --bin stylize -- …` (default features: text, gpu, view, mp4), or add just \
         this feature to this build with `{} …` (docs/cli.md, \"Builds and features\")",
        cargo_run_adding(feature)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cargo_run_adding_keeps_this_builds_features_and_adds_one() {
        let command = cargo_run_adding("view");
        if cfg!(all(feature = "text", feature = "gpu", feature = "mp4")) {
            // The default build (CI's workspace tests): adding `view` is every feature.
            assert_eq!(command, "cargo run --release --bin stylize --");
        } else if cfg!(not(any(
            feature = "text",
            feature = "gpu",
            feature = "view",
            feature = "mp4"
        ))) {
            // The quick-start build (CI's `--no-default-features` test).
            assert_eq!(
                command,
                "cargo run --release --no-default-features --features view --bin stylize --"
            );
        } else {
            let list = format!("--features {} --bin", names_with(Some("view")).join(","));
            assert!(
                command.contains("--no-default-features") && command.contains(&list),
                "{command}"
            );
        }
    }

    #[test]
    fn summary_names_this_builds_features() {
        let s = summary();
        if cfg!(all(
            feature = "text",
            feature = "gpu",
            feature = "view",
            feature = "mp4"
        )) {
            assert_eq!(s, "text, gpu, view, mp4");
        } else if cfg!(not(any(
            feature = "text",
            feature = "gpu",
            feature = "view",
            feature = "mp4"
        ))) {
            assert_eq!(s, "none");
        }
    }
}
