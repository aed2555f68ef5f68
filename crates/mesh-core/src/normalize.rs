//! Side-2 cube normalization (spec §1.1).

use crate::geometry::bbox;

/// The affine map applied by [`side2_cube`]: `p_new = (p_old − centre) · scale`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Normalization {
    /// Bounding-box centre `(min + max) / 2` of the input, per axis.
    pub centre: [f64; 3],
    /// `2 / (largest bounding-box extent)`; `1` when the extent is zero or not finite.
    pub scale: f64,
}

impl Normalization {
    /// Applies the map to one point: `(p − centre) · scale`.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        [
            (p[0] - self.centre[0]) * self.scale,
            (p[1] - self.centre[1]) * self.scale,
            (p[2] - self.centre[2]) * self.scale,
        ]
    }

    /// Inverse map: `q / scale + centre` (back to the input's coordinates).
    pub fn invert(&self, q: [f64; 3]) -> [f64; 3] {
        [
            q[0] / self.scale + self.centre[0],
            q[1] / self.scale + self.centre[1],
            q[2] / self.scale + self.centre[2],
        ]
    }
}

/// Normalizes positions in place to the side-2 cube (spec §1.1): centre = (bbox_min + bbox_max)/2
/// per axis, scale = 2 / (largest bbox extent), `p ← (p − centre)·scale`. The longest side becomes
/// exactly [−1, 1]; the bbox is centred at the origin (the vertex centroid is *not* subtracted).
///
/// A degenerate input (all points equal, or empty) is only centred (`scale = 1`), never divided by 0.
pub fn side2_cube(positions: &mut [[f64; 3]]) -> Normalization {
    let (lo, hi) = bbox(positions);
    // Halved before adding or subtracting, so that finite bounds near f64::MAX cannot overflow
    // (`hi − lo` does beyond ~9e307). Halving is exact, so for every other input these are the
    // same numbers as `(lo + hi)/2` and `2 / (hi − lo)`.
    let centre: [f64; 3] = std::array::from_fn(|k| 0.5 * lo[k] + 0.5 * hi[k]);
    let half_extent = (0..3)
        .map(|k| 0.5 * hi[k] - 0.5 * lo[k])
        .fold(f64::NEG_INFINITY, f64::max);
    let scale = if half_extent > 0.0 && half_extent.is_finite() {
        1.0 / half_extent
    } else {
        1.0
    };
    let centre = if centre.iter().all(|c| c.is_finite()) {
        centre
    } else {
        [0.0; 3]
    };
    let n = Normalization { centre, scale };
    for p in positions.iter_mut() {
        *p = n.apply(*p);
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn longest_side_becomes_minus_one_to_one_and_bbox_is_centred() {
        let mut p = vec![[1.0, 10.0, -3.0], [5.0, 11.0, -2.0], [3.0, 10.5, -2.5]];
        let n = side2_cube(&mut p);
        assert_eq!(n.centre, [3.0, 10.5, -2.5]);
        assert!((n.scale - 0.5).abs() < 1e-15);
        let (lo, hi) = bbox(&p);
        assert!((lo[0] + 1.0).abs() < 1e-15 && (hi[0] - 1.0).abs() < 1e-15);
        for k in 0..3 {
            assert!((lo[k] + hi[k]).abs() < 1e-15, "axis {k} not centred");
        }
        // The inverse maps back.
        let q = n.invert(p[1]);
        assert!((q[0] - 5.0).abs() < 1e-14 && (q[1] - 11.0).abs() < 1e-14);
    }

    #[test]
    fn coordinates_near_the_largest_f64_are_normalized() {
        // hi − lo and lo + hi overflow here; the longest side must still become [−1, 1].
        let mut p = vec![
            [-1.5e308, 0.0, 1e308],
            [1.5e308, 1e308, -1e308],
            [0.0, 5e307, 0.0],
        ];
        let n = side2_cube(&mut p);
        assert!(n.scale > 0.0 && n.scale.is_finite() && n.centre == [0.0, 5e307, 0.0]);
        // The scale 1/1.5e308 is subnormal (two bits short of full precision): ±1 up to rounding.
        assert!(
            (p[0][0] + 1.0).abs() < 1e-14 && (p[1][0] - 1.0).abs() < 1e-14,
            "{p:?}"
        );
        assert!(
            p.iter()
                .flatten()
                .all(|v| v.is_finite() && v.abs() < 1.0 + 1e-14)
        );
        let q = n.invert(p[2]);
        assert!(q[0] == 0.0 && (q[1] / 5e307 - 1.0).abs() < 1e-15);
    }

    #[test]
    fn degenerate_inputs_stay_finite() {
        let mut single = vec![[2.0, 2.0, 2.0]];
        let n = side2_cube(&mut single);
        assert_eq!(n.scale, 1.0);
        assert_eq!(single[0], [0.0; 3]);
        let mut empty: Vec<[f64; 3]> = vec![];
        let n = side2_cube(&mut empty);
        assert!(n.scale.is_finite() && n.centre.iter().all(|c| c.is_finite()));
    }
}
