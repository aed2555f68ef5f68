//! Model-free stylization: target normals from a style's Gauss map, reached by optimizing the dARAP
//! targets `x` with Adam on the area-weighted normal-alignment objective of the **deformed** mesh
//! ([`alignment`]).
//!
//! A style maps a unit normal to a unit target direction:
//! - `cube`: the nearest axis `±e_i` (largest |component|, its sign);
//! - `octahedron`: the nearest of the eight `(±1, ±1, ±1)/√3` (component signs, 0 counting as +);
//! - `exemplar:MESH`: the exemplar's area-weighted vertex normal with the largest dot product.
//!
//! Face `f`'s target is the style applied to the **rest** face normal (fixed for the run). The
//! dARAP layer (same λ semantics as the text path) turns `x` into positions; the gradient flows
//! `ℓ → positions (alignment adjoint) → x (dARAP adjoint)`.

pub mod alignment;
pub mod target_angle;

use std::path::{Path, PathBuf};

use crate::error::{Context, Result, invalid};

/// A normal style (a Gauss-map target).
#[derive(Clone, Debug, PartialEq)]
pub enum Style {
    /// Nearest axis direction ±e_i.
    Cube,
    /// Nearest (±1, ±1, ±1)/√3.
    Octahedron,
    /// Nearest unit vertex normal of an exemplar mesh.
    Exemplar {
        /// Where the exemplar came from (for the record).
        path: PathBuf,
        /// The exemplar's unit vertex normals (zero-length ones dropped).
        normals: Vec<[f64; 3]>,
    },
}

impl Style {
    /// Parses `cube`, `octahedron` or `exemplar:PATH` (the exemplar mesh is read here).
    pub fn parse(spec: &str) -> Result<Self> {
        match spec.trim() {
            "cube" => Ok(Self::Cube),
            "octahedron" => Ok(Self::Octahedron),
            s => {
                let Some(path) = s.strip_prefix("exemplar:") else {
                    invalid!("unknown style {spec:?} (expected cube, octahedron or exemplar:MESH)");
                };
                Self::exemplar(Path::new(path))
            }
        }
    }

    /// Reads an exemplar mesh and keeps its unit area-weighted vertex normals.
    pub fn exemplar(path: &Path) -> Result<Self> {
        let mesh = mesh_core::io::read_mesh(path)
            .with_context(|| format!("cannot read exemplar mesh {}", path.display()))?;
        if let Some(bad) = mesh
            .faces
            .iter()
            .flatten()
            .find(|&&v| v as usize >= mesh.positions.len())
        {
            invalid!("exemplar {}: face index {bad} out of range", path.display());
        }
        if let Some(v) = mesh
            .positions
            .iter()
            .position(|p| p.iter().any(|c| !c.is_finite()))
        {
            invalid!(
                "exemplar {}: vertex {v} has a non-finite coordinate {:?}",
                path.display(),
                mesh.positions[v]
            );
        }
        let normals: Vec<[f64; 3]> =
            mesh_core::normals::vertex_normals_area_weighted(&mesh.positions, &mesh.faces)
                .into_iter()
                .filter(|n| {
                    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                    (l - 1.0).abs() < 1e-6
                })
                .collect();
        if normals.is_empty() {
            invalid!("exemplar {} has no usable vertex normals", path.display());
        }
        Ok(Self::Exemplar {
            path: path.to_path_buf(),
            normals,
        })
    }

    /// The name recorded in run directories (`exemplar:PATH` for exemplars).
    pub fn name(&self) -> String {
        match self {
            Self::Cube => "cube".into(),
            Self::Octahedron => "octahedron".into(),
            Self::Exemplar { path, .. } => format!("exemplar:{}", path.display()),
        }
    }

    /// The target of one unit normal `n`. A zero `n` maps to a valid target too.
    pub fn target(&self, n: [f64; 3]) -> [f64; 3] {
        match self {
            Self::Cube => {
                let axis = (0..3)
                    .max_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
                    .unwrap_or(0);
                let mut t = [0.0; 3];
                t[axis] = if n[axis] < 0.0 { -1.0 } else { 1.0 };
                t
            }
            Self::Octahedron => {
                let s = 1.0 / 3.0_f64.sqrt();
                n.map(|c| if c < 0.0 { -s } else { s })
            }
            Self::Exemplar { normals, .. } => normals
                .iter()
                .copied()
                .max_by(|a, b| {
                    let da = a[0] * n[0] + a[1] * n[1] + a[2] * n[2];
                    let db = b[0] * n[0] + b[1] * n[1] + b[2] * n[2];
                    da.total_cmp(&db)
                })
                .unwrap_or([0.0, 0.0, 1.0]),
        }
    }

