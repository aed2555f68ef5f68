//! Cameras and lights: the reference view sampler (spec §6), turntable orbits and the adaptive
//! camera-distance multiplier (spec §5).
//!
//! Conventions: world up is +y; every camera looks at the origin. A view at elevation `e`, azimuth
//! `a` (degrees) and distance `d` has its eye at `d·(cos e cos a, sin e, cos e sin a)`. The field of
//! view is vertical, in degrees; 90° is a focal length of 1, the reference's effective value.

use glam::DVec3;
use rand::{Rng, RngCore};

use crate::{RenderError, View};

/// Ranges of the uniform per-view draws. Each range is `[low, high)`.
///
/// Under feature `serde` this (de)serializes by its field names, except that
/// [`fov_y_deg`](Self::fov_y_deg) is named `fov_deg` (the config files' key since the first
/// release: a config's `[camera]` section embeds this struct); missing keys take the defaults and
/// unknown keys are refused.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct CameraConfig {
    /// Elevation above the xz-plane in degrees.
    pub elevation_deg: [f64; 2],
    /// Azimuth around +y in degrees (measured from +x towards +z).
    pub azimuth_deg: [f64; 2],
    /// Distance of the eye from the origin, before the adaptive multiplier.
    pub distance: [f64; 2],
    /// Vertical field of view in degrees (serialized as `fov_deg`).
    #[cfg_attr(feature = "serde", serde(rename = "fov_deg"))]
    pub fov_y_deg: f64,
}

impl Default for CameraConfig {
    /// The reference sampler: elevation [0°, 60°], azimuth [0°, 361°), distance [2.5, 3.0], fov 90°.
    fn default() -> Self {
        Self {
            elevation_deg: [0.0, 60.0],
            azimuth_deg: [0.0, 361.0],
            distance: [2.5, 3.0],
            fov_y_deg: 90.0,
        }
    }
}

impl CameraConfig {
    /// Names accepted by [`CameraConfig::preset`].
    pub const PRESETS: &'static [&'static str] = &["default", "tall"];

    /// Preset for tall, slender shapes (humans): elevation [0°, 30°], distance [1.4, 2.6].
    pub fn tall() -> Self {
        Self {
            elevation_deg: [0.0, 30.0],
            distance: [1.4, 2.6],
            ..Self::default()
        }
    }

    /// Looks a preset up by name (`"default"` or `"tall"`).
    pub fn preset(name: &str) -> Result<Self, RenderError> {
        match name {
            "default" => Ok(Self::default()),
            "tall" => Ok(Self::tall()),
            other => Err(RenderError::InvalidInput(format!(
                "unknown camera preset {other:?} (known: {})",
                Self::PRESETS.join(", ")
            ))),
        }
    }
}

/// Eye position `d·(cos e cos a, sin e, cos e sin a)` for elevation `e` and azimuth `a` in degrees.
pub fn eye_position(elevation_deg: f64, azimuth_deg: f64, distance: f64) -> [f64; 3] {
    let (e, a) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
    [
        distance * e.cos() * a.cos(),
        distance * e.sin(),
        distance * e.cos() * a.sin(),
    ]
}

/// A cosine-weighted unit direction in the hemisphere around the unit vector `axis`, from two
/// uniform numbers `u1, u2 ∈ [0, 1)`: polar angle θ with cos θ = sqrt(1 − u1) (density ∝ cos θ),
/// azimuth 2π·u2 in a fixed frame built around `axis`.
pub fn cosine_weighted_direction(axis: [f64; 3], u1: f64, u2: f64) -> [f64; 3] {
    let z = DVec3::from(axis).normalize_or(DVec3::Y);
    // A fixed orthonormal frame around z (Frisvad / Duff et al. branchless construction).
    let sign = 1.0_f64.copysign(z.z);
    let a = -1.0 / (sign + z.z);
    let b = z.x * z.y * a;
    let x = DVec3::new(1.0 + sign * z.x * z.x * a, sign * b, -sign * z.x);
    let y = DVec3::new(b, sign + z.y * z.y * a, -z.y);
    let r = u1.clamp(0.0, 1.0).sqrt();
    let phi = std::f64::consts::TAU * u2;
    let cos_theta = (1.0 - u1.clamp(0.0, 1.0)).sqrt();
    (x * (r * phi.cos()) + y * (r * phi.sin()) + z * cos_theta)
        .normalize_or(z)
        .into()
}

