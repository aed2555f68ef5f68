//! The dARAP layer used alone: deform an icosphere toward tilted normals and get a gradient.
//!
//! `cargo run -p darap --example standalone`

use darap::{Darap, DarapOptions};

fn main() -> Result<(), darap::DarapError> {
    let mesh = mesh_core::shapes::icosphere(3); // any positions normalized to the side-2 cube
    let layer = Darap::new(&mesh.positions, &mesh.faces, DarapOptions::default())?; // λ = 8, gis rule
    // Targets: rest normals tilted toward +x (only directions matter).
    let x: Vec<[f64; 3]> = layer
        .rest_normals()
        .iter()
        .map(|n| [n[0] + 0.5, n[1], n[2]])
        .collect();
    let state = layer.forward(&x)?;
    // Gradient of ℓ = ½ Σ_v |p_v|² (spread of the deformed mesh) with respect to the targets.
    let grad_x = layer.backward(&state, &state.positions);
    let moved = state
        .positions
        .iter()
        .zip(&mesh.positions)
        .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt());
    println!(
        "{} vertices, max displacement {:.4}",
        layer.num_vertices(),
        moved.fold(0.0, f64::max)
    );
    println!(
        "|∂ℓ/∂x| at vertex 0: {:.3e}",
        grad_x[0].iter().map(|g| g * g).sum::<f64>().sqrt()
    );
    Ok(())
}
