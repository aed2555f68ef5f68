//! The artifact measure of issue 40's end-to-end check (docs/remeshing.md, "End to end"): for
//! each run directory given, how much the stylization distorted the triangulation it was given.
//!
//! - **stretched edges** (`stylize::remeshing::stretched_edges`): the share of edges whose length in
//!   the result (`mesh.obj`, mapped back to the normalized frame) is more than 2× or less than ½×
//!   their length in the rest mesh (`deformation.npz` `verts`: the source as optimized, remeshed or
//!   not). The cube style flattens and straightens, so an even mesh keeps almost every edge within
//!   2×; spikes and crumples are edges pulled far out of proportion.
//! - **new self-intersections**: intersecting face pairs the result has and its source has not
//!   (`mesh_core::intersect`, exact predicates), the faces in such a pair, and their share of the
//!   result's area (which, unlike the counts, does not grow with the resolution).
//!
//! `cargo run --release -p stylize-cli --example remesh_artifacts -- RUN_DIR...`

use anyhow::Context;

fn main() -> anyhow::Result<()> {
    let dirs: Vec<String> = std::env::args().skip(1).collect();
    anyhow::ensure!(!dirs.is_empty(), "usage: remesh_artifacts RUN_DIR...");
    println!(
        "| run | vertices | faces | edges stretched or shrunk > 2× | worst ratio | self-intersecting pairs: source → result (new) | faces in a new pair | their share of the area |"
    );
    println!("|---|---:|---:|---:|---:|---|---:|---:|");
    for dir in dirs {
        let dir = std::path::PathBuf::from(dir);
        // Both in the normalized frame (mesh.obj is written in the input's frame by default).
        let (source, result) =
            stylize::eval::load_run_pair(&dir).with_context(|| format!("{}", dir.display()))?;
        anyhow::ensure!(
            result.faces == source.faces,
            "{}: mesh.obj is not the deformation of deformation.npz's faces",
            dir.display()
        );
        let stretch = stylize::remeshing::stretched_edges(
            &source.positions,
            &result.positions,
            &source.faces,
        )?;
        let (distorted, worst, edges) = (stretch.stretched, stretch.worst_ratio, stretch.edges);
        let faces = &source.faces;
        let source = &source.positions;
        let si_source = mesh_core::intersect::self_intersections(source, faces)?;
        let si_result = mesh_core::intersect::self_intersections(&result.positions, &result.faces)?;
        let new = mesh_core::intersect::new_pairs(&si_source, &si_result)?;
        let mut involved: Vec<u32> = new.iter().flat_map(|&(a, b)| [a, b]).collect();
        involved.sort_unstable();
        involved.dedup();
        // The same as a share of the result's area: unlike pair and face counts, it does not grow
        // with the resolution (a finer mesh cuts the same intersection curve into more pairs).
        let area = |f: [u32; 3]| {
            let p = |k: usize| result.positions[f[k] as usize];
            0.5 * mesh_core::geometry::norm(mesh_core::geometry::cross(
                mesh_core::geometry::sub(p(1), p(0)),
                mesh_core::geometry::sub(p(2), p(0)),
            ))
        };
        let total: f64 = faces.iter().map(|&f| area(f)).sum();
        let in_pairs: f64 = involved.iter().map(|&f| area(faces[f as usize])).sum();
        println!(
            "| {} | {} | {} | {:.2} % ({distorted} of {}) | {worst:.1}× | {} → {} ({}) | {:.2} % ({}) | {:.2} % |",
            dir.display(),
            source.len(),
            faces.len(),
            100.0 * stretch.share(),
            edges,
            si_source.pairs.len(),
            si_result.pairs.len(),
            new.len(),
            100.0 * involved.len() as f64 / faces.len() as f64,
            involved.len(),
            100.0 * in_pairs / total
        );
    }
    Ok(())
}
