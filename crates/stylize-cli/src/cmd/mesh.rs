//! `stylize mesh`: mesh utilities. `stylize mesh check FILE [--json]` reads a mesh, runs the
//! validation of `mesh_core::validate` and prints what repair finds and would do, then the
//! self-intersections of the repaired mesh ([`self_intersection_section`]: exact,
//! `mesh_core::intersect`; pairs, faces, per component).
//! `--regions` lists instead the parts the file offers for `stylize run --region` (named parts
//! and scalar properties, with the vertex counts they select on the repaired mesh).

use std::path::PathBuf;

use anyhow::Context;
use mesh_core::validate::{Locations, RepairOptions, ValidationReport, validate};

/// Arguments of `stylize mesh`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    command: MeshCommand,
}

#[derive(clap::Subcommand, Debug)]
enum MeshCommand {
    /// Validate a mesh (OBJ, OFF, PLY, glTF/GLB) and report every problem and what repair does
    /// about it. Exits with status 1 when the mesh cannot be used.
    Check(CheckArgs),
}

#[derive(clap::Args, Debug)]
struct CheckArgs {
    /// The mesh file.
    file: PathBuf,
    /// Print the report as JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Drop vertices with NaN/infinite coordinates (and their faces) instead of refusing.
    #[arg(long)]
    drop_nonfinite: bool,
    /// Drop faces that refer to missing vertices instead of refusing.
    #[arg(long)]
    drop_out_of_range: bool,
    /// A face is a needle when its smallest corner angle is below this (degrees).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    needle_angle: f64,
    /// List the parts the file offers for `--region` (OBJ groups/objects/materials, glTF
    /// nodes/meshes, PLY properties) with the vertices each selects, instead of the report.
    #[arg(long)]
    regions: bool,
}

/// Runs `stylize mesh`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        MeshCommand::Check(a) => check(a),
    }
}

fn check(a: CheckArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.needle_angle.is_finite() && a.needle_angle >= 0.0,
        "--needle-angle must be a non-negative number of degrees"
    );
    if a.regions {
        return list_regions(&a);
    }
    let mesh = mesh_core::io::read_mesh(&a.file).context("cannot load the mesh")?;
    let options = RepairOptions {
        drop_nonfinite_vertices: a.drop_nonfinite,
        drop_out_of_range_faces: a.drop_out_of_range,
        needle_angle_degrees: a.needle_angle,
        ..RepairOptions::default()
    };
    let report = validate(&mesh, &options);
    // A mesh the repairs accept must also be one a run can solve on: the same preparation and
    // dARAP precomputation as `stylize run`, so the verdicts agree (tiny debris components made
    // the factorization fail while the report said "usable").
    // (Only with the default repairs: `--drop-…` preview repairs a run does not make.)
    let solver_error = if report.is_refused() || a.drop_nonfinite || a.drop_out_of_range {
        None
    } else {
        solver_check(&a.file)
    };
    let quality = if report.is_refused() {
        None
    } else {
        Some(repaired_quality(&mesh, &options)?)
    };
    let extents = Extents::of(&mesh.positions);
    let intersections = if report.is_refused() {
        None
    } else {
        Some(self_intersection_section(&mesh, &options)?)
    };
    if a.json {
        let mut json = report_json(&a.file, &report);
        json["solver_error"] = solver_error.clone().into();
        if let Some(x) = &intersections {
            json["self_intersections"] = x.json();
        }
        if let Some(q) = &quality {
            json["quality"] = stylize::remeshing::quality_json(q);
            json["remeshing_advised"] = serde_json::json!(remesh_advice(q).0);
            json["remeshing_advice"] = serde_json::json!(remesh_advice(q).1);
        }
        json["extents"] = serde_json::json!(extents.size);
        json["up_hint"] = serde_json::json!(extents.up_hint());
        outln!(
            "{}",
            serde_json::to_string_pretty(&json).context("cannot format the report as JSON")?
        )?;
    } else {
        outp!("{}", report_table(&a.file, &report))?;
        outp!("{}", extents.table())?;
        if let Some(x) = &intersections {
            outp!("{}", x.table())?;
        }
        if let Some(q) = &quality {
            outp!("{}", quality_table(q))?;
        }
        if let Some(e) = &solver_error {
            outln!("but a run cannot use it: {e}")?;
        }
    }
    if report.is_refused() {
        anyhow::bail!(
            "{} cannot be used: {}",
            a.file.display(),
            report.refusal_message()
        );
    }
    if let Some(e) = solver_error {
        anyhow::bail!("{} cannot be used for a run: {e}", a.file.display());
    }
    Ok(())
}