fn uniform(rng: &mut dyn RngCore, range: [f64; 2]) -> f64 {
    range[0] + (range[1] - range[0]) * rng.random::<f64>()
}

/// Draws `n` views from `config`, the distance range scaled by `adapt_multiplier`.
///
/// Per view, in this order: elevation, azimuth and distance (uniform), then the light: a
/// cosine-weighted direction around normalize(eye) (two uniforms), placed at the view's camera
/// distance. The same seeded generator state gives the same views.
pub fn sample_views(
    config: &CameraConfig,
    n: usize,
    adapt_multiplier: f64,
    rng: &mut dyn RngCore,
) -> Vec<View> {
    (0..n)
        .map(|_| {
            let elevation = uniform(rng, config.elevation_deg);
            let azimuth = uniform(rng, config.azimuth_deg);
            let distance = uniform(rng, config.distance) * adapt_multiplier;
            let eye = eye_position(elevation, azimuth, distance);
            let (u1, u2) = (rng.random::<f64>(), rng.random::<f64>());
            let dir = DVec3::from(cosine_weighted_direction(eye, u1, u2));
            View {
                eye,
                target: [0.0; 3],
                up: [0.0, 1.0, 0.0],
                fov_y_deg: config.fov_y_deg,
                light_pos: (dir * distance).into(),
            }
        })
        .collect()
}

/// `n` views on a circle for turntables: azimuth 360°·k/n, fixed elevation and distance, the light
/// at the eye (a head light).
pub fn orbit_views(n: usize, elevation_deg: f64, distance: f64, fov_y_deg: f64) -> Vec<View> {
    (0..n)
        .map(|k| {
            let azimuth = 360.0 * k as f64 / n as f64;
            let eye = eye_position(elevation_deg, azimuth, distance);
            View {
                eye,
                target: [0.0; 3],
                up: [0.0, 1.0, 0.0],
                fov_y_deg,
                light_pos: eye,
            }
        })
        .collect()
}

