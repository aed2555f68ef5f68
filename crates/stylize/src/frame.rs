//! Frames of a run: the input's own coordinates, the orientation (`mesh.up`), and the side-2
//! normalized frame the optimization works in.
//!
//! A run reads positions `p` in the **input frame** (the file's coordinates, axes and scale),
//! turns them so that the mesh's up axis becomes +y ([`UpAxis::rotation`], a proper rotation that
//! permutes axes and flips signs), and normalizes them to the side-2 cube (bounding box centred at
//! the origin, longest side 2; `runner::prepare_mesh`). Everything the optimization sees — the
//! renders, the view sampler's elevation above the xz-plane, dARAP, `deformation.npz`'s `verts` —
//! lives in that **normalized frame**. The map back is one affine map, [`InputFrame`]:
//!
//! `p = A·q + t`, with `A = Rᵀ / s` and `t = Rᵀ·c`
//!
//! where `R` is the orientation, `c` the centre and `s` the scale of the normalization (the two
//! successive normalizations of `prepare_mesh` folded into one). `deformation.npz` records it as the
//! extra key `to_input_frame`, a `<f8` (4, 4) homogeneous matrix `[[A, t], [0, 0, 0, 1]]` for column
//! vectors (NumPy: `p = q @ M[:3, :3].T + M[:3, 3]`).
//!
//! **Results.** dARAP's post-process (`recenter_rescale`, the default, and `recenter_only`) moves
//! the result's vertex centroid to the origin, whereas the rest mesh's bounding box is centred
//! there; a result written in the input frame ([`OutputFrame::Input`], the default) is therefore
//! first moved back by the rest mesh's vertex centroid `c̄` (the mean of the rest positions in the
//! normalized frame), so that it sits where the input was: `p = A·(q + c̄) + t`
//! ([`InputFrame::place_result`]). With λ = 0 this gives back the input mesh (up to the f32
//! rounding of `verts`). [`OutputFrame::Normalized`] writes `q` unchanged, as the reference does.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// The frame mesh outputs are written in (`run.output_frame`, `--output-frame`): a presentation
/// setting, never part of the task identity (a resume rewrites every output).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OutputFrame {
    /// The input's own coordinates, axes and scale (the default).
    #[default]
    Input,
    /// The reference's side-2 normalized frame (after the orientation `mesh.up`).
    Normalized,
}

impl OutputFrame {
    /// `input` or `normalized`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Input => "input",
            Self::Normalized => "normalized",
        }
    }
}

impl std::fmt::Display for OutputFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for OutputFrame {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "input" => Ok(Self::Input),
            "normalized" | "normalised" => Ok(Self::Normalized),
            other => Err(Error::Invalid(format!(
                "unknown output frame {other:?} (known: input, normalized)"
            ))),
        }
    }
}

/// The input's up axis (`mesh.up`, `--up`): which of its axes points up. The view sampler puts +y
/// up (elevations above the xz-plane, as the reference), so a z-up mesh (CAD, scans) is turned
/// with [`UpAxis::rotation`] before normalization and turned back on output.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum UpAxis {
    /// +x up.
    #[serde(rename = "+x")]
    PosX,
    /// −x up.
    #[serde(rename = "-x")]
    NegX,
    /// +y up (the reference's convention; the default).
    #[default]
    #[serde(rename = "+y")]
    PosY,
    /// −y up.
    #[serde(rename = "-y")]
    NegY,
    /// +z up (CAD, most scans and STL exports).
    #[serde(rename = "+z")]
    PosZ,
    /// −z up.
    #[serde(rename = "-z")]
    NegZ,
}

impl UpAxis {
    /// Every axis, in the order of [`UpAxis::name`]'s list.
    pub const ALL: [UpAxis; 6] = [
        Self::PosX,
        Self::NegX,
        Self::PosY,
        Self::NegY,
        Self::PosZ,
        Self::NegZ,
    ];

    /// `+x`, `-x`, `+y`, `-y`, `+z` or `-z`.
    pub fn name(self) -> &'static str {
        match self {
            Self::PosX => "+x",
            Self::NegX => "-x",
            Self::PosY => "+y",
            Self::NegY => "-y",
            Self::PosZ => "+z",
            Self::NegZ => "-z",
        }
    }

    /// The rotation `R` (rows; `p_turned = R·p`) that takes this axis to +y: a proper rotation
    /// (determinant +1, so faces keep their orientation) that permutes the axes and flips signs.
    /// `+z`: `(x, y, z) ↦ (x, z, −y)` (−90° about x); `-z`: `(x, −z, y)`; `+x`: `(−y, x, z)`
    /// (+90° about z); `-x`: `(y, −x, z)`; `-y`: `(x, −y, −z)` (180° about x); `+y`: identity.
    pub fn rotation(self) -> [[f64; 3]; 3] {
        match self {
            Self::PosY => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            Self::NegY => [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
            Self::PosZ => [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]],
            Self::NegZ => [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]],
            Self::PosX => [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            Self::NegX => [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        }
    }

    /// Turns positions in place (`p ← R·p`). The rotation only permutes and negates coordinates,
    /// so this is exact.
    pub fn turn(self, positions: &mut [[f64; 3]]) {
        if self == Self::PosY {
            return;
        }
        let r = self.rotation();
        for p in positions {
            *p = mat_vec(&r, *p);
        }
    }
}

