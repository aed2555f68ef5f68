//! Reads a mesh, validates it with the default repair policy and prints the report.
//!
//! `cargo run -p mesh-core --example check_mesh -- fixtures/meshes/bone.ply`

use mesh_core::io::read_mesh;
use mesh_core::validate::{RepairOptions, validate};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Some(path) = std::env::args().nth(1) else {
        return Err("usage: check_mesh FILE".into());
    };
    let mesh = read_mesh(&path)?;
    let report = validate(&mesh, &RepairOptions::default());
    println!(
        "{path}: {} vertices, {} faces → {} vertices, {} faces, {} part(s), {}",
        report.input_vertices,
        report.input_faces,
        report.output_vertices,
        report.output_faces,
        report.components,
        if report.closed { "closed" } else { "open" }
    );
    for issue in &report.issues {
        println!(
            "  [{}] {}: {}",
            issue.action.name(),
            issue.kind.name(),
            issue.message
        );
    }
    Ok(())
}
