//! The strength-knob study of issue 41 (docs/strength.md): re-applying a saved deformation "more
//! strongly" with three controls, each at strength `s` (s = 1 is the optimized setting):
//!
//! - `gis λ·s`: the reference rule at λ = s·λ₀ (what `apply --lambda` and the viewer's slider do);
//! - `procrustes λ·s`: the textbook Kabsch rule at λ = s·λ₀ (it does not reproduce a `gis` run at
//!   s = 1: another local step);
//! - `geodesic R^s`: the rotations of the saved result (`gis` at λ₀) scaled along their geodesic,
//!   `R_v^s = exp(s·log R_v)` (same axis, angle × s), then the global step. At s = 1 it is the
//!   saved result (up to the log/exp round trip, ~1e-15);
//! - `strength s (procrustes increment)`: `R_v(s) = P_v(s·λ₀)·P_v(λ₀)ᵀ·R_v(λ₀)` with `P` the
//!   `procrustes` rule's rotations, then the global step — what `apply --strength` ships
//!   (`darap::Darap::forward_at_strength`), written out from three plain forward passes.
//!
//! For each: the volume ratio and the mean face-area ratio (as `stylize eval`), the share of
//! rotations over 90°, the faces in new self-intersecting pairs (exact, against the rest mesh),
//! and the **stylization**: the area-weighted mean over faces of `n_f · t_f` (the result's face
//! normal against the face's target, the normalized sum of its corners' unit targets) — the
//! quantity the optimization pushed up — and the largest vertex distance to the saved result
//! (side-2 cube frame, after the same recentre/rescale as `eval`).
//!
//! `cargo run --release -p stylize-cli --example strength_study [SAVED.npz…]` (default: the golden
//! bunny). Prints a Markdown table per file.

#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use darap::RotationRule;
use mesh_core::TriMesh;
use stylize::intersections::SourceIntersections;
use stylize::saved::SavedDeformation;

type Mat3 = [[f64; 3]; 3];

/// Axis and angle (θ ∈ [0, π]) of a rotation.
fn axis_angle(r: &Mat3) -> ([f64; 3], f64) {
    let c = ((r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0).clamp(-1.0, 1.0);
    let theta = c.acos();
    let v = [r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]];
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if theta < 1e-12 {
        return ([1.0, 0.0, 0.0], 0.0);
    }
    if n > 1e-6 {
        return (v.map(|x| x / n), theta);
    }
    // θ ≈ π: the axis is the column of (R + I)/2 with the largest diagonal.
    let k = (0..3).max_by(|&a, &b| r[a][a].total_cmp(&r[b][b])).unwrap();
    let col: [f64; 3] = std::array::from_fn(|i| (r[i][k] + if i == k { 1.0 } else { 0.0 }) / 2.0);
    let l = (col[0] * col[0] + col[1] * col[1] + col[2] * col[2]).sqrt();
    (col.map(|x| x / l), theta)
}

/// Rodrigues: the rotation by `theta` about the unit `axis`.
fn rotation(axis: [f64; 3], theta: f64) -> Mat3 {
    let (s, c) = theta.sin_cos();
    let [x, y, z] = axis;
    let t = 1.0 - c;
    [
        [c + x * x * t, x * y * t - z * s, x * z * t + y * s],
        [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
        [z * x * t - y * s, z * y * t + x * s, c + z * z * t],
    ]
}

fn power(r: &Mat3, s: f64) -> Mat3 {
    let (axis, theta) = axis_angle(r);
    rotation(axis, s * theta)
}

fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn transpose(a: &Mat3) -> Mat3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if l > 0.0 { v.map(|x| x / l) } else { v }
}

/// Area-weighted mean of n_f · t_f.
fn stylization(positions: &[[f64; 3]], faces: &[[u32; 3]], targets: &[[f64; 3]]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for f in faces {
        let [a, b, c] = f.map(|i| positions[i as usize]);
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let cr = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        let area2 = (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]).sqrt();
        if area2 == 0.0 {
            continue;
        }
        let t = unit(f.iter().fold([0.0; 3], |acc, &i| {
            let ti = unit(targets[i as usize]);
            [acc[0] + ti[0], acc[1] + ti[1], acc[2] + ti[2]]
        }));
        num += cr[0] * t[0] + cr[1] * t[1] + cr[2] * t[2];
        den += area2;
    }
    num / den
}

/// `eval`'s frame for a result: centroid at 0, bbox diagonal that of the rest (side-2 cube).
fn eval_frame(rest: &[[f64; 3]], p: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let c = mesh_core::geometry::vertex_centroid(p);
    let q: Vec<[f64; 3]> = p
        .iter()
        .map(|x| [x[0] - c[0], x[1] - c[1], x[2] - c[2]])
        .collect();
    let s = mesh_core::geometry::bbox_diagonal(rest) / mesh_core::geometry::bbox_diagonal(&q);
    q.iter().map(|x| x.map(|v| v * s)).collect()
}