impl std::fmt::Display for UpAxis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for UpAxis {
    type Err = Error;
    /// `+x`, `-x`, `+y`, `-y`, `+z`, `-z`; a bare `x`, `y`, `z` means the positive axis.
    fn from_str(s: &str) -> Result<Self> {
        let t = s.trim().to_ascii_lowercase();
        let t = if t.len() == 1 { format!("+{t}") } else { t };
        Self::ALL
            .into_iter()
            .find(|a| a.name() == t)
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "unknown up axis {s:?} (known: +x, -x, +y, -y, +z, -z; x, y, z mean +)"
                ))
            })
    }
}

fn mat_vec(m: &[[f64; 3]; 3], p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2])
}

/// The affine map from the normalized frame back to the input frame, `p = A·q + t` (see the module
/// documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputFrame {
    /// `A` (rows).
    pub linear: [[f64; 3]; 3],
    /// `t`.
    pub translation: [f64; 3],
}

impl InputFrame {
    /// The identity map (a mesh already in the normalized frame).
    pub const IDENTITY: Self = Self {
        linear: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [0.0; 3],
    };

    /// The inverse of `q = (R·p − centre)·scale`: `A = Rᵀ/scale`, `t = Rᵀ·centre`.
    pub fn from_normalization(up: UpAxis, centre: [f64; 3], scale: f64) -> Self {
        let r = up.rotation();
        let rt: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| r[j][i]));
        Self {
            linear: rt.map(|row| row.map(|v| v / scale)),
            translation: mat_vec(&rt, centre),
        }
    }

    /// `A·q + t`.
    pub fn apply(&self, q: [f64; 3]) -> [f64; 3] {
        let a = mat_vec(&self.linear, q);
        std::array::from_fn(|i| a[i] + self.translation[i])
    }

    /// The map the other way (input → normalized), `q = A⁻¹·(p − t)`; an error when `A` is
    /// singular or not finite.
    pub fn inverse(&self) -> Result<Self> {
        let m = &self.linear;
        let cof = |i: usize, j: usize| {
            let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
            let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
            m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
        };
        let det = m[0][0] * cof(0, 0) + m[0][1] * cof(0, 1) + m[0][2] * cof(0, 2);
        if !(det.is_finite() && det != 0.0) {
            return Err(Error::Invalid(format!(
                "the recorded frame transform is singular or not finite (determinant {det})"
            )));
        }
        // inverse = adjugate / det, adjugate[i][j] = cofactor[j][i].
        let inv: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| cof(j, i) / det));
        let t = mat_vec(&inv, self.translation).map(|v| -v);
        Ok(Self {
            linear: inv,
            translation: t,
        })
    }

    /// The 4×4 homogeneous matrix (row-major), as `deformation.npz`'s `to_input_frame` stores it.
    pub fn to_matrix(&self) -> [f64; 16] {
        let (a, t) = (&self.linear, &self.translation);
        [
            a[0][0], a[0][1], a[0][2], t[0], //
            a[1][0], a[1][1], a[1][2], t[1], //
            a[2][0], a[2][1], a[2][2], t[2], //
            0.0, 0.0, 0.0, 1.0,
        ]
    }

    /// Reads the 4×4 matrix of [`Self::to_matrix`]: finite, last row `0 0 0 1`, invertible.
    pub fn from_matrix(m: &[f64]) -> Result<Self> {
        if m.len() != 16 || m.iter().any(|v| !v.is_finite()) || m[12..] != [0.0, 0.0, 0.0, 1.0] {
            return Err(Error::Invalid(
                "`to_input_frame` must be a finite 4×4 affine matrix with last row 0 0 0 1".into(),
            ));
        }
        let f = Self {
            linear: std::array::from_fn(|i| std::array::from_fn(|j| m[4 * i + j])),
            translation: [m[3], m[7], m[11]],
        };
        f.inverse()?;
        Ok(f)
    }

    /// Positions of a dARAP result `q` (normalized frame) placed in the input frame: moved back by
    /// the rest mesh's vertex centroid when the post-process recentred the result (`recentred`),
    /// then mapped by `A·q + t` (see the module documentation).
    pub fn place_result(
        &self,
        result: &[[f64; 3]],
        rest: &[[f64; 3]],
        recentred: bool,
    ) -> Vec<[f64; 3]> {
        let shift = if recentred {
            mesh_core::geometry::vertex_centroid(rest)
        } else {
            [0.0; 3]
        };
        result
            .iter()
            .map(|q| self.apply([q[0] + shift[0], q[1] + shift[1], q[2] + shift[2]]))
            .collect()
    }

    /// The inverse of [`Self::place_result`]: a result written in the input frame, back in the
    /// normalized frame with its vertex centroid at the origin when `recentred`.
    pub fn unplace_result(
        &self,
        placed: &[[f64; 3]],
        rest: &[[f64; 3]],
        recentred: bool,
    ) -> Result<Vec<[f64; 3]>> {
        let inv = self.inverse()?;
        let shift = if recentred {
            mesh_core::geometry::vertex_centroid(rest)
        } else {
            [0.0; 3]
        };
        Ok(placed
            .iter()
            .map(|p| {
                let q = inv.apply(*p);
                [q[0] - shift[0], q[1] - shift[1], q[2] - shift[2]]
            })
            .collect())
    }
}

