//! Four pixels at a time: `f64` values in [`LANES`] lanes ([`L`]) and 3-vectors of them ([`V`]),
//! for the shading's Jacobian evaluated on several pixels together
//! ([`super::shading::shade_jacobian_lanes`], the renderer's backward).
//!
//! Every operation is the per-lane IEEE operation written as a loop over the lanes (the compiler
//! turns it into one 256-bit instruction under [`super::simd::dispatch`]), and the vector
//! operations evaluate in glam's `DVec3` order (`dot` = `(x·x') + (y·y') + (z·z')`, `cross` as
//! glam writes it), so a lane computes bit for bit what the scalar `DVec3` code computes.
//! The shading's scalar per-pixel code is their reference (tested bit for bit).

use std::ops::{Add, Div, Mul, Neg, Sub};

use glam::DVec3;

/// Pixels evaluated together (one 256-bit register of `f64`).
pub const LANES: usize = 4;

/// One `f64` per lane.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct L(pub [f64; LANES]);

/// One condition per lane.
pub type Mask = [bool; LANES];

impl L {
    #[inline(always)]
    pub fn splat(x: f64) -> Self {
        Self([x; LANES])
    }

    #[inline(always)]
    fn map(self, f: impl Fn(f64) -> f64) -> Self {
        Self(self.0.map(f))
    }

    #[inline(always)]
    fn zip(self, o: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        Self(std::array::from_fn(|l| f(self.0[l], o.0[l])))
    }

    #[inline(always)]
    fn test(self, o: Self, f: impl Fn(f64, f64) -> bool) -> Mask {
        std::array::from_fn(|l| f(self.0[l], o.0[l]))
    }

    #[inline(always)]
    pub fn sqrt(self) -> Self {
        self.map(f64::sqrt)
    }

    /// `f64::max` per lane.
    #[inline(always)]
    pub fn max(self, o: Self) -> Self {
        self.zip(o, f64::max)
    }

    /// `f64::clamp` per lane.
    #[inline(always)]
    pub fn clamp(self, lo: f64, hi: f64) -> Self {
        self.map(|x| x.clamp(lo, hi))
    }

    #[inline(always)]
    pub fn lt(self, o: Self) -> Mask {
        self.test(o, |a, b| a < b)
    }

    #[inline(always)]
    pub fn le(self, o: Self) -> Mask {
        self.test(o, |a, b| a <= b)
    }

    #[inline(always)]
    pub fn gt(self, o: Self) -> Mask {
        self.test(o, |a, b| a > b)
    }

    /// `m ? a : b` per lane.
    #[inline(always)]
    pub fn select(m: Mask, a: Self, b: Self) -> Self {
        Self(std::array::from_fn(|l| if m[l] { a.0[l] } else { b.0[l] }))
    }
}

/// Lane-wise `a && b`.
#[inline(always)]
pub fn and(a: Mask, b: Mask) -> Mask {
    std::array::from_fn(|l| a[l] && b[l])
}

macro_rules! lane_op {
    ($trait:ident, $f:ident, $op:tt) => {
        impl $trait for L {
            type Output = L;
            #[inline(always)]
            fn $f(self, o: L) -> L {
                self.zip(o, |a, b| a $op b)
            }
        }
    };
}
lane_op!(Add, add, +);
lane_op!(Sub, sub, -);
lane_op!(Mul, mul, *);
lane_op!(Div, div, /);

impl Neg for L {
    type Output = L;
    #[inline(always)]
    fn neg(self) -> L {
        self.map(|x| -x)
    }
}

/// A 3-vector per lane.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct V {
    pub x: L,
    pub y: L,
    pub z: L,
}

impl V {
    pub const ZERO: Self = Self {
        x: L([0.0; LANES]),
        y: L([0.0; LANES]),
        z: L([0.0; LANES]),
    };

    /// Lane `l` from `v[l]`.
    #[inline(always)]
    pub fn gather(v: [DVec3; LANES]) -> Self {
        Self {
            x: L(v.map(|v| v.x)),
            y: L(v.map(|v| v.y)),
            z: L(v.map(|v| v.z)),
        }
    }

    /// Lane `l`.
    #[inline(always)]
    pub fn lane(&self, l: usize) -> DVec3 {
        DVec3::new(self.x.0[l], self.y.0[l], self.z.0[l])
    }

    /// `DVec3::dot`: `(x·x') + (y·y') + (z·z')`.
    #[inline(always)]
    pub fn dot(self, o: Self) -> L {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    /// `DVec3::cross`, in glam's operand order.
    #[inline(always)]
    pub fn cross(self, o: Self) -> Self {
        Self {
            x: self.y * o.z - o.y * self.z,
            y: self.z * o.x - o.z * self.x,
            z: self.x * o.y - o.x * self.y,
        }
    }

    #[inline(always)]
    pub fn length_squared(self) -> L {
        self.dot(self)
    }

    /// `m ? a : b` per lane.
    #[inline(always)]
    pub fn select(m: Mask, a: Self, b: Self) -> Self {
        Self {
            x: L::select(m, a.x, b.x),
            y: L::select(m, a.y, b.y),
            z: L::select(m, a.z, b.z),
        }
    }
}

impl Add for V {
    type Output = V;
    #[inline(always)]
    fn add(self, o: V) -> V {
        V {
            x: self.x + o.x,
            y: self.y + o.y,
            z: self.z + o.z,
        }
    }
}

impl Sub for V {
    type Output = V;
    #[inline(always)]
    fn sub(self, o: V) -> V {
        V {
            x: self.x - o.x,
            y: self.y - o.y,
            z: self.z - o.z,
        }
    }
}

impl Neg for V {
    type Output = V;
    #[inline(always)]
    fn neg(self) -> V {
        V {
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }
}

/// Each component times the lane's scalar (`DVec3 * f64`).
impl Mul<L> for V {
    type Output = V;
    #[inline(always)]
    fn mul(self, s: L) -> V {
        V {
            x: self.x * s,
            y: self.y * s,
            z: self.z * s,
        }
    }
}

/// [`super::math::normalize`] per lane: `(x · inv, inv)` with `inv = 1 / √max(|x|², 1e-20)`.
#[inline(always)]
pub fn normalize(x: V) -> (V, L) {
    let inv = L::splat(1.0)
        / x.length_squared()
            .max(L::splat(super::math::NORMALIZE_EPS2))
            .sqrt();
    (x * inv, inv)
}

/// [`super::math::normalize_adjoint`] per lane.
#[inline(always)]
pub fn normalize_adjoint(x: V, y: V, inv: L, dy: V) -> V {
    let above = x.length_squared().gt(L::splat(super::math::NORMALIZE_EPS2));
    V::select(above, (dy - y * y.dot(dy)) * inv, dy * inv)
}