/// The adaptive distance multiplier (spec §5): the largest |coordinate| after centring the
/// axis-aligned bounding box at the origin. Returns 1 for an empty input, one with a non-finite
/// coordinate, or one of zero extent (a camera at the origin would see nothing).
pub fn adapt_multiplier(positions: &[[f64; 3]]) -> f64 {
    if positions.iter().flatten().any(|c| !c.is_finite()) {
        return 1.0;
    }
    let (lo, hi) = mesh_core::geometry::bbox(positions);
    let m = (0..3)
        .map(|k| 0.5 * (hi[k] - lo[k]))
        .fold(f64::NEG_INFINITY, f64::max);
    if m.is_finite() && m > 0.0 { m } else { 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn close(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
        (0..3).all(|k| (a[k] - b[k]).abs() <= tol)
    }

    #[test]
    fn eye_position_matches_spherical_formula_at_axes() {
        assert!(close(eye_position(0.0, 0.0, 2.0), [2.0, 0.0, 0.0], 1e-12));
        assert!(close(eye_position(0.0, 90.0, 2.0), [0.0, 0.0, 2.0], 1e-12));
        assert!(close(eye_position(90.0, 37.0, 3.0), [0.0, 3.0, 0.0], 1e-12));
        let e = eye_position(30.0, 45.0, 1.0);
        assert!((DVec3::from(e).length() - 1.0).abs() < 1e-12);
        assert!((e[1] - 0.5).abs() < 1e-12);
    }

    #[test]
    fn sampled_views_stay_in_ranges_and_repeat_with_the_seed() {
        let cfg = CameraConfig::default();
        let a = sample_views(&cfg, 200, 1.3, &mut ChaCha8Rng::seed_from_u64(7));
        let b = sample_views(&cfg, 200, 1.3, &mut ChaCha8Rng::seed_from_u64(7));
        let c = sample_views(&cfg, 200, 1.3, &mut ChaCha8Rng::seed_from_u64(8));
        assert_eq!(a, b);
        assert_ne!(a, c);
        for v in &a {
            let eye = DVec3::from(v.eye);
            let d = eye.length();
            assert!(
                (2.5 * 1.3 - 1e-9..3.0 * 1.3 + 1e-9).contains(&d),
                "distance {d}"
            );
            let elevation = (eye.y / d).asin().to_degrees();
            assert!(
                (-1e-9..60.0 + 1e-9).contains(&elevation),
                "elevation {elevation}"
            );
            let light = DVec3::from(v.light_pos);
            assert!(
                (light.length() - d).abs() < 1e-9,
                "light distance equals camera distance"
            );
            assert!(
                light.dot(eye) >= -1e-9,
                "light lies in the hemisphere around the eye"
            );
            assert_eq!(v.target, [0.0; 3]);
            assert_eq!(v.fov_y_deg, 90.0);
        }
    }

    #[test]
    fn tall_preset_uses_its_ranges() {
        let cfg = CameraConfig::preset("tall").expect("known preset");
        assert_eq!(cfg, CameraConfig::tall());
        for v in sample_views(&cfg, 100, 1.0, &mut ChaCha8Rng::seed_from_u64(1)) {
            let eye = DVec3::from(v.eye);
            let d = eye.length();
            assert!((1.4 - 1e-9..2.6 + 1e-9).contains(&d));
            assert!((eye.y / d).asin().to_degrees() <= 30.0 + 1e-9);
        }
        assert!(CameraConfig::preset("wide").is_err());
    }

    #[test]
    fn cosine_weighted_light_has_mean_cosine_two_thirds() {
        // For density p(ω) = cos θ / π on the hemisphere, E[cos θ] = 2/3 and E[cos² θ] = 1/2.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let axis = DVec3::new(0.3, -0.5, 0.8).normalize();
        let n = 40_000;
        let (mut m1, mut m2) = (0.0, 0.0);
        for _ in 0..n {
            let d = DVec3::from(cosine_weighted_direction(
                axis.into(),
                rng.random(),
                rng.random(),
            ));
            assert!((d.length() - 1.0).abs() < 1e-12);
            let c = d.dot(axis);
            m1 += c;
            m2 += c * c;
        }
        m1 /= n as f64;
        m2 /= n as f64;
        // Standard errors are about 0.0012 and 0.0014; allow ~5 of them.
        assert!((m1 - 2.0 / 3.0).abs() < 6e-3, "mean cos {m1}");
        assert!((m2 - 0.5).abs() < 7e-3, "mean cos² {m2}");
    }

    #[test]
    fn orbit_views_circle_at_fixed_elevation() {
        let views = orbit_views(4, 20.0, 2.5, 60.0);
        assert_eq!(views.len(), 4);
        assert!(close(views[0].eye, eye_position(20.0, 0.0, 2.5), 1e-12));
        assert!(close(views[1].eye, eye_position(20.0, 90.0, 2.5), 1e-12));
        for v in &views {
            assert_eq!(v.light_pos, v.eye);
            assert_eq!(v.fov_y_deg, 60.0);
        }
    }

    #[test]
    fn adapt_multiplier_is_half_the_largest_bbox_extent() {
        let pts = [[1.0, 2.0, -3.0], [3.0, 2.5, -1.0], [2.0, 2.2, -2.0]];
        // Extents 2, 0.5, 2 → centred max |coord| = 1.
        assert!((adapt_multiplier(&pts) - 1.0).abs() < 1e-15);
        assert_eq!(adapt_multiplier(&[]), 1.0);
        assert_eq!(adapt_multiplier(&[[f64::NAN, 0.0, 0.0]]), 1.0);
        assert_eq!(adapt_multiplier(&[[0.5, 0.5, 0.5]]), 1.0);
    }
}
