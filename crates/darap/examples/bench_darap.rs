//! dARAP timings: precompute, forward, backward and forward+backward on meshes of ~2k to ~160k
//! vertices, with 1 and 2 rayon threads and sequential sparse solves (the default, see
//! `cotan::PinnedCholesky`), plus 2 rayon threads with 2-thread solves (`faer::Par::rayon(2)`).
//!
//! `cargo run --release -p darap --example bench_darap -- [--max-vertices N] [--reps N]`
//!
//! Meshes: the golden bunny (1,839 V) and its midpoint subdivisions (`fixtures/golden/bunny.obj`,
//! normalized to the side-2 cube), and icospheres of 10,242 / 40,962 / 163,842 V.

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
            darap::procedural::icosphere(level),
        ));
    }
    meshes.retain(|(_, m)| m.positions.len() <= max_vertices);
    meshes.sort_by_key(|(_, m)| m.positions.len());

    println!(
        "| mesh | V | rayon threads | solver threads | precompute ms | forward ms | backward ms | fwd+bwd ms |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|");
    for (name, mesh) in &meshes {
        for (threads, solver_threads) in [(1usize, 1usize), (2, 1), (2, 2)] {
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
                let mut layer = layer.ok_or(darap::DarapError::NoFaces)?;
                layer.set_solver_parallelism(if solver_threads > 1 {
                    faer::Par::rayon(solver_threads)
                } else {
                    faer::Par::Seq
                });
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
                    "| {name} | {} | {threads} | {solver_threads} | {pre:.1} | {fwd:.2} | {bwd:.2} | {both:.2} |",
                    mesh.positions.len()
                );
                Ok(())
            })?;
        }
    }
    Ok(())
}
