//! Measures what `--region-feather K` does at a region's boundary, and draws a before/after
//! contact sheet of a localized run (numbers and image in `docs/cli.md`, "Regions").
//!
//! `cargo run --release -p stylize-cli --example region_feather -- [OUT_PNG] [ITERATIONS]`
//!
//! Runs the cube style (default 200 iterations) on the bunny with the region `box:-1,-1,-1,0,1,1`
//! (the half x ≤ 0) for K = 0, 2, 4 and reports, over the **seam** (mesh edges with one end in
//! the region and one outside) and the band of edges within two rings of it:
//! - the largest and mean change of the dihedral angle (deformed − rest, degrees);
//! - the same on the seam edges alone;
//! - the region's mean alignment with the cube style (how much stylization the feather costs).

use std::collections::HashMap;
use std::path::PathBuf;

use anyhow::Context;
use stylize::run_pictures::{tint_region, turntable, write_grid};
use stylize::runner::{RunRequest, prepare_mesh_with_region};
use stylize::style::Style;
use stylize_cli::config::{Config, RegionSection};
use stylize_cli::runner::{LogMode, execute};

const REGION: &str = "box:-1,-1,-1,0,1,1";

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    dot(a, b).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Interior edges → their two faces.
fn edge_faces(faces: &[[u32; 3]]) -> HashMap<[u32; 2], Vec<usize>> {
    let mut m: HashMap<[u32; 2], Vec<usize>> = HashMap::new();
    for (fi, f) in faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            m.entry([a.min(b), a.max(b)]).or_default().push(fi);
        }
    }
    m.retain(|_, v| v.len() == 2);
    m
}

/// Signed-free dihedral measure: the angle between the two face normals (0 = flat).
fn normal_angle(normals: &[[f64; 3]], pair: &[usize]) -> f64 {
    angle_deg(normals[pair[0]], normals[pair[1]])
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let png = PathBuf::from(
        args.first()
            .map_or("docs/images/region_before_after.png", |s| s),
    );
    let iterations: u64 = args
        .get(1)
        .map_or(Ok(200), |s| s.parse())
        .context("ITERATIONS")?;
    let mesh_path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/meshes/bunny.obj");
    let tmp = tempfile::tempdir()?;
    println!("bunny, cube style, {iterations} iterations, region {REGION}");
    println!(
        "| K | band: max abs Δdihedral | band: mean | seam: max abs Δdihedral | seam: mean | region alignment |"
    );
    println!("|---|---|---|---|---|---|");
    let mut sheet_meshes = None;
    for k in [0u32, 2, 4] {
        let mut c = Config::default();
        c.style.iterations = iterations;
        c.run.checkpoint_every = 0;
        c.run.preview_every = 0;
        c.run.turntable_views = 2;
        c.run.turntable_size = 32;
        c.region = RegionSection {
            specs: vec![REGION.into()],
            feather: k,
            tint: false,
        };
        let out = tmp.path().join(format!("k{k}"));
        execute(
            &RunRequest {
                mesh: mesh_path.clone(),
                out: out.clone(),
                config: c.clone(),
                force: false,
                resume: false,
                halt_after: None,
            },
            LogMode::Quiet,
            Style::Cube,
        )?;
        let (rest, _, region) = prepare_mesh_with_region(&mesh_path, &c.region)?;
        let region = region.context("region")?;
        let deformed = mesh_core::io::read_mesh(out.join("mesh.obj"))?;
        let faces = &rest.faces;
        let n_rest = mesh_core::normals::face_normals(&rest.positions, faces);
        let n_def = mesh_core::normals::face_normals(&deformed.positions, faces);
        // Distance in rings from the seam: ring 0 = the seam's vertices.
        let inside = &region.free;
        let outside: Vec<bool> = inside.iter().map(|f| !f).collect();
        let from_out = mesh_core::region::feather_weights(inside, faces, 3);
        let from_in = mesh_core::region::feather_weights(&outside, faces, 3);
        // w = d/4 with d the rings to the other side (1 on the seam's vertices).
        let near = |v: u32| {
            let v = v as usize;
            let d = if inside[v] { from_out[v] } else { from_in[v] };
            d <= 3.0 / 4.0 // within 3 rings of the other side: the seam and two more rings
        };
        let mut max_change: f64 = 0.0;
        let mut sum_change = 0.0;
        let mut count = 0usize;
        let mut seam_max: f64 = 0.0;
        let mut seam_sum = 0.0;
        let mut seam_count = 0usize;
        for (e, pair) in edge_faces(faces) {
            if !(near(e[0]) && near(e[1])) {
                continue;
            }
            let change = (normal_angle(&n_def, &pair) - normal_angle(&n_rest, &pair)).abs();
            max_change = max_change.max(change);
            sum_change += change;
            count += 1;
            if inside[e[0] as usize] != inside[e[1] as usize] {
                seam_max = seam_max.max(change);
                seam_sum += change;
                seam_count += 1;
            }
        }
        let region_faces: Vec<[u32; 3]> = faces
            .iter()
            .copied()
            .filter(|f| f.iter().all(|&v| inside[v as usize]))
            .collect();
        let targets = Style::Cube.face_targets(&rest.positions, &region_faces);
        let align =
            stylize::style::alignment::mean_alignment(&deformed.positions, &region_faces, &targets);
        let align_rest =
            stylize::style::alignment::mean_alignment(&rest.positions, &region_faces, &targets);
        println!(
            "| {k} | {max_change:.2}° | {:.2}° ({count} edges) | {seam_max:.2}° | {:.2}° ({seam_count} edges) | {align_rest:.4} → {align:.4} |",
            sum_change / count.max(1) as f64,
            seam_sum / seam_count.max(1) as f64
        );
        if k == 2 {
            sheet_meshes = Some((rest, deformed, region.free));
        }
    }
    let (rest, deformed, free) = sheet_meshes.context("K = 2 run")?;
    let mut renderer = raster_diff::CpuRenderer::default();
    let mut before = turntable(&mut renderer, &rest.positions, &rest.faces, 4, 160, 60.0)?;
    if let Some(ids) = renderer.triangle_ids() {
        tint_region(&mut before, &ids, &rest.faces, &free);
    }
    let mut after = turntable(
        &mut renderer,
        &deformed.positions,
        &deformed.faces,
        4,
        160,
        60.0,
    )?;
    if let Some(ids) = renderer.triangle_ids() {
        tint_region(&mut after, &ids, &deformed.faces, &free);
    }
    before.count += after.count;
    before.rgb.extend_from_slice(&after.rgb);
    write_grid(&png, &before)?;
    println!(
        "contact sheet (top: rest, bottom: K = 2; region tinted): {}",
        png.display()
    );
    Ok(())
}
