//! Triangle-quality figures and a sampled two-sided Hausdorff distance.

use super::RemeshError;
use super::min_angle;
use crate::bvh::Bvh;
use crate::geometry::{norm, sub};

/// Refuses an out-of-range index or a non-finite vertex used by a face.
pub(super) fn check_faces(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Result<(), RemeshError> {
    for (fi, &f) in faces.iter().enumerate() {
        crate::bvh::face_triangle(positions, fi, f)?;
    }
    Ok(())
}

/// Triangle-quality figures of a mesh ([`quality`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quality {
    /// Vertices used by a face.
    pub vertices: usize,
    /// Faces.
    pub faces: usize,
    /// Mean length of the distinct edges.
    pub edge_length_mean: f64,
    /// Standard deviation of the distinct edges' lengths (population).
    pub edge_length_std: f64,
    /// The smallest corner angle of any face, in degrees (0 for a degenerate face).
    pub min_angle_deg: f64,
    /// Share of faces (0–1) with a corner under 10°.
    pub share_below_10_deg: f64,
    /// Share of faces (0–1) with a corner under 30°.
    pub share_below_30_deg: f64,
    /// Share of interior vertices (0–1; not on a boundary edge) with exactly 6 neighbours.
    pub share_valence_6: f64,
    /// The bounding-box diagonal of the used vertices.
    pub diagonal: f64,
}

impl Quality {
    /// `edge_length_std / edge_length_mean` (0 for no edge).
    pub fn edge_std_over_mean(&self) -> f64 {
        if self.edge_length_mean > 0.0 {
            self.edge_length_std / self.edge_length_mean
        } else {
            0.0
        }
    }
}

/// The quality figures of `(positions, faces)` (faces with repeated vertices count as faces with a
/// 0° corner; their edges count once each). Refuses out-of-range indices and non-finite vertices.
pub fn quality(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Result<Quality, RemeshError> {
    check_faces(positions, faces)?;
    let mut edges: Vec<[u32; 2]> = faces
        .iter()
        .flat_map(|f| {
            [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]]
                .into_iter()
                .filter(|e| e[0] != e[1])
                .map(|e| [e[0].min(e[1]), e[0].max(e[1])])
        })
        .collect();
    edges.sort_unstable();
    let mut used = vec![false; positions.len()];
    let mut boundary = vec![false; positions.len()];
    let mut valence = vec![0u32; positions.len()];
    let mut lengths = Vec::new();
    let mut i = 0;
    while i < edges.len() {
        let mut j = i;
        while j < edges.len() && edges[j] == edges[i] {
            j += 1;
        }
        let [a, b] = edges[i];
        lengths.push(norm(sub(positions[a as usize], positions[b as usize])));
        valence[a as usize] += 1;
        valence[b as usize] += 1;
        if j - i == 1 {
            boundary[a as usize] = true;
            boundary[b as usize] = true;
        }
        i = j;
    }
    let mut bb = crate::bvh::Aabb::EMPTY;
    for f in faces {
        for &v in f {
            used[v as usize] = true;
            bb.grow(positions[v as usize]);
        }
    }
    let n = lengths.len().max(1) as f64;
    let mean = lengths.iter().sum::<f64>() / n;
    let var = lengths.iter().map(|l| (l - mean) * (l - mean)).sum::<f64>() / n;
    let (mut min_deg, mut below10, mut below30) = (f64::INFINITY, 0usize, 0usize);
    for f in faces {
        let p = f.map(|v| positions[v as usize]);
        let a = min_angle(p[0], p[1], p[2]).to_degrees();
        min_deg = min_deg.min(a);
        below10 += (a < 10.0) as usize;
        below30 += (a < 30.0) as usize;
    }
    let interior: Vec<usize> = (0..positions.len())
        .filter(|&v| used[v] && !boundary[v])
        .collect();
    let six = interior.iter().filter(|&&v| valence[v] == 6).count();
    let nf = faces.len().max(1) as f64;
    Ok(Quality {
        vertices: used.iter().filter(|&&u| u).count(),
        faces: faces.len(),
        edge_length_mean: if lengths.is_empty() { 0.0 } else { mean },
        edge_length_std: var.sqrt(),
        min_angle_deg: if faces.is_empty() { 0.0 } else { min_deg },
        share_below_10_deg: below10 as f64 / nf,
        share_below_30_deg: below30 as f64 / nf,
        share_valence_6: if interior.is_empty() {
            0.0
        } else {
            six as f64 / interior.len() as f64
        },
        diagonal: if faces.is_empty() {
            0.0
        } else {
            norm(sub(bb.hi, bb.lo))
        },
    })
}