/// Why `stylize run` could not start its dARAP layer on `file` (prepared exactly as a run with
/// the default configuration prepares it: default repairs, `mesh.remesh`'s default, side-2
/// normalization), if it could not.
fn solver_check(file: &std::path::Path) -> Option<String> {
    let defaults = crate::config::Config::default();
    let rest = match stylize::runner::prepare_run_mesh(
        file,
        defaults.mesh.remesh,
        defaults.mesh.up,
        &defaults.region,
    ) {
        Ok(prepared) => prepared.mesh,
        Err(e) => return Some(format!("{e:#}")),
    };
    darap::Darap::new(&rest.positions, &rest.faces, darap::DarapOptions::default())
        .err()
        .map(|e| format!("dARAP precomputation: {e}"))
}

/// Triangle quality of the mesh after the repair `options` make (what a run would optimize,
/// before `[mesh] remesh`).
fn repaired_quality(
    mesh: &mesh_core::TriMesh,
    options: &RepairOptions,
) -> anyhow::Result<mesh_core::remesh::Quality> {
    let repaired = mesh_core::validate::repair(mesh, options).context("cannot repair the mesh")?;
    mesh_core::remesh::quality(&repaired.mesh.positions, &repaired.mesh.faces)
        .context("cannot measure the triangles")
}

/// Whether remeshing is advised (the criterion of `--remesh auto`,
/// [`stylize::remeshing::remeshing_advised`]) and the sentence that says so.
fn remesh_advice(q: &mesh_core::remesh::Quality) -> (bool, String) {
    match stylize::remeshing::remeshing_advised(q) {
        Some(why) => (
            true,
            format!(
                "remeshing advised ({why}): `stylize run` remeshes it by default (`--remesh \
                 auto`); `stylize remesh` does it alone"
            ),
        ),
        None => (
            false,
            "triangles even enough: `stylize run` keeps them as they are (`--remesh auto`)".into(),
        ),
    }
}

/// The quality figures and the advice, for people.
fn quality_table(q: &mesh_core::remesh::Quality) -> String {
    format!(
        "\ntriangles (after repair): {}\n{}\n",
        stylize::remeshing::quality_line(q),
        remesh_advice(q).1
    )
}

/// The self-intersections of the repaired mesh (what a run uses), for `mesh check`.
struct SelfIntersectionSection {
    result: mesh_core::intersect::SelfIntersections,
}

/// How many example pairs `mesh check` lists.
const EXAMPLE_PAIRS: usize = 10;

/// Repairs `mesh` as a run would and checks the result for self-intersections.
fn self_intersection_section(
    mesh: &mesh_core::TriMesh,
    options: &RepairOptions,
) -> anyhow::Result<SelfIntersectionSection> {
    let repaired = mesh_core::validate::repair(mesh, options).context("cannot repair the mesh")?;
    if repaired.mesh.faces.is_empty() {
        return Ok(SelfIntersectionSection {
            result: mesh_core::intersect::SelfIntersections::default(),
        });
    }
    let result =
        mesh_core::intersect::self_intersections(&repaired.mesh.positions, &repaired.mesh.faces)
            .context("self-intersection check of the repaired mesh")?;
    Ok(SelfIntersectionSection { result })
}

impl SelfIntersectionSection {
    fn json(&self) -> serde_json::Value {
        let r = &self.result;
        serde_json::json!({
            "pairs": r.pairs.len(),
            "faces": r.faces.len(),
            "degenerate_faces": r.degenerate.len(),
            "example_pairs": r.pairs.iter().take(EXAMPLE_PAIRS).collect::<Vec<_>>(),
            "per_component": r.per_component.iter().map(|c| serde_json::json!({
                "faces": c.faces,
                "involved_faces": c.involved_faces,
                "pairs_within": c.pairs_within,
                "pairs_across": c.pairs_across,
            })).collect::<Vec<_>>(),
            "numbering": "faces of the repaired mesh",
        })
    }

