//! Remeshes one mesh file and prints the figures as JSON — the measuring end of
//! `scripts/bench_remesh.py` (a release build of mesh-core alone; `stylize remesh` does the same
//! with a report for people).
//!
//! `remesh_file IN OUT PERCENT ITERATIONS FEATURE_DEG [REFERENCE]`
//!
//! Reads IN, repairs it (`validate::repair` defaults, as `stylize remesh`), remeshes it to
//! PERCENT % of its bounding-box diagonal (ITERATIONS 0: no remeshing, IN's own figures), writes
//! OUT, and prints `before`/`after` quality, the sampled two-sided Hausdorff distance between the
//! output and IN (or, with REFERENCE, between IN and REFERENCE: how far another tool's output IN
//! lies from its source) as % of the diagonal, the self-intersecting face pairs (exact,
//! `mesh_core::intersect`) of the output and of the input (or REFERENCE), and the seconds the
//! remeshing took.

use std::time::Instant;

use mesh_core::remesh::{Quality, RemeshOptions};

fn q(q: &Quality) -> String {
    format!(
        "{{\"vertices\": {}, \"faces\": {}, \"edge_std_over_mean\": {}, \"min_angle_deg\": {}, \
         \"share_below_10_deg\": {}, \"share_below_30_deg\": {}, \"share_valence_6\": {}}}",
        q.vertices,
        q.faces,
        q.edge_std_over_mean(),
        q.min_angle_deg,
        q.share_below_10_deg,
        q.share_below_30_deg,
        q.share_valence_6
    )
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    if a.len() < 5 {
        return Err("usage: remesh_file IN OUT PERCENT ITERATIONS FEATURE_DEG [REFERENCE]".into());
    }
    let mesh = mesh_core::io::read_mesh(&a[0])?;
    let m =
        mesh_core::validate::repair(&mesh, &mesh_core::validate::RepairOptions::default())?.mesh;
    let before = mesh_core::remesh::quality(&m.positions, &m.faces)?;
    let percent: f64 = a[2].parse()?;
    let iterations: usize = a[3].parse()?;
    let options = RemeshOptions {
        iterations,
        feature_angle_deg: a[4].parse()?,
        ..RemeshOptions::new(percent / 100.0 * before.diagonal)
    };
    let start = Instant::now();
    let out = if iterations == 0 {
        None
    } else {
        Some(mesh_core::remesh::remesh(&m.positions, &m.faces, &options)?)
    };
    let seconds = start.elapsed().as_secs_f64();
    let (p, f) = match &out {
        Some(o) => (o.positions.clone(), o.faces.clone()),
        None => (m.positions.clone(), m.faces.clone()),
    };
    let after = mesh_core::remesh::quality(&p, &f)?;
    mesh_core::io::write_mesh(&a[1], &mesh_core::TriMesh::new(p.clone(), f.clone()), None)?;
    let reference = match a.get(5) {
        Some(path) => {
            let r = mesh_core::io::read_mesh(path)?;
            (r.positions, r.faces)
        }
        None => (m.positions.clone(), m.faces.clone()),
    };
    let h = mesh_core::remesh::hausdorff(&p, &f, &reference.0, &reference.1)?;
    // Self-intersecting face pairs (exact) of the output and of the input it came from.
    let pairs_out = mesh_core::intersect::self_intersections(&p, &f)?
        .pairs
        .len();
    let pairs_in = mesh_core::intersect::self_intersections(&reference.0, &reference.1)?
        .pairs
        .len();
    println!(
        "{{\"before\": {}, \"after\": {}, \"hausdorff_out_to_in_percent_of_diagonal\": {}, \
         \"hausdorff_in_to_out_percent_of_diagonal\": {}, \"self_intersecting_pairs_out\": \
         {pairs_out}, \"self_intersecting_pairs_in\": {pairs_in}, \"seconds\": {seconds}}}",
        q(&before),
        q(&after),
        100.0 * h.a_to_b / before.diagonal,
        100.0 * h.b_to_a / before.diagonal
    );
    Ok(())
}
