//! Latency of the viewer's λ slider: one `GET api/items/0/result?lambda=L` answered by the
//! viewer's router (dARAP re-solve at λ with the prefactored layer, λ diagnostics, f32 framing) —
//! everything the server does for one slider move; the browser's upload and draw come on top.
//!
//! Meshes: the golden bunny (1 839 vertices) and the cow fixture midpoint-subdivided once and twice
//! (11 610 and 46 434 vertices: the ~2k/10k/40k of issue 12), then the bunny subdivided once,
//! twice and three times; targets are the cube style's (each rest normal snapped to the nearest
//! axis), saved as a run's `deformation.npz` at λ = 8.
//!
//! `cargo run --release -p stylize-cli --example view_latency [REPEATS]`
//!
//! Prints the wall-clock median and 90th percentile per request and the process's CPU time per
//! request (all threads: the self-intersection check runs on up to 2).

#![allow(clippy::unwrap_used)]

use std::sync::Arc;
use std::time::Instant;

use axum::body::Body;
use axum::http::Request;
use mesh_core::TriMesh;
use stylize::saved::SavedDeformation;
use stylize_cli::view::{Viewer, server::router};
use tower::ServiceExt;

fn snap(n: [f64; 3]) -> [f32; 3] {
    let k = (0..3)
        .max_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
        .unwrap();
    let mut t = [0.0f32; 3];
    t[k] = n[k].signum() as f32;
    t
}

fn main() {
    let repeats: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(30);
    let golden = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/golden/bunny_targets.npz");
    let base = SavedDeformation::read(&golden).unwrap();
    let bunny = TriMesh::new(
        base.verts.iter().map(|v| v.map(f64::from)).collect(),
        base.faces.clone(),
    );
    let mut cow = mesh_core::io::read_mesh(
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/meshes/cow.off"),
    )
    .unwrap();
    mesh_core::normalize::side2_cube(&mut cow.positions);
    let subdivided = |m: &TriMesh, levels: usize| {
        let mut m = m.clone();
        for _ in 0..levels {
            m = mesh_core::subdivide::midpoint(&m);
        }
        m
    };
    let meshes = [
        ("bunny", bunny.clone()),
        ("cow ×1", subdivided(&cow, 1)),
        ("cow ×2", subdivided(&cow, 2)),
        ("bunny ×1", subdivided(&bunny, 1)),
        ("bunny ×2", subdivided(&bunny, 2)),
        ("bunny ×3", subdivided(&bunny, 3)),
    ];
    let rt = tokio::runtime::Builder::new_current_thread()
        .build()
        .unwrap();
    println!("| mesh | vertices | faces | median ms | p90 ms | CPU ms per request |");
    println!("|---|---:|---:|---:|---:|---:|");
    for (label, mesh) in &meshes {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("run");
        std::fs::create_dir_all(&run).unwrap();
        let normals =
            mesh_core::normals::vertex_normals_area_weighted(&mesh.positions, &mesh.faces);
        let saved = SavedDeformation {
            verts: mesh.positions.iter().map(|p| p.map(|c| c as f32)).collect(),
            faces: mesh.faces.clone(),
            verts_normals: normals.iter().map(|&n| snap(n)).collect(),
            ..base.clone()
        };
        saved.write(run.join("deformation.npz")).unwrap();
        let app = router(Arc::new(
            Viewer::open(std::slice::from_ref(&run), "t".into()).unwrap(),
        ));
        let mut ms = Vec::new();
        let mut cpu0 = 0.0;
        rt.block_on(async {
            for i in 0..repeats + 1 {
                // Alternate λ like a slider moving back and forth.
                let lambda = 4.0 + (i % 7) as f64;
                let req = Request::builder()
                    .uri(format!("/t/api/items/0/result?lambda={lambda}"))
                    .body(Body::empty())
                    .unwrap();
                if i == 1 {
                    cpu0 = process_cpu_ms();
                }
                let t0 = Instant::now();
                let resp = app.clone().oneshot(req).await.unwrap();
                let body = axum::body::to_bytes(resp.into_body(), usize::MAX)
                    .await
                    .unwrap();
                let dt = t0.elapsed().as_secs_f64() * 1e3;
                assert!(body.len() >= 12 * mesh.positions.len());
                if i > 0 {
                    // The first request builds and factors the layer.
                    ms.push(dt);
                }
            }
        });
        let cpu = (process_cpu_ms() - cpu0) / ms.len() as f64;
        ms.sort_by(f64::total_cmp);
        println!(
            "| {label} | {} | {} | {:.1} | {:.1} | {cpu:.1} |",
            mesh.positions.len(),
            mesh.faces.len(),
            ms[ms.len() / 2],
            ms[(ms.len() * 9) / 10]
        );
    }
}

/// CPU time of the whole process (all threads) in ms (`/proc/self/stat` utime + stime, 10 ms
/// ticks): on a machine shared with other work, time spent waiting for a core does not count, and
/// on an idle machine a request's wall time is at most its CPU time (its only waits are for its
/// own threads).
fn process_cpu_ms() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap();
    let rest = &stat[stat.rfind(')').unwrap() + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    (f[11].parse::<f64>().unwrap() + f[12].parse::<f64>().unwrap()) * 10.0
}