/// A two-sided distance between two surfaces ([`hausdorff`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hausdorff {
    /// The largest distance from a sample of `a` to surface `b`.
    pub a_to_b: f64,
    /// The largest distance from a sample of `b` to surface `a`.
    pub b_to_a: f64,
    /// The mean distance from `a`'s samples to `b`.
    pub mean_a_to_b: f64,
}

impl Hausdorff {
    /// `max(a_to_b, b_to_a)`.
    pub fn max(&self) -> f64 {
        self.a_to_b.max(self.b_to_a)
    }
}

/// The samples of one side: every vertex a face uses, and per face its centroid and its three edge
/// midpoints.
fn samples(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<[f64; 3]> {
    let mut used = vec![false; positions.len()];
    let mut out = Vec::with_capacity(faces.len() * 4 + positions.len());
    for f in faces {
        let p = f.map(|v| positions[v as usize]);
        for &v in f {
            used[v as usize] = true;
        }
        out.push([
            (p[0][0] + p[1][0] + p[2][0]) / 3.0,
            (p[0][1] + p[1][1] + p[2][1]) / 3.0,
            (p[0][2] + p[1][2] + p[2][2]) / 3.0,
        ]);
        for k in 0..3 {
            let (a, b) = (p[k], p[(k + 1) % 3]);
            out.push([
                (a[0] + b[0]) / 2.0,
                (a[1] + b[1]) / 2.0,
                (a[2] + b[2]) / 2.0,
            ]);
        }
    }
    out.extend(
        (0..positions.len())
            .filter(|&v| used[v])
            .map(|v| positions[v]),
    );
    out
}

/// The Hausdorff distance between surfaces `a` and `b`, both ways, sampled: from every vertex a
/// face uses and every face's centroid and edge midpoints on one side to the exact closest point of
/// the other surface (through a [`Bvh`]). Sampling makes it a lower bound of the true distance that
/// is tight when the faces are small against the distance's variation (the remesher's case: the
/// largest deviation is at vertices or mid-edge). Both meshes need at least one face.
pub fn hausdorff(
    a_positions: &[[f64; 3]],
    a_faces: &[[u32; 3]],
    b_positions: &[[f64; 3]],
    b_faces: &[[u32; 3]],
) -> Result<Hausdorff, RemeshError> {
    check_faces(a_positions, a_faces)?;
    check_faces(b_positions, b_faces)?;
    if a_faces.is_empty() || b_faces.is_empty() {
        return Err(RemeshError::Empty);
    }
    let ta = Bvh::new(a_positions, a_faces)?;
    let tb = Bvh::new(b_positions, b_faces)?;
    let one_way = |from: &[[f64; 3]], to: &Bvh| {
        let (mut worst, mut sum, mut n) = (0.0f64, 0.0, 0usize);
        for p in from {
            if let Some(c) = to.closest_point(*p) {
                let d = c.distance_squared.sqrt();
                worst = worst.max(d);
                sum += d;
                n += 1;
            }
        }
        (worst, sum / n.max(1) as f64)
    };
    let (a_to_b, mean_a_to_b) = one_way(&samples(a_positions, a_faces), &tb);
    let (b_to_a, _) = one_way(&samples(b_positions, b_faces), &ta);
    Ok(Hausdorff {
        a_to_b,
        b_to_a,
        mean_a_to_b,
    })
}
