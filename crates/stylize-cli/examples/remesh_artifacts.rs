//! The artifact measure of issue 40's end-to-end check (docs/remeshing.md, "End to end"): for
//! each run directory given, how much the stylization distorted the triangulation it was given.
//!
//! - **stretched edges**: the share of edges whose length in the result (`mesh.obj`) is more than
//!   2× or less than ½× their length in the rest mesh (`deformation.npz` `verts`: the source as
//!   optimized, remeshed or not). The cube style flattens and straightens, so an even mesh keeps
//!   almost every edge within 2×; spikes and crumples are edges pulled far out of proportion.
//! - **new self-intersections**: intersecting face pairs the result has and its source has not
//!   (`mesh_core::intersect`, exact predicates).
//!
//! `cargo run --release -p stylize-cli --example remesh_artifacts -- RUN_DIR...`

use anyhow::Context;

fn main() -> anyhow::Result<()> {
    let dirs: Vec<String> = std::env::args().skip(1).collect();
    anyhow::ensure!(!dirs.is_empty(), "usage: remesh_artifacts RUN_DIR...");
    println!(
        "| run | vertices | faces | edges stretched or shrunk > 2× | worst ratio | self-intersecting pairs: source → result (new) | faces in a new pair |"
    );
    println!("|---|---:|---:|---:|---:|---|---:|");
    for dir in dirs {
        let dir = std::path::PathBuf::from(dir);
        let saved = stylize::saved::SavedDeformation::read(dir.join("deformation.npz"))
            .with_context(|| format!("{}", dir.display()))?;
        let source: Vec<[f64; 3]> = saved.verts.iter().map(|p| p.map(f64::from)).collect();
        let result = mesh_core::io::read_mesh(dir.join("mesh.obj"))?;
        anyhow::ensure!(
            result.faces == saved.faces,
            "{}: mesh.obj is not the deformation of deformation.npz's faces",
            dir.display()
        );
        let mut edges: Vec<[u32; 2]> = saved
            .faces
            .iter()
            .flat_map(|f| [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]])
            .map(|[a, b]| [a.min(b), a.max(b)])
            .collect();
        edges.sort_unstable();
        edges.dedup();
        let len = |p: &[[f64; 3]], [a, b]: [u32; 2]| {
            mesh_core::geometry::norm(mesh_core::geometry::sub(p[a as usize], p[b as usize]))
        };
        let (mut distorted, mut worst) = (0usize, 1.0f64);
        for &e in &edges {
            let r = len(&result.positions, e) / len(&source, e);
            let r = if r < 1.0 { 1.0 / r } else { r };
            worst = worst.max(r);
            distorted += usize::from(r > 2.0);
        }
        let si_source = mesh_core::intersect::self_intersections(&source, &saved.faces)?;
        let si_result = mesh_core::intersect::self_intersections(&result.positions, &result.faces)?;
        let new = mesh_core::intersect::new_pairs(&si_source, &si_result)?;
        let mut involved: Vec<u32> = new.iter().flat_map(|&(a, b)| [a, b]).collect();
        involved.sort_unstable();
        involved.dedup();
        println!(
            "| {} | {} | {} | {:.2} % ({distorted} of {}) | {worst:.1}× | {} → {} ({}) | {:.2} % ({}) |",
            dir.display(),
            source.len(),
            saved.faces.len(),
            100.0 * distorted as f64 / edges.len() as f64,
            edges.len(),
            si_source.pairs.len(),
            si_result.pairs.len(),
            new.len(),
            100.0 * involved.len() as f64 / saved.faces.len() as f64,
            involved.len()
        );
    }
    Ok(())
}
