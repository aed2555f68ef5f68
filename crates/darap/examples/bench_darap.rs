//! dARAP timings: precompute, forward, backward and forward+backward on meshes of ~2k to ~160k
//! vertices, with 1 and 2 rayon threads (the sparse solves are sequential, see
//! `cotan::PinnedCholesky`).
//!
//! `cargo run --release -p darap --example bench_darap -- [--max-vertices N] [--reps N]
//! [--threads N] [--mesh PATH]... [--only NAME]`
//!
//! Meshes: the golden bunny (1,839 V) and its midpoint subdivisions (`fixtures/golden/bunny.obj`,
//! normalized to the side-2 cube), CGAL's cow and fandisk, icospheres of 10,242 / 40,962 /
//! 163,842 V, plus any `--mesh PATH` (any format `mesh_core::io` reads). `--threads N` runs only
//! the N-thread rows (use with `taskset -c K` for one-core numbers); `--only NAME` one mesh (for
//! profiling). The factor column is the
//! number of stored entries of the pinned Laplacian's Cholesky factor.

use darap::{Darap, DarapOptions};
use mesh_core::TriMesh;
use std::time::Instant;

fn median_ms(mut f: impl FnMut(), reps: usize) -> f64 {
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str, default: usize| -> usize {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    };
    let max_vertices = arg("--max-vertices", 200_000);
    let reps = arg("--reps", 11).max(1);
    let only_threads = arg("--threads", 0);
    let extra: Vec<&String> = args
        .iter()
        .enumerate()
        .filter(|(i, _)| *i > 0 && args[i - 1] == "--mesh")
        .map(|(_, a)| a)
        .collect();

    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../fixtures/golden/bunny.obj"
    );
    let mut bunny = mesh_core::io::read_mesh(path)?;
    mesh_core::normalize::side2_cube(&mut bunny.positions);
    let mut meshes: Vec<(String, TriMesh)> = Vec::new();
    let mut m = bunny;
    for level in 0..4 {
        meshes.push((format!("bunny/{level}"), m.clone()));
        m = mesh_core::subdivide::midpoint(&m);
    }
    // CGAL's cow (2,904 V) and fandisk (6,475 V) bracket the 5k-vertex target size.
    for name in ["cow", "fandisk"] {
        let path = format!(
            "{}/../../fixtures/meshes/{name}.off",
            env!("CARGO_MANIFEST_DIR")
        );
        let mut mesh = mesh_core::io::read_mesh(&path)?;
        mesh_core::normalize::side2_cube(&mut mesh.positions);
        meshes.push((name.to_string(), mesh));
    }
    for level in [5, 6, 7] {
        meshes.push((
            format!("icosphere/{level}"),
            mesh_core::shapes::icosphere(level),
        ));
    }
    for path in extra {
        let mut mesh = mesh_core::io::read_mesh(path)?;
        mesh_core::normalize::side2_cube(&mut mesh.positions);
        let name = std::path::Path::new(path)
            .file_stem()
            .map_or_else(|| path.clone(), |s| s.to_string_lossy().into_owned());
        meshes.push((name, mesh));
    }
    meshes.retain(|(_, m)| m.positions.len() <= max_vertices);
    if let Some(only) = args
        .iter()
        .position(|a| a == "--only")
        .and_then(|i| args.get(i + 1))
    {
        meshes.retain(|(name, _)| name == only);
    }
    meshes.sort_by_key(|(_, m)| m.positions.len());

    println!(
        "| mesh | V | factor nnz | rayon threads | precompute ms | forward ms | backward ms | fwd+bwd ms |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|");
    for (name, mesh) in &meshes {
        for threads in [1usize, 2] {
            if only_threads != 0 && threads != only_threads {
                continue;
            }
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()?;
            pool.install(|| -> Result<(), darap::DarapError> {
                let pre_reps = if mesh.positions.len() > 50_000 {
                    3
                } else {
                    reps.min(5)
                };
                let mut layer = None;
                let pre = median_ms(
                    || {
                        layer =
                            Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default()).ok()
                    },
                    pre_reps,
                );
                let layer = layer.ok_or(darap::DarapError::NoFaces)?;
                let x: Vec<[f64; 3]> = layer
                    .rest_normals()
                    .iter()
                    .enumerate()
                    .map(|(i, n)| {
                        let s = (i as f64 * 0.618).sin() * 0.4;
                        [n[0] + s, n[1] - 0.5 * s, n[2] + 0.2]
                    })
                    .collect();
                let state = layer.forward(&x)?;
                let g = state.positions.clone();
                let fwd = median_ms(
                    || {
                        std::hint::black_box(layer.forward(&x).ok());
                    },
                    reps,
                );
                let bwd = median_ms(
                    || {
                        std::hint::black_box(layer.backward(&state, &g));
                    },
                    reps,
                );
                let both = median_ms(
                    || {
                        if let Ok(s) = layer.forward(&x) {
                            std::hint::black_box(layer.backward(&s, &g));
                        }
                    },
                    reps,
                );
                println!(
                    "| {name} | {} | {} | {threads} | {pre:.1} | {fwd:.3} | {bwd:.3} | {both:.3} |",
                    mesh.positions.len(),
                    layer.factor_nnz(),
                );
                Ok(())
            })?;
        }
    }
    Ok(())
}