    /// Per-face targets from the rest mesh's unit face normals (a degenerate face gets the target
    /// of `(0, 0, 1)`; its weight in the objective is its area, so it hardly matters).
    pub fn face_targets(&self, positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<[f64; 3]> {
        faces
            .iter()
            .map(|&f| {
                let n = alignment::face_cross(positions, f);
                let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                let unit = if l > 1e-300 {
                    n.map(|c| c / l)
                } else {
                    [0.0, 0.0, 1.0]
                };
                self.target(unit)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::alignment::*;
    use super::*;

    fn unit(v: [f64; 3]) -> [f64; 3] {
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|c| c / l)
    }

    #[test]
    fn cube_style_picks_the_nearest_signed_axis() {
        assert_eq!(Style::Cube.target(unit([0.2, -0.9, 0.1])), [0.0, -1.0, 0.0]);
        assert_eq!(Style::Cube.target(unit([0.7, 0.1, 0.69])), [1.0, 0.0, 0.0]);
        assert_eq!(Style::Cube.target(unit([0.1, 0.1, -0.5])), [0.0, 0.0, -1.0]);
    }

    #[test]
    fn octahedron_style_is_the_nearest_corner_direction() {
        let s = 1.0 / 3.0_f64.sqrt();
        // Brute force over the 8 candidates as an independent reference.
        let n = unit([0.3, -0.8, 0.2]);
        let mut best = ([0.0; 3], f64::NEG_INFINITY);
        for sx in [-s, s] {
            for sy in [-s, s] {
                for sz in [-s, s] {
                    let d = sx * n[0] + sy * n[1] + sz * n[2];
                    if d > best.1 {
                        best = ([sx, sy, sz], d);
                    }
                }
            }
        }
        assert_eq!(Style::Octahedron.target(n), best.0);
    }

    #[test]
    fn exemplar_style_picks_the_most_aligned_normal() {
        let style = Style::Exemplar {
            path: "x".into(),
            normals: vec![[1.0, 0.0, 0.0], unit([0.0, 1.0, 1.0]), [0.0, -1.0, 0.0]],
        };
        assert_eq!(style.target(unit([0.1, 0.5, 0.6])), unit([0.0, 1.0, 1.0]));
        assert_eq!(style.target(unit([0.1, -0.9, 0.0])), [0.0, -1.0, 0.0]);
    }

    #[test]
    fn exemplar_octahedron_file_reproduces_the_cube_style() {
        // The regular octahedron's area-weighted vertex normals are exactly ±e_i, so as an
        // exemplar it must give the cube style's targets.
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("octahedron.obj");
        mesh_core::io::write_mesh(&path, &mesh_core::shapes::octahedron(), None)
            .unwrap_or_else(|e| panic!("{e}"));
        let spec = format!("exemplar:{}", path.display());
        let style = Style::parse(&spec).unwrap_or_else(|e| panic!("{e:#}"));
        for n in [
            [0.2, -0.9, 0.1],
            [0.7, 0.1, 0.69],
            [0.1, 0.1, -0.5],
            [-0.6, 0.3, 0.2],
        ] {
            let n = unit(n);
            assert_eq!(style.target(n), Style::Cube.target(n), "{n:?}");
        }
        assert!(Style::parse("exemplar:/no/such/file.obj").is_err());
        // A vertex at infinity is named as such (not "no usable vertex normals").
        std::fs::write(
            &path,
            "v 0 0 0\nv 1 0 0\nv 0 inf 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let e = Style::parse(&spec)
            .err()
            .map(|e| format!("{e:#}"))
            .unwrap_or_default();
        assert!(e.contains("vertex 2") && e.contains("non-finite"), "{e}");
    }

    #[test]
    fn unknown_style_is_a_clear_error() {
        let e = Style::parse("sphere")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("unknown style"), "{e}");
    }

    #[test]
    fn alignment_is_zero_on_target_and_area_weighted_off_target() {
        // A right triangle of area 1/2 in the xy-plane, normal +z.
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let f = [[0, 1, 2]];
        assert_eq!(alignment_loss(&p, &f, &[[0.0, 0.0, 1.0]]), 0.0);
        // Target +x: 1 − n·t = 1, times the area 1/2.
        assert!((alignment_loss(&p, &f, &[[1.0, 0.0, 0.0]]) - 0.5).abs() < 1e-15);
        // Opposite target: 2 · 1/2.
        assert!((alignment_loss(&p, &f, &[[0.0, 0.0, -1.0]]) - 1.0).abs() < 1e-15);
        assert!((mean_alignment(&p, &f, &[[0.0, 0.0, -1.0]]) + 1.0).abs() < 1e-15);
    }

    #[test]
    fn alignment_gradient_matches_central_differences() {
        let p = vec![
            [0.1, -0.2, 0.05],
            [1.0, 0.1, 0.2],
            [0.2, 0.9, -0.1],
            [0.6, 0.5, 0.8],
        ];
        let f = [[0, 1, 2], [0, 2, 3], [1, 3, 2]];
        let t = [
            unit([0.3, 0.1, 1.0]),
            unit([-1.0, 0.2, 0.1]),
            unit([0.0, -1.0, 0.4]),
        ];
        let (_, g) = alignment_loss_and_grad(&p, &f, &t);
        let h = 1e-6;
        for v in 0..p.len() {
            for c in 0..3 {
                let mut a = p.clone();
                let mut b = p.clone();
                a[v][c] += h;
                b[v][c] -= h;
                let fd = (alignment_loss(&a, &f, &t) - alignment_loss(&b, &f, &t)) / (2.0 * h);
                assert!(
                    (fd - g[v][c]).abs() < 1e-7,
                    "v{v} c{c}: fd {fd} vs {}",
                    g[v][c]
                );
            }
        }
    }

    #[test]
    fn degenerate_faces_give_finite_gradients() {
        let p = [[0.0; 3], [0.0; 3], [0.0; 3], [1.0, 1.0, 1.0]];
        let f = [[0, 1, 2], [0, 1, 3]];
        let (l, g) = alignment_loss_and_grad(&p, &f, &[[0.0, 0.0, 1.0]; 2]);
        assert!(l.is_finite());
        assert!(g.iter().flatten().all(|x| x.is_finite()));
        assert!(mean_alignment(&p, &f, &[[0.0, 0.0, 1.0]; 2]).is_finite());
    }
}
