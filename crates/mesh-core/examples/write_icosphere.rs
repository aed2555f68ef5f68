//! Writes [`mesh_core::shapes::icosphere`] of a given level to a mesh file (format by extension),
//! e.g. the 20,480-face benchmark mesh of `scripts/bench-target3.sh`.
//!
//! `cargo run -p mesh-core --example write_icosphere -- 5 ico5.obj`

use mesh_core::io::write_mesh;
use mesh_core::shapes::icosphere;

/// Level 8 has 655,362 vertices; beyond that the file only grows (×4 a level).
const MAX_LEVEL: u32 = 8;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [level, path] = args.as_slice() else {
        return Err("usage: write_icosphere LEVEL FILE (.obj, .ply, .off or .glb)".into());
    };
    let level: u32 = level
        .parse()
        .ok()
        .filter(|l| *l <= MAX_LEVEL)
        .ok_or_else(|| format!("LEVEL must be an integer from 0 to {MAX_LEVEL}, got '{level}'"))?;
    let mesh = icosphere(level);
    write_mesh(path, &mesh, None)?;
    println!(
        "{path}: icosphere level {level}, {} vertices, {} faces",
        mesh.positions.len(),
        mesh.faces.len()
    );
    Ok(())
}
