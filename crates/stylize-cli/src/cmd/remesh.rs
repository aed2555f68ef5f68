//! `stylize remesh IN --out OUT`: isotropic remeshing of a mesh file on its own (what `stylize
//! run --remesh` does first), with a before/after quality report.
//!
//! The mesh is read and repaired as a run does (`stylize mesh check` lists what that changes),
//! remeshed in its own units and frame (`mesh_core::remesh`), and written to OUT in the format of
//! OUT's extension. The target edge length is `--edge-length` (in the side-2 frame a run uses —
//! the longest bounding-box side counts 2 — or `1.5%` of the bounding-box diagonal), or derived
//! from `--target-vertices`, or 1.5 % of the diagonal by default.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use mesh_core::remesh::{Quality, RemeshOptions};
use stylize::remeshing::{DEFAULT_EDGE_LENGTH, EdgeLength, quality_json, quality_line};

/// Arguments of `stylize remesh`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Input mesh (OBJ, OFF, PLY, glTF/GLB).
    pub input: PathBuf,
    /// Output mesh (format from the extension; never the input).
    #[arg(short, long, value_name = "FILE")]
    pub out: PathBuf,
    /// Target edge length: in the side-2 frame (`0.03`; the longest bounding-box side counts 2)
    /// or a percentage of the bounding-box diagonal (`1.5%`, the default).
    #[arg(long, value_name = "L", conflicts_with = "target_vertices")]
    pub edge_length: Option<EdgeLength>,
    /// Aim at about this many vertices instead (the edge length that tiles the surface's area
    /// with N·2 equilateral triangles).
    #[arg(long, value_name = "N")]
    pub target_vertices: Option<u64>,
    /// Dihedral angle (degrees) above which an edge is a crease kept by the remesher; 180 keeps
    /// only boundaries.
    #[arg(long, value_name = "DEG", default_value_t = 30.0)]
    pub feature_angle: f64,
    /// Rounds of split, collapse, flip and relaxation.
    #[arg(long, value_name = "K", default_value_t = 10)]
    pub iterations: usize,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Replace OUT when it exists.
    #[arg(long)]
    pub force: bool,
}

/// The target edge length in the mesh's own units.
fn target_length(a: &Args, positions: &[[f64; 3]], faces: &[[u32; 3]], q: &Quality) -> f64 {
    if let Some(n) = a.target_vertices {
        // A closed triangle mesh has about twice as many faces as vertices.
        let area: f64 = faces
            .iter()
            .map(|f| {
                let p = f.map(|v| positions[v as usize]);
                let u = mesh_core::geometry::sub(p[1], p[0]);
                let w = mesh_core::geometry::sub(p[2], p[0]);
                0.5 * mesh_core::geometry::norm(mesh_core::geometry::cross(u, w))
            })
            .sum();
        return (area / (2.0 * n.max(1) as f64 * 3f64.sqrt() / 4.0)).sqrt();
    }
    match a.edge_length.unwrap_or(DEFAULT_EDGE_LENGTH) {
        EdgeLength::PercentOfDiagonal(p) => p / 100.0 * q.diagonal,
        EdgeLength::Absolute(l) => {
            // Side-2 units: the longest bounding-box side is 2.
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for f in faces {
                for &v in f {
                    for k in 0..3 {
                        lo[k] = lo[k].min(positions[v as usize][k]);
                        hi[k] = hi[k].max(positions[v as usize][k]);
                    }
                }
            }
            let side = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
            l * side / 2.0
        }
    }
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// Runs `stylize remesh`.
pub fn run(a: Args) -> anyhow::Result<()> {
    if !(a.feature_angle.is_finite() && (0.0..=180.0).contains(&a.feature_angle)) {
        bail!(
            "--feature-angle must be between 0 and 180 degrees, got {}",
            a.feature_angle
        );
    }
    if a.target_vertices == Some(0) {
        bail!("--target-vertices must be at least 1");
    }
    if same_file(&a.input, &a.out) {
        bail!(
            "--out {} is the input: write the remeshed mesh elsewhere",
            a.out.display()
        );
    }
    if a.out.exists() && !a.force {
        bail!("{} exists; pass --force to replace it", a.out.display());
    }
    mesh_core::io::Format::from_path(&a.out)
        .with_context(|| format!("cannot write {}: unknown output format", a.out.display()))?;
    let mesh = mesh_core::io::read_mesh(&a.input)
        .with_context(|| format!("cannot read mesh {}", a.input.display()))?;
    let repaired =
        mesh_core::validate::repair(&mesh, &mesh_core::validate::RepairOptions::default())
            .with_context(|| format!("mesh {} cannot be used", a.input.display()))?;
    let m = &repaired.mesh;
    let before = mesh_core::remesh::quality(&m.positions, &m.faces)?;
    let l = target_length(&a, &m.positions, &m.faces, &before);
    let options = RemeshOptions {
        iterations: a.iterations,
        feature_angle_deg: a.feature_angle,
        ..RemeshOptions::new(l)
    };
    let start = Instant::now();
    let out = mesh_core::remesh::remesh(&m.positions, &m.faces, &options).map_err(|e| {
        let hint = match e {
            mesh_core::remesh::RemeshError::NonManifoldEdge { .. }
            | mesh_core::remesh::RemeshError::NonManifoldVertex { .. } => {
                " (numbers after repair; `stylize mesh check` lists the non-manifold places: \
                 split the mesh there or fix it in a mesh editor)"
            }
            _ => "",
        };
        anyhow::Error::new(e).context(format!("cannot remesh {}{hint}", a.input.display()))
    })?;
    let seconds = start.elapsed().as_secs_f64();
    let after = mesh_core::remesh::quality(&out.positions, &out.faces)?;
    let h = mesh_core::remesh::hausdorff(&out.positions, &out.faces, &m.positions, &m.faces)?;
    let result = mesh_core::TriMesh::new(out.positions, out.faces);
    let normals =
        mesh_core::normals::vertex_normals_area_weighted(&result.positions, &result.faces);
    rundir::durable::replace_with(&a.out, |tmp| {
        mesh_core::io::write_mesh(tmp, &result, Some(&normals)).map_err(anyhow::Error::from)
    })
    .with_context(|| format!("cannot write {}", a.out.display()))?;
    let diag = before.diagonal;
    if a.json {
        let j = serde_json::json!({
            "input": a.input.display().to_string(),
            "output": a.out.display().to_string(),
            "edge_length": l,
            "edge_length_percent_of_diagonal": 100.0 * l / diag,
            "iterations": options.iterations,
            "feature_angle_deg": options.feature_angle_deg,
            "before": quality_json(&before),
            "after": quality_json(&after),
            "hausdorff_out_to_in_percent_of_diagonal": 100.0 * h.a_to_b / diag,
            "hausdorff_in_to_out_percent_of_diagonal": 100.0 * h.b_to_a / diag,
            "seconds": seconds,
        });
        outln!("{}", serde_json::to_string_pretty(&j)?)?;
    } else {
        outln!(
            "{} → {}: edge length {l:.6} ({:.2} % of the diagonal), {} iterations, feature angle {}°, {seconds:.2} s",
            a.input.display(),
            a.out.display(),
            100.0 * l / diag,
            options.iterations,
            options.feature_angle_deg
        )?;
        outln!("  before: {}", quality_line(&before))?;
        outln!("  after:  {}", quality_line(&after))?;
        outln!(
            "  Hausdorff distance: output → input {:.3} %, input → output {:.3} % of the diagonal",
            100.0 * h.a_to_b / diag,
            100.0 * h.b_to_a / diag
        )?;
    }
    Ok(())
}
