//! Small vector helpers with their adjoints.

pub use glam::DVec3;

/// Squared-length floor of the guarded normalization (spec §6): x / sqrt(max(|x|², 1e-20)).
pub const NORMALIZE_EPS2: f64 = 1e-20;

/// Guarded normalization y = x / sqrt(max(|x|², 1e-20)); returns (y, 1/sqrt(max(|x|², 1e-20))).
#[inline(always)]
pub fn normalize(x: DVec3) -> (DVec3, f64) {
    let inv = 1.0 / x.length_squared().max(NORMALIZE_EPS2).sqrt();
    (x * inv, inv)
}

/// Adjoint of [`normalize`]: given y, its `inv` and dL/dy, returns dL/dx.
/// Where the floor is active the map is x·const and the adjoint is dy·inv.
#[inline(always)]
pub fn normalize_adjoint(x: DVec3, y: DVec3, inv: f64, dy: DVec3) -> DVec3 {
    if x.length_squared() > NORMALIZE_EPS2 {
        (dy - y * y.dot(dy)) * inv
    } else {
        dy * inv
    }
}

/// Adjoint of g = e1 × e2: returns (dL/de1, dL/de2) from dL/dg.
#[inline(always)]
pub fn cross_adjoint(e1: DVec3, e2: DVec3, dg: DVec3) -> (DVec3, DVec3) {
    (e2.cross(dg), dg.cross(e1))
}

/// Loads vertex `i` of a slice of triples.
#[inline(always)]
pub fn v3(p: &[[f64; 3]], i: u32) -> DVec3 {
    DVec3::from(p[i as usize])
}