    fn table(&self) -> String {
        use std::fmt::Write;
        let r = &self.result;
        let mut s = String::new();
        if r.pairs.is_empty() {
            let _ = writeln!(
                s,
                "\nself-intersections: none ({} face{} checked exactly)",
                r.num_faces,
                if r.num_faces == 1 { "" } else { "s" }
            );
        } else {
            let _ = writeln!(
                s,
                "\nself-intersections: {} pair{} of faces intersect ({} faces of {}; repaired mesh numbering)",
                r.pairs.len(),
                if r.pairs.len() == 1 { "" } else { "s" },
                r.faces.len(),
                r.num_faces
            );
            let examples: Vec<String> = r
                .pairs
                .iter()
                .take(EXAMPLE_PAIRS)
                .map(|(a, b)| format!("{a}–{b}"))
                .collect();
            let _ = writeln!(s, "  e.g. {}", examples.join(", "));
            if r.per_component.len() > 1 {
                for (i, c) in r.per_component.iter().enumerate() {
                    if c.pairs_within + c.pairs_across > 0 {
                        let _ = writeln!(
                            s,
                            "  part {i}: {} of {} faces, {} pairs within, {} with other parts",
                            c.involved_faces, c.faces, c.pairs_within, c.pairs_across
                        );
                    }
                }
            }
        }
        if !r.degenerate.is_empty() {
            let _ = writeln!(
                s,
                "  {} zero-area face{} (never counted as intersecting)",
                r.degenerate.len(),
                if r.degenerate.len() == 1 { "" } else { "s" }
            );
        }
        s
    }
}

/// The bounding box extents per axis of a mesh's finite vertices, and the orientation hint.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Extents {
    /// max − min along x, y, z (0 without finite vertices).
    size: [f64; 3],
}

/// The hint fires when the y extent is below this share of the largest extent (and the smallest).
const FLAT_Y_SHARE: f64 = 2.0 / 3.0;