fn main() {
    let mut files: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    if files.is_empty() {
        files.push(
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("../../fixtures/golden/bunny_targets.npz"),
        );
    }
    let strengths = [0.5, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0];
    for file in &files {
        let saved = SavedDeformation::read(file).unwrap();
        let lambda0 = saved.recorded_lambda().unwrap();
        let mut ready = saved
            .ready_layer(file, lambda0, Some(RotationRule::Gis))
            .unwrap();
        let rest = ready.rest.clone();
        let mut source = SourceIntersections::new(&rest).unwrap();
        let base = ready.at_lambda(lambda0).unwrap();
        let saved_result = eval_frame(&rest.positions, &base.positions);
        println!(
            "\n### {} ({} vertices, {} faces, saved λ₀ = {lambda0}; the rest mesh has {} intersecting pairs)\n",
            file.display(),
            rest.positions.len(),
            rest.faces.len(),
            source.source().pairs.len()
        );
        println!(
            "| control | s | volume ratio | face-area ratio | rotations > 90° | faces in new pairs | stylization n·t | max distance to saved |"
        );
        println!("|---|---:|---:|---:|---:|---:|---:|---:|");
        println!(
            "| rest mesh | 0 | 1 | 1 | 0 % | 0 | {:.4} | — |",
            stylization(&rest.positions, &rest.faces, &ready.targets)
        );
        ready.layer.set_rotation_rule(RotationRule::Procrustes);
        let procrustes_base = ready.at_lambda(lambda0).unwrap().rotations;
        ready.layer.set_rotation_rule(RotationRule::Gis);
        for control in [
            "gis λ·s",
            "procrustes λ·s",
            "geodesic R^s",
            "strength s (procrustes increment)",
        ] {
            for &s in &strengths {
                let (positions, rotations): (Vec<[f64; 3]>, Vec<Mat3>) = match control {
                    "geodesic R^s" => {
                        let rot: Vec<Mat3> = base.rotations.iter().map(|r| power(r, s)).collect();
                        (ready.layer.global_step(&rot), rot)
                    }
                    "strength s (procrustes increment)" => {
                        // What `apply --strength s` ships (darap::Darap::forward_at_strength),
                        // written out here from three plain forward passes.
                        ready.layer.set_rotation_rule(RotationRule::Procrustes);
                        let p = ready.at_lambda(s * lambda0).unwrap().rotations;
                        ready.layer.set_rotation_rule(RotationRule::Gis);
                        let rot: Vec<Mat3> = base
                            .rotations
                            .iter()
                            .zip(p.iter().zip(&procrustes_base))
                            .map(|(r, (ps, p1))| mul(&mul(ps, &transpose(p1)), r))
                            .collect();
                        let shipped = ready.at_strength(lambda0, s).unwrap();
                        let worst = shipped
                            .rotations
                            .iter()
                            .zip(&rot)
                            .flat_map(|(a, b)| {
                                (0..9).map(move |k| (a[k / 3][k % 3] - b[k / 3][k % 3]).abs())
                            })
                            .fold(0.0, f64::max);
                        assert!(worst < 1e-12, "the shipped control differs by {worst}");
                        (shipped.positions, shipped.rotations)
                    }
                    _ => {
                        let rule = if control.starts_with("gis") {
                            RotationRule::Gis
                        } else {
                            RotationRule::Procrustes
                        };
                        ready.layer.set_rotation_rule(rule);
                        let d = ready.at_lambda(s * lambda0).unwrap();
                        ready.layer.set_rotation_rule(RotationRule::Gis);
                        (d.positions, d.rotations)
                    }
                };
                let result = TriMesh::new(positions.clone(), rest.faces.clone());
                let (ratios, _, volume) = stylize::eval::pair_ratios(&rest, &result).unwrap();
                let area = ratios.iter().sum::<f64>() / ratios.len() as f64;
                let flipped = rotations
                    .iter()
                    .filter(|r| r[0][0] + r[1][1] + r[2][2] < 1.0)
                    .count() as f64
                    / rotations.len() as f64;
                let new_faces = source.check(&positions).unwrap().figures.new_faces;
                let framed = eval_frame(&rest.positions, &positions);
                let dist = framed
                    .iter()
                    .zip(&saved_result)
                    .map(|(a, b)| {
                        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2))
                            .sqrt()
                    })
                    .fold(0.0, f64::max);
                println!(
                    "| {control} | {s} | {volume:.3} | {area:.3} | {:.1} % | {new_faces} | {:.4} | {dist:.2e} |",
                    100.0 * flipped,
                    stylization(&framed, &rest.faces, &ready.targets)
                );
            }
        }
        // R^1 = R: the geodesic control's round trip at s = 1, rotation by rotation.
        let worst = base
            .rotations
            .iter()
            .map(|r| {
                let d = power(r, 1.0);
                (0..3)
                    .flat_map(|i| (0..3).map(move |j| (i, j)))
                    .map(|(i, j)| (d[i][j] - r[i][j]).abs())
                    .fold(0.0, f64::max)
            })
            .fold(0.0, f64::max);
        println!("\nlargest |R^1 − R| entry: {worst:.1e}");
    }
}