/// Whether dARAP's post-process moves the result's vertex centroid to the origin.
pub fn recentres(post: darap::PostProcess) -> bool {
    post != darap::PostProcess::None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(m: &[[f64; 3]; 3]) -> f64 {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    }

    #[test]
    fn every_up_axis_is_a_proper_rotation_taking_it_to_plus_y() {
        for up in UpAxis::ALL {
            let r = up.rotation();
            assert_eq!(det(&r), 1.0, "{up}");
            let axis = match up {
                UpAxis::PosX => [1.0, 0.0, 0.0],
                UpAxis::NegX => [-1.0, 0.0, 0.0],
                UpAxis::PosY => [0.0, 1.0, 0.0],
                UpAxis::NegY => [0.0, -1.0, 0.0],
                UpAxis::PosZ => [0.0, 0.0, 1.0],
                UpAxis::NegZ => [0.0, 0.0, -1.0],
            };
            assert_eq!(mat_vec(&r, axis), [0.0, 1.0, 0.0], "{up}");
            assert_eq!(up.name().parse::<UpAxis>().ok(), Some(up));
        }
        assert_eq!("z".parse::<UpAxis>().ok(), Some(UpAxis::PosZ));
        assert!("w".parse::<UpAxis>().is_err());
        assert!("+zz".parse::<UpAxis>().is_err());
    }

    #[test]
    fn input_frame_inverts_the_normalization_and_reads_back_from_its_matrix() {
        let up = UpAxis::PosZ;
        let (centre, scale) = ([3.0, -2.0, 1000.5], 0.002);
        let frame = InputFrame::from_normalization(up, centre, scale);
        let p = [12.5, 400.0, -7.25];
        let mut q = [p];
        up.turn(&mut q);
        let q = q[0];
        let q = [
            (q[0] - centre[0]) * scale,
            (q[1] - centre[1]) * scale,
            (q[2] - centre[2]) * scale,
        ];
        let back = frame.apply(q);
        for k in 0..3 {
            assert!((back[k] - p[k]).abs() < 1e-9, "{back:?} vs {p:?}");
        }
        let inv = frame.inverse().unwrap_or(InputFrame::IDENTITY);
        let q2 = inv.apply(p);
        for k in 0..3 {
            assert!((q2[k] - q[k]).abs() < 1e-12, "{q2:?} vs {q:?}");
        }
        let read = InputFrame::from_matrix(&frame.to_matrix()).unwrap_or(InputFrame::IDENTITY);
        assert_eq!(read, frame);
        let mut singular = frame.to_matrix();
        singular[..3].copy_from_slice(&[0.0; 3]);
        assert!(InputFrame::from_matrix(&singular).is_err());
        let mut nan = frame.to_matrix();
        nan[5] = f64::NAN;
        assert!(InputFrame::from_matrix(&nan).is_err());
        assert!(InputFrame::from_matrix(&[1.0; 9]).is_err());
    }

    #[test]
    fn place_result_moves_the_centroid_back_and_unplace_inverts_it() {
        let frame = InputFrame::from_normalization(UpAxis::NegX, [5.0, 6.0, 7.0], 0.5);
        let rest = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let c = mesh_core::geometry::vertex_centroid(&rest);
        // A recentred result: the rest mesh moved so that its centroid is at the origin.
        let result: Vec<[f64; 3]> = rest
            .iter()
            .map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]])
            .collect();
        let placed = frame.place_result(&result, &rest, true);
        for (a, r) in placed.iter().zip(&rest) {
            let b = frame.apply(*r);
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-12);
            }
        }
        let back = frame
            .unplace_result(&placed, &rest, true)
            .unwrap_or_default();
        for (a, b) in back.iter().zip(&result) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-12);
            }
        }
    }
}