impl Extents {
    fn of(positions: &[[f64; 3]]) -> Self {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in positions.iter().filter(|p| p.iter().all(|c| c.is_finite())) {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        Self {
            size: std::array::from_fn(|k| if hi[k] >= lo[k] { hi[k] - lo[k] } else { 0.0 }),
        }
    }

    /// A hint that the mesh may lie on its side: the renders put +y up (the view sampler's
    /// elevations are above the xz-plane), and most upright objects are not flattest along their
    /// up axis. The rule: y is the smallest extent and below [`FLAT_Y_SHARE`] of the largest.
    fn up_hint(&self) -> Option<String> {
        let [x, y, z] = self.size;
        let largest = x.max(y).max(z);
        (largest > 0.0 && y < x && y < z && y < FLAT_Y_SHARE * largest).then(|| {
            format!(
                "the mesh is flattest along y ({:.0}% of its largest extent): stylization renders \
                 it with +y up, so if it lies on its side (a z-up export: CAD, scans), pass \
                 --up z (or the axis that points up: --up x, --up -z, …); a mesh that is really \
                 flat, such as a rug, is fine as it is",
                100.0 * y / largest
            )
        })
    }

    fn table(&self) -> String {
        let [x, y, z] = self.size;
        let mut s = format!("extents: x {x:.6}, y {y:.6}, z {z:.6} (renders put +y up)\n");
        if let Some(h) = self.up_hint() {
            s += &format!("hint: {h}\n");
        }
        s
    }
}

/// One row of `--regions`: spec, kind, vertices it selects on the repaired mesh, a note.
fn region_rows(file: &std::path::Path) -> anyhow::Result<Vec<(String, String, usize, String)>> {
    use mesh_core::region::{Comparison, RegionInput, RegionSpec, select_vertices};
    let (mesh, parts) =
        mesh_core::io::read_mesh_with_parts(file).context("cannot load the mesh")?;
    let repaired = mesh_core::validate::repair(&mesh, &RepairOptions::default())
        .with_context(|| format!("{} cannot be used", file.display()))?;
    let input = RegionInput {
        positions: &repaired.mesh.positions,
        faces: &repaired.mesh.faces,
        vertex_map: &repaired.vertex_map,
        face_map: &repaired.face_map,
        parts: &parts,
    };
    let count = |spec: &RegionSpec| -> anyhow::Result<usize> {
        Ok(select_vertices(spec, &input)?
            .iter()
            .filter(|&&b| b)
            .count())
    };
    let mut rows = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for p in &parts.named {
        if !seen.insert(p.name.clone()) {
            continue; // `part:NAME` selects every part of that name at once
        }
        let kinds: Vec<&str> = parts
            .named
            .iter()
            .filter(|q| q.name == p.name)
            .map(|q| q.kind.name())
            .collect();
        let spec = RegionSpec::Part(p.name.clone());
        rows.push((
            spec.to_string(),
            kinds.join("+"),
            count(&spec)?,
            String::new(),
        ));
    }
    for (per, list) in [
        ("vertex property", &parts.vertex_properties),
        ("face property", &parts.face_properties),
    ] {
        for p in list {
            let mut distinct: Vec<f64> = p.values.iter().copied().filter(|x| !x.is_nan()).collect();
            distinct.sort_by(f64::total_cmp);
            distinct.dedup();
            let (lo, hi) = (
                distinct.first().copied().unwrap_or(f64::NAN),
                distinct.last().copied().unwrap_or(f64::NAN),
            );
            if distinct.len() <= 8 {
                for &v in &distinct {
                    let spec = RegionSpec::Property {
                        name: p.name.clone(),
                        op: Comparison::Eq,
                        value: v,
                    };
                    rows.push((
                        spec.to_string(),
                        per.to_string(),
                        count(&spec)?,
                        String::new(),
                    ));
                }
            } else {
                rows.push((
                    format!("property:{} OP VALUE", p.name),
                    per.to_string(),
                    repaired.mesh.positions.len(),
                    format!("{} distinct values in [{lo}, {hi}]", distinct.len()),
                ));
            }
        }
    }
    Ok(rows)
}

fn list_regions(a: &CheckArgs) -> anyhow::Result<()> {
    let rows = region_rows(&a.file)?;
    if a.json {
        let json: Vec<serde_json::Value> = rows
            .iter()
            .map(|(spec, kind, n, note)| {
                serde_json::json!({ "spec": spec, "kind": kind, "vertices": n, "note": note })
            })
            .collect();
        outln!(
            "{}",
            serde_json::to_string_pretty(&json).context("cannot format the parts as JSON")?
        )?;
        return Ok(());
    }
    if rows.is_empty() {
        outln!(
            "{}: no named parts or properties (use box:, sphere: or vertices: regions)",
            a.file.display()
        )?;
        return Ok(());
    }
    outln!(
        "{}: regions on offer (vertices on the repaired mesh)",
        a.file.display()
    )?;
    let width = rows.iter().map(|r| r.0.chars().count()).max().unwrap_or(0);
    for (spec, kind, n, note) in &rows {
        outln!("  {spec:<width$}  {kind:<16} {n:>8} vertices  {note}")?;
    }
    Ok(())
}

fn locations_json(l: &Locations) -> serde_json::Value {
    use serde_json::json;
    match l {
        Locations::Vertices(v) => json!({ "vertices": v }),
        Locations::Faces(f) => json!({ "faces": f }),
        Locations::Edges(e) => json!({ "edges": e }),
        Locations::VertexPairs(p) => json!({ "vertex_pairs": p }),
        Locations::ComponentSizes(s) => json!({ "component_sizes": s }),
        _ => json!({}),
    }
}

/// The report as JSON: input/output sizes, verdict, and every issue with its kind, action,
/// count, example locations (input numbering) and message.
fn report_json(file: &std::path::Path, r: &ValidationReport) -> serde_json::Value {
    serde_json::json!({
        "file": file.display().to_string(),
        "input": { "vertices": r.input_vertices, "faces": r.input_faces },
        "after_repair": {
            "vertices": r.output_vertices,
            "faces": r.output_faces,
            "components": r.components,
            "closed": r.closed,
        },
        "usable": !r.is_refused(),
        "issues": r.issues.iter().map(|i| serde_json::json!({
            "kind": i.kind.name(),
            "action": i.action.name(),
            "count": i.count,
            "examples": locations_json(&i.examples),
            "message": i.message,
        })).collect::<Vec<_>>(),
    })
}

/// The report as a table for people.
fn report_table(file: &std::path::Path, r: &ValidationReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}: {} vertices, {} faces",
        file.display(),
        r.input_vertices,
        r.input_faces
    );
    let _ = writeln!(
        s,
        "after repair: {} vertices, {} face{}, {} part{}, {}",
        r.output_vertices,
        r.output_faces,
        if r.output_faces == 1 { "" } else { "s" },
        r.components,
        if r.components == 1 { "" } else { "s" },
        if r.closed { "closed" } else { "open" }
    );
    if r.issues.is_empty() {
        let _ = writeln!(s, "no problems found");
        return s;
    }
    let _ = writeln!(s);
    let _ = writeln!(s, "{:<9} {:<25} {:>7}  details", "action", "issue", "count");
    for i in &r.issues {
        let _ = writeln!(
            s,
            "{:<9} {:<25} {:>7}  {}",
            i.action.name(),
            i.kind.name().replace('_', " "),
            i.count,
            i.message
        );
    }
    let _ = writeln!(
        s,
        "\n{}",
        if r.is_refused() {
            "verdict: cannot be used as is (see the `refused` rows)"
        } else {
            "verdict: usable (after the repairs listed)"
        }
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesh_core::TriMesh;

    /// The bunny and a well-shaped icosahedron 1e-9 of its size: the repairs keep both parts, but
    /// the dARAP factorization fails on the debris; `mesh check` says so, as `run` would.
    #[test]
    fn tiny_debris_that_a_run_cannot_factor_is_reported_by_mesh_check() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let bunny = mesh_core::io::read_mesh(
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/meshes/bunny.obj"),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let extent = mesh_core::geometry::bbox_diagonal(&bunny.positions);
        let (mut p, mut f) = (bunny.positions.clone(), bunny.faces.clone());
        let (dp, df) = mesh_core::shapes::icosphere(0).into_parts();
        let base = p.len() as u32;
        let at = [p[0][0] + 0.3 * extent, p[0][1], p[0][2]];
        let s = 1e-9 * extent;
        p.extend(
            dp.iter()
                .map(|v| [at[0] + s * v[0], at[1] + s * v[1], at[2] + s * v[2]]),
        );
        f.extend(df.iter().map(|t| t.map(|i| i + base)));
        let args = |file: PathBuf| CheckArgs {
            file,
            json: false,
            drop_nonfinite: false,
            drop_out_of_range: false,
            needle_angle: 1.0,
            regions: false,
        };
        // Written with every digit (the debris lives in the 10th significant one).
        let mut obj = String::new();
        for v in &p {
            obj.push_str(&format!("v {:?} {:?} {:?}\n", v[0], v[1], v[2]));
        }
        for t in &f {
            obj.push_str(&format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1));
        }
        let debris = dir.path().join("debris.obj");
        std::fs::write(&debris, obj).unwrap_or_else(|e| panic!("{e}"));
        let e = check(args(debris)).expect_err("a run could not use it");
        assert!(
            format!("{e:#}").contains("cannot be used for a run")
                && format!("{e:#}").contains("component far smaller than the mesh"),
            "{e:#}"
        );
        let (p, f) = mesh_core::shapes::icosphere(2).into_parts();
        let sphere = dir.path().join("sphere.obj");
        mesh_core::io::write_mesh(&sphere, &TriMesh::new(p, f), None)
            .unwrap_or_else(|e| panic!("{e}"));
        check(args(sphere)).unwrap_or_else(|e| panic!("{e:#}"));
    }

    fn two_parts_with_nan() -> TriMesh {
        TriMesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [f64::NAN, 0.0, 0.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn json_report_names_kinds_actions_and_input_locations() {
        let r = validate(&two_parts_with_nan(), &RepairOptions::default());
        let j = report_json(std::path::Path::new("x.obj"), &r);
        assert_eq!(j["usable"], serde_json::json!(false));
        assert_eq!(j["input"]["vertices"], serde_json::json!(4));
        let first = &j["issues"][0];
        assert_eq!(first["kind"], "non_finite_coordinates");
        assert_eq!(first["action"], "refused");
        assert_eq!(first["examples"]["vertices"], serde_json::json!([3]));
    }

    #[test]
    fn table_lists_every_issue_and_the_verdict() {
        let r = validate(&two_parts_with_nan(), &RepairOptions::default());
        let t = report_table(std::path::Path::new("x.obj"), &r);
        assert!(
            t.contains("refused") && t.contains("non finite coordinates"),
            "{t}"
        );
        assert!(t.contains("verdict: cannot be used"), "{t}");
        assert_eq!(
            t.lines()
                .filter(|l| l.starts_with("refused")
                    || l.starts_with("kept")
                    || l.starts_with("repaired"))
                .count(),
            r.issues.len()
        );
    }

    fn fixture(name: &str) -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/meshes")
            .join(name)
    }

    fn args(name: &str, json: bool) -> CheckArgs {
        CheckArgs {
            file: fixture(name),
            json,
            drop_nonfinite: false,
            drop_out_of_range: false,
            needle_angle: 1.0,
            regions: false,
        }
    }

    #[test]
    fn regions_list_parts_with_the_vertices_they_select_or_say_there_are_none() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("two.obj");
        std::fs::write(
            &path,
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nusemtl red\nf 1 2 3\nusemtl blue\nf 2 4 3\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let rows = region_rows(&path).unwrap_or_else(|e| panic!("{e:#}"));
        let got: Vec<(&str, &str, usize)> = rows
            .iter()
            .map(|r| (r.0.as_str(), r.1.as_str(), r.2))
            .collect();
        assert_eq!(
            got,
            [("part:red", "material", 3), ("part:blue", "material", 3)]
        );
        assert!(
            region_rows(&fixture("cow.off"))
                .unwrap_or_else(|e| panic!("{e:#}"))
                .is_empty()
        );
        let mut a = args("cow.off", false);
        a.regions = true;
        assert!(check(a).is_ok());
    }

    #[test]
    fn quality_advice_follows_the_auto_criterion() {
        let q = |name: &str| {
            let mesh = mesh_core::io::read_mesh(fixture(name)).unwrap_or_else(|e| panic!("{e}"));
            repaired_quality(&mesh, &RepairOptions::default()).unwrap_or_else(|e| panic!("{e:#}"))
        };
        for (name, advised) in [
            ("bunny.obj", false),
            ("fandisk.off", false),
            ("cow.off", true),
            ("triceratops.off", true),
        ] {
            let quality = q(name);
            let (got, text) = remesh_advice(&quality);
            assert_eq!(got, advised, "{name}: {text}");
            let table = quality_table(&quality);
            assert!(
                table.contains("std/mean") && table.contains(&text),
                "{table}"
            );
        }
    }

    #[test]
    fn extents_hint_that_a_mesh_lies_on_its_side_only_when_it_is_flattest_along_y() {
        // A tall, slim box standing up (y-up) gets no hint; the same box lying along z does, and
        // turning it back with mesh.up = +z removes it.
        let standing = vec![[0.0, 0.0, 0.0], [1.0, 3.0, 0.8]];
        assert_eq!(Extents::of(&standing).up_hint(), None);
        let mut lying: Vec<[f64; 3]> = standing.iter().map(|p| [p[0], -p[2], p[1]]).collect();
        let hint = Extents::of(&lying).up_hint().unwrap_or_default();
        assert!(hint.contains("--up z"), "{hint}");
        stylize::frame::UpAxis::PosZ.turn(&mut lying);
        assert_eq!(Extents::of(&lying).up_hint(), None);
        assert_eq!(Extents::of(&lying).size, Extents::of(&standing).size);
        // A cube-ish mesh and one without finite vertices: no hint.
        assert_eq!(Extents::of(&[[0.0; 3], [1.0, 0.9, 1.0]]).up_hint(), None);
        assert_eq!(Extents::of(&[[f64::NAN; 3]]).up_hint(), None);
        let t = Extents::of(&standing).table();
        assert!(
            t.starts_with("extents: x 1.000000, y 3.000000, z 0.800000"),
            "{t}"
        );
    }

    #[test]
    fn check_succeeds_on_repairable_meshes_and_fails_on_refused_or_unreadable_ones() {
        assert!(check(args("bone.ply", false)).is_ok());
        assert!(check(args("cow.off", false)).is_ok());
        assert!(check(args("triceratops.off", true)).is_ok());
        let e = check(args("bad/nan_coordinates.obj", false)).expect_err("refused");
        assert!(format!("{e:#}").contains("vertex 3"), "{e:#}");
        let e = check(args("bad/truncated.ply", true)).expect_err("unreadable");
        assert!(format!("{e:#}").contains("truncated"), "{e:#}");
        let dropped = CheckArgs {
            drop_nonfinite: true,
            ..args("bad/nan_coordinates.obj", false)
        };
        assert!(check(dropped).is_ok(), "the drop option makes it usable");
        let bad = CheckArgs {
            needle_angle: f64::NAN,
            ..args("bone.ply", false)
        };
        assert!(check(bad).is_err());
    }
}
